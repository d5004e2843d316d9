//! A tiny built-in bitmap font: glyphs of 5 by 7 pixels for the digits,
//! the lower-case letters and a few signs, enough for legends and scale
//! bars, drawn at a whole-number scale. A character it lacks is drawn as
//! `?`; upper-case letters are drawn as their lower-case ones.

use crate::canvas::Canvas;

/// Width of a glyph, pixels at scale 1.
pub const GLYPH_WIDTH: u32 = 5;
/// Height of a glyph, pixels at scale 1.
pub const GLYPH_HEIGHT: u32 = 7;
/// Blank columns between two glyphs, at scale 1.
const GAP: u32 = 1;

/// Each glyph's rows, top first; bit 4 is the leftmost pixel.
#[rustfmt::skip]
const GLYPHS: &[(char, [u8; 7])] = &[
    ('0', [0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110]),
    ('1', [0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('2', [0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111]),
    ('3', [0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110]),
    ('4', [0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010]),
    ('5', [0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110]),
    ('6', [0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110]),
    ('7', [0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000]),
    ('8', [0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110]),
    ('9', [0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100]),
    ('a', [0b00000, 0b00000, 0b01110, 0b00001, 0b01111, 0b10001, 0b01111]),
    ('b', [0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b11110]),
    ('c', [0b00000, 0b00000, 0b01110, 0b10000, 0b10000, 0b10001, 0b01110]),
    ('d', [0b00001, 0b00001, 0b01101, 0b10011, 0b10001, 0b10001, 0b01111]),
    ('e', [0b00000, 0b00000, 0b01110, 0b10001, 0b11111, 0b10000, 0b01110]),
    ('f', [0b00110, 0b01001, 0b01000, 0b11100, 0b01000, 0b01000, 0b01000]),
    ('g', [0b00000, 0b00000, 0b01111, 0b10001, 0b01111, 0b00001, 0b01110]),
    ('h', [0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001]),
    ('i', [0b00100, 0b00000, 0b01100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('j', [0b00010, 0b00000, 0b00110, 0b00010, 0b00010, 0b10010, 0b01100]),
    ('k', [0b10000, 0b10000, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010]),
    ('l', [0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('m', [0b00000, 0b00000, 0b11010, 0b10101, 0b10101, 0b10001, 0b10001]),
    ('n', [0b00000, 0b00000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001]),
    ('o', [0b00000, 0b00000, 0b01110, 0b10001, 0b10001, 0b10001, 0b01110]),
    ('p', [0b00000, 0b00000, 0b11110, 0b10001, 0b11110, 0b10000, 0b10000]),
    ('q', [0b00000, 0b00000, 0b01101, 0b10011, 0b01111, 0b00001, 0b00001]),
    ('r', [0b00000, 0b00000, 0b10110, 0b11001, 0b10000, 0b10000, 0b10000]),
    ('s', [0b00000, 0b00000, 0b01110, 0b10000, 0b01110, 0b00001, 0b11110]),
    ('t', [0b01000, 0b01000, 0b11100, 0b01000, 0b01000, 0b01001, 0b00110]),
    ('u', [0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b10011, 0b01101]),
    ('v', [0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100]),
    ('w', [0b00000, 0b00000, 0b10001, 0b10001, 0b10101, 0b10101, 0b01010]),
    ('x', [0b00000, 0b00000, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001]),
    ('y', [0b00000, 0b00000, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110]),
    ('z', [0b00000, 0b00000, 0b11111, 0b00010, 0b00100, 0b01000, 0b11111]),
    (' ', [0; 7]),
    ('.', [0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b01100]),
    (',', [0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b00100, 0b01000]),
    (':', [0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b01100, 0b00000]),
    ('-', [0b00000, 0b00000, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000]),
    ('/', [0b00000, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b00000]),
    ('(', [0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00100, 0b00010]),
    (')', [0b01000, 0b00100, 0b00010, 0b00010, 0b00010, 0b00100, 0b01000]),
    ('?', [0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b00000, 0b00100]),
];

/// The rows of `c`'s glyph (`?`'s for a character the font lacks).
pub fn glyph(c: char) -> [u8; 7] {
    let c = c.to_ascii_lowercase();
    let find = |wanted: char| GLYPHS.iter().find(|(g, _)| *g == wanted);
    find(c)
        .or_else(|| find('?'))
        .map_or([0; 7], |(_, rows)| *rows)
}

/// Width of `text` drawn at `scale`, pixels: glyphs and the gaps between
/// them.
pub fn text_width(text: &str, scale: u32) -> u32 {
    let n = text.chars().count() as u32;
    if n == 0 {
        return 0;
    }
    scale * (n * (GLYPH_WIDTH + GAP) - GAP)
}

/// Height of a line of text at `scale`, pixels.
pub fn text_height(scale: u32) -> u32 {
    scale * GLYPH_HEIGHT
}

/// Draws `text` in `rgb` with its top left at `(col, row)`, each font
/// pixel a square of `scale` pixels (0 draws nothing).
pub fn draw_text<C: Canvas + ?Sized>(
    canvas: &mut C,
    col: i64,
    row: i64,
    text: &str,
    scale: u32,
    rgb: [u8; 3],
) {
    let s = i64::from(scale);
    for (i, c) in text.chars().enumerate() {
        let left = col + i as i64 * i64::from(GLYPH_WIDTH + GAP) * s;
        for (r, bits) in glyph(c).iter().enumerate() {
            for x in 0..GLYPH_WIDTH {
                if bits & (1 << (GLYPH_WIDTH - 1 - x)) == 0 {
                    continue;
                }
                for dy in 0..s {
                    for dx in 0..s {
                        canvas.paint(left + i64::from(x) * s + dx, row + r as i64 * s + dy, rgb);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canvas::GrayCanvas;

    #[test]
    fn every_glyph_fits_in_five_columns_and_is_told_apart() {
        for (c, rows) in GLYPHS {
            assert!(rows.iter().all(|r| *r < 32), "{c}");
        }
        for (i, (a, rows_a)) in GLYPHS.iter().enumerate() {
            for (b, rows_b) in &GLYPHS[i + 1..] {
                assert_ne!(a, b);
                if *a != ' ' && *b != ' ' {
                    assert_ne!(rows_a, rows_b, "{a} and {b} look alike");
                }
            }
        }
    }

    #[test]
    fn text_is_drawn_at_its_scale_and_unknown_characters_as_a_question_mark() {
        let mut pixels = vec![255u8; 40 * 20];
        let mut canvas = GrayCanvas {
            width: 40,
            height: 20,
            pixels: &mut pixels,
        };
        draw_text(&mut canvas, 1, 2, "1", 2, [0, 0, 0]);
        // '1' at scale 2: its top row has one pixel, column 2, so pixels
        // (1 + 4, 2) and (1 + 5, 2) are ink, (1 + 3, 2) is not.
        assert_eq!(canvas.colour(5, 2), Some([0; 3]));
        assert_eq!(canvas.colour(6, 3), Some([0; 3]));
        assert_eq!(canvas.colour(4, 2), Some([255; 3]));
        // Its bottom row is three wide: columns 1..=3, rows 14 and 15.
        assert_eq!(canvas.colour(1 + 2, 2 + 13), Some([0; 3]));
        assert_eq!(canvas.colour(1 + 7, 2 + 12), Some([0; 3]));
        assert_eq!(text_width("1 m", 2), 2 * (3 * 6 - 1));
        assert_eq!(text_height(3), 21);
        assert_eq!(glyph('#'), glyph('?'));
        assert_eq!(glyph('M'), glyph('m'));
    }
}
