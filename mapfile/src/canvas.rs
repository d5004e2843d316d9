//! What the picture helpers ([`font`](crate::font),
//! [`scale_bar`](crate::scale_bar)) draw on: any grid of pixels that can be
//! read and painted, an RGB plot or a grayscale map alike.

/// A grid of pixels, row 0 at the top.
pub trait Canvas {
    /// Pixels per row and rows.
    fn size(&self) -> (u32, u32);
    /// The colour at `(col, row)`; `None` outside.
    fn colour(&self, col: i64, row: i64) -> Option<[u8; 3]>;
    /// Paints `(col, row)`; a pixel outside is left alone.
    fn paint(&mut self, col: i64, row: i64, rgb: [u8; 3]);

    /// Fills `rect`; what lies outside the canvas is left alone.
    fn fill(&mut self, rect: Rect, rgb: [u8; 3]) {
        for r in rect.row..rect.row + i64::from(rect.height) {
            for c in rect.col..rect.col + i64::from(rect.width) {
                self.paint(c, r, rgb);
            }
        }
    }
}

/// A rectangle of pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Column of the left edge.
    pub col: i64,
    /// Row of the top edge.
    pub row: i64,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
}

impl Rect {
    /// Whether the two share a pixel.
    pub fn overlaps(&self, other: &Rect) -> bool {
        self.col < other.col + i64::from(other.width)
            && other.col < self.col + i64::from(self.width)
            && self.row < other.row + i64::from(other.height)
            && other.row < self.row + i64::from(self.height)
    }
}

/// A corner of a canvas.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Corner {
    /// Top left.
    TopLeft,
    /// Top right.
    TopRight,
    /// Bottom left.
    BottomLeft,
    /// Bottom right.
    BottomRight,
}

impl Corner {
    /// The rectangle of `width` by `height` pixels in this corner of a
    /// canvas of `size`, `margin` pixels in from both edges.
    pub fn rect(self, size: (u32, u32), width: u32, height: u32, margin: u32) -> Rect {
        let (w, h, m) = (i64::from(size.0), i64::from(size.1), i64::from(margin));
        let left = m;
        let right = w - m - i64::from(width);
        let top = m;
        let bottom = h - m - i64::from(height);
        let (col, row) = match self {
            Corner::TopLeft => (left, top),
            Corner::TopRight => (right, top),
            Corner::BottomLeft => (left, bottom),
            Corner::BottomRight => (right, bottom),
        };
        Rect {
            col,
            row,
            width,
            height,
        }
    }
}

/// Of `corners` (in order of preference), the one whose box of `width` by
/// `height` pixels, `margin` in from the edges, covers the fewest pixels
/// that `busy` says hold something, overlapping none of `taken`; `None`
/// when the box does not fit on the canvas or every corner is taken.
pub fn quietest_corner<C: Canvas + ?Sized>(
    canvas: &C,
    corners: &[Corner],
    width: u32,
    height: u32,
    margin: u32,
    taken: &[Rect],
    busy: impl Fn(i64, i64) -> bool,
) -> Option<Rect> {
    let size = canvas.size();
    if u64::from(width) + 2 * u64::from(margin) > u64::from(size.0)
        || u64::from(height) + 2 * u64::from(margin) > u64::from(size.1)
    {
        return None;
    }
    corners
        .iter()
        .map(|corner| corner.rect(size, width, height, margin))
        .filter(|rect| !taken.iter().any(|t| t.overlaps(rect)))
        .map(|rect| {
            let mut count = 0u64;
            for r in rect.row..rect.row + i64::from(rect.height) {
                for c in rect.col..rect.col + i64::from(rect.width) {
                    if busy(c, r) {
                        count += 1;
                    }
                }
            }
            (count, rect)
        })
        // The first of equally quiet corners: the order of preference.
        .min_by_key(|(count, _)| *count)
        .map(|(_, rect)| rect)
}

/// A grayscale image seen as a canvas: a colour painted becomes its mean
/// of red, green and blue.
#[derive(Debug)]
pub struct GrayCanvas<'a> {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` values, top row first.
    pub pixels: &'a mut [u8],
}

impl GrayCanvas<'_> {
    fn index(&self, col: i64, row: i64) -> Option<usize> {
        let inside =
            col >= 0 && row >= 0 && col < i64::from(self.width) && row < i64::from(self.height);
        let i = row as usize * self.width as usize + col as usize;
        (inside && i < self.pixels.len()).then_some(i)
    }
}

impl Canvas for GrayCanvas<'_> {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn colour(&self, col: i64, row: i64) -> Option<[u8; 3]> {
        self.index(col, row).map(|i| [self.pixels[i]; 3])
    }

    fn paint(&mut self, col: i64, row: i64, rgb: [u8; 3]) {
        if let Some(i) = self.index(col, row) {
            let sum: u16 = rgb.iter().map(|&v| u16::from(v)).sum();
            self.pixels[i] = (sum / 3) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quietest_corner_avoids_busy_pixels_and_taken_boxes() {
        let mut pixels = vec![255u8; 20 * 10];
        let mut canvas = GrayCanvas {
            width: 20,
            height: 10,
            pixels: &mut pixels,
        };
        // Something drawn in the top left.
        canvas.fill(
            Rect {
                col: 0,
                row: 0,
                width: 6,
                height: 4,
            },
            [0, 0, 0],
        );
        let all = [
            Corner::TopLeft,
            Corner::TopRight,
            Corner::BottomLeft,
            Corner::BottomRight,
        ];
        let busy = |c: i64, r: i64| canvas.colour(c, r).is_some_and(|rgb| rgb[0] < 128);
        let rect = quietest_corner(&canvas, &all, 5, 3, 1, &[], busy).expect("fits");
        assert_eq!((rect.col, rect.row), (14, 1));
        let taken = [rect];
        let next = quietest_corner(&canvas, &all, 5, 3, 1, &taken, busy).expect("fits");
        assert_eq!((next.col, next.row), (1, 6));
        assert_eq!(quietest_corner(&canvas, &all, 19, 3, 1, &[], busy), None);
    }
}
