//! Scale bars: a round length (1, 2 or 5 times a power of ten metres) as
//! a bar of exactly that many metres' pixels, its length written above it
//! in the built-in [`font`](crate::font), on a small backing box placed in
//! the quietest corner of a picture.

use crate::canvas::{Canvas, Corner, Rect, quietest_corner};
use crate::font::{draw_text, text_height, text_width};

/// Shortest bar drawn, pixels: below this a bar cannot be read.
pub const MIN_BAR_PX: u32 = 12;
/// Longest bar as a fraction of the picture's width.
pub const MOST_WIDTH_FRACTION: f64 = 0.25;

/// A bar of a round length.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaleBar {
    /// Its length, metres.
    pub metres: f64,
    /// Its length, pixels: `metres` times pixels per metre, rounded.
    pub length_px: u32,
    /// Its length in words: `50 cm`, `1 m`, `20 m`, `2 km`.
    pub label: String,
}

impl ScaleBar {
    /// The longest round length whose bar is at most `most_px` pixels at
    /// `px_per_m`; `None` when even the shortest that can be read
    /// ([`MIN_BAR_PX`]) is longer, or `px_per_m` is not a positive number.
    pub fn choose(px_per_m: f64, most_px: u32) -> Option<Self> {
        if !(px_per_m.is_finite() && px_per_m > 0.0) {
            return None;
        }
        let mut best = None;
        for exponent in -3..=6 {
            for mantissa in [1.0, 2.0, 5.0] {
                let metres = mantissa * 10f64.powi(exponent);
                let px = (metres * px_per_m).round();
                if px >= f64::from(MIN_BAR_PX) && px <= f64::from(most_px) {
                    best = Some((metres, px as u32));
                }
            }
        }
        best.map(|(metres, length_px)| Self {
            metres,
            length_px,
            label: label(metres),
        })
    }
}

/// `metres` in the unit that keeps the number whole: mm, cm, m or km.
fn label(metres: f64) -> String {
    let (value, unit) = if metres >= 1000.0 {
        (metres / 1000.0, "km")
    } else if metres >= 1.0 {
        (metres, "m")
    } else if metres >= 0.01 {
        (metres * 100.0, "cm")
    } else {
        (metres * 1000.0, "mm")
    };
    format!("{} {unit}", value.round())
}

/// How a bar is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarStyle {
    /// The bar's and the label's colour.
    pub ink: [u8; 3],
    /// The box behind them.
    pub backing: [u8; 3],
    /// Font pixels per font dot; the bar's thickness and padding follow.
    pub scale: u32,
    /// Pixels between the box and the picture's edge.
    pub margin: u32,
}

/// The size of the box holding `bar` drawn in `style`: (width, height).
pub fn box_size(bar: &ScaleBar, style: &BarStyle) -> (u32, u32) {
    let s = style.scale.max(1);
    let pad = 3 * s;
    let inner = bar.length_px.max(text_width(&bar.label, s));
    (
        inner + 2 * pad,
        // Label, a gap, then the ticks standing on the bar.
        pad + text_height(s) + 2 * s + 6 * s + pad,
    )
}

/// Draws `bar` in `style` into `rect` (of [`box_size`]): the backing box,
/// the label centred above, and the bar, `bar.length_px` columns long, 2
/// rows thick at scale 1 with a tick up at each end.
pub fn draw_bar<C: Canvas + ?Sized>(canvas: &mut C, rect: Rect, bar: &ScaleBar, style: &BarStyle) {
    let s = style.scale.max(1);
    let pad = i64::from(3 * s);
    canvas.fill(rect, style.backing);
    let inner = i64::from(rect.width) - 2 * pad;
    let centre = rect.col + pad + inner / 2;
    let label_width = i64::from(text_width(&bar.label, s));
    draw_text(
        canvas,
        centre - label_width / 2,
        rect.row + pad,
        &bar.label,
        s,
        style.ink,
    );
    let length = i64::from(bar.length_px);
    let left = centre - length / 2;
    let bottom = rect.row + i64::from(rect.height) - pad - 1;
    let thickness = i64::from(2 * s);
    let tick = i64::from(4 * s);
    for col in left..left + length {
        for row in bottom - thickness + 1..=bottom {
            canvas.paint(col, row, style.ink);
        }
    }
    for end in [left, left + length - i64::from(s)] {
        for col in end..end + i64::from(s) {
            for row in bottom - tick - thickness + 1..=bottom {
                canvas.paint(col, row, style.ink);
            }
        }
    }
}

/// Chooses a bar for a picture of `px_per_m` (at most a quarter of its
/// width), finds the quietest of `corners` for it (see
/// [`quietest_corner`]) and draws it there; returns the box drawn, or
/// `None` when no readable bar fits the picture.
pub fn draw_scale_bar<C: Canvas + ?Sized>(
    canvas: &mut C,
    px_per_m: f64,
    style: &BarStyle,
    corners: &[Corner],
    taken: &[Rect],
    busy: impl Fn(i64, i64) -> bool,
) -> Option<Rect> {
    let (width, _) = canvas.size();
    let most = (f64::from(width) * MOST_WIDTH_FRACTION).floor() as u32;
    let bar = ScaleBar::choose(px_per_m, most)?;
    let (w, h) = box_size(&bar, style);
    let rect = quietest_corner(canvas, corners, w, h, style.margin, taken, busy)?;
    draw_bar(canvas, rect, &bar, style);
    Some(rect)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canvas::GrayCanvas;

    #[test]
    fn the_bar_is_the_longest_round_length_that_fits() {
        // 20 px a metre (5 cm cells), at most 50 px: 2 m, 40 px.
        let bar = ScaleBar::choose(20.0, 50).expect("bar");
        assert_eq!((bar.metres, bar.length_px), (2.0, 40));
        assert_eq!(bar.label, "2 m");
        // 1000 px over 30 m: 33.3 px a metre, at most 250 px: 5 m, 167 px.
        let bar = ScaleBar::choose(1000.0 / 30.0, 250).expect("bar");
        assert_eq!((bar.metres, bar.length_px), (5.0, 167));
        let bar = ScaleBar::choose(400.0, 250).expect("bar");
        assert_eq!((bar.label.as_str(), bar.length_px), ("50 cm", 200));
        let bar = ScaleBar::choose(0.1, 250).expect("bar");
        assert_eq!(bar.label, "2 km");
        assert_eq!(ScaleBar::choose(20.0, 5), None);
        assert_eq!(ScaleBar::choose(f64::NAN, 100), None);
        assert_eq!(ScaleBar::choose(0.0, 100), None);
    }

    #[test]
    fn a_drawn_bar_is_its_metres_over_the_resolution_in_pixels() {
        let resolution = 0.05;
        let (width, height) = (200u32, 120u32);
        let mut pixels = vec![254u8; (width * height) as usize];
        let mut canvas = GrayCanvas {
            width,
            height,
            pixels: &mut pixels,
        };
        let style = BarStyle {
            ink: [0, 0, 0],
            backing: [255, 255, 255],
            scale: 1,
            margin: 4,
        };
        let rect = draw_scale_bar(
            &mut canvas,
            1.0 / resolution,
            &style,
            &[Corner::BottomLeft],
            &[],
            |_, _| false,
        )
        .expect("fits");
        // The bar's bottom row holds the bar alone: count its ink.
        let bottom = rect.row + i64::from(rect.height) - 3 - 1;
        let ink: Vec<i64> = (0..i64::from(width))
            .filter(|&c| canvas.colour(c, bottom) == Some([0; 3]))
            .collect();
        let metres = 2.0;
        assert_eq!(ink.len() as f64, (metres / resolution).round());
        // Unbroken, inside the box, which sits in the bottom left corner.
        assert_eq!(ink.last().expect("ink") - ink[0] + 1, ink.len() as i64);
        assert_eq!((rect.col, rect.row + i64::from(rect.height)), (4, 116));
        // The label is drawn above the bar, and the map beside the box is
        // left as it was.
        let label_ink = (rect.row..bottom - 6)
            .flat_map(|r| (rect.col..rect.col + i64::from(rect.width)).map(move |c| (c, r)))
            .filter(|&(c, r)| canvas.colour(c, r) == Some([0; 3]))
            .count();
        assert!(label_ink > 10, "{label_ink}");
        assert_eq!(canvas.colour(150, 60), Some([254; 3]));
    }

    #[test]
    fn a_picture_too_small_gets_no_bar() {
        let mut pixels = vec![254u8; 30 * 10];
        let mut canvas = GrayCanvas {
            width: 30,
            height: 10,
            pixels: &mut pixels,
        };
        let style = BarStyle {
            ink: [0, 0, 0],
            backing: [255, 255, 255],
            scale: 1,
            margin: 2,
        };
        let drawn = draw_scale_bar(
            &mut canvas,
            20.0,
            &style,
            &[Corner::BottomLeft],
            &[],
            |_, _| false,
        );
        assert_eq!(drawn, None);
        assert!(pixels.iter().all(|&p| p == 254));
    }
}
