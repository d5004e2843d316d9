//! The plot's legend: what each colour and mark means, in the built-in
//! bitmap font, on a white box in the plot's quietest corner.

use deog_mapfile::font::{draw_text, text_height, text_width};
use deog_mapfile::{Canvas, Corner, Rect, canvas::quietest_corner};

use super::plot::{
    BEFORE_CONVERGENCE_RGB, ESTIMATE_RGB, KIDNAP_RGB, LEGEND_BACKING_RGB, LEGEND_EDGE_RGB,
    RECOVERY_RGB, Raster, TEXT_RGB, TRUTH_RGB,
};

/// The legend's lines, in order.
pub const ENTRIES: [(Swatch, &str); 5] = [
    (Swatch::Line(TRUTH_RGB), "true path"),
    (Swatch::Line(ESTIMATE_RGB), "estimate"),
    (
        Swatch::Points(BEFORE_CONVERGENCE_RGB),
        "estimate before convergence",
    ),
    (Swatch::Cross(KIDNAP_RGB), "kidnap"),
    (Swatch::Ring(RECOVERY_RGB), "recovery"),
];

/// How an entry shows its mark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Swatch {
    /// A short line.
    Line([u8; 3]),
    /// A few points, unjoined.
    Points([u8; 3]),
    /// A diagonal cross.
    Cross([u8; 3]),
    /// A ring.
    Ring([u8; 3]),
}

/// Draws the legend at font scale `scale` in the quietest corner that
/// holds it; returns its box, or `None` when the plot is too small for it.
pub(crate) fn draw_legend(
    raster: &mut Raster,
    scale: u32,
    margin: u32,
    busy: impl Fn(&Raster, i64, i64) -> bool,
) -> Option<Rect> {
    let s = scale.max(1);
    let pad = 4 * s;
    let swatch = 12 * s;
    let line = text_height(s) + 4 * s;
    let widest = ENTRIES
        .iter()
        .map(|(_, text)| text_width(text, s))
        .max()
        .unwrap_or(0);
    let width = pad + swatch + 3 * s + widest + pad;
    let height = pad + ENTRIES.len() as u32 * line - 4 * s + pad;
    let rect = {
        let view: &Raster = raster;
        quietest_corner(
            view,
            &[
                Corner::TopLeft,
                Corner::TopRight,
                Corner::BottomRight,
                Corner::BottomLeft,
            ],
            width,
            height,
            margin,
            &[],
            |c, r| busy(view, c, r),
        )?
    };
    raster.fill(rect, LEGEND_EDGE_RGB);
    raster.fill(
        Rect {
            col: rect.col + 1,
            row: rect.row + 1,
            width: rect.width - 2,
            height: rect.height - 2,
        },
        LEGEND_BACKING_RGB,
    );
    for (i, (mark, text)) in ENTRIES.iter().enumerate() {
        let top = rect.row + i64::from(pad) + i as i64 * i64::from(line);
        let left = rect.col + i64::from(pad);
        let middle = top + i64::from(text_height(s)) / 2;
        draw_swatch(raster, *mark, left, middle, i64::from(swatch), s);
        draw_text(
            raster,
            left + i64::from(swatch + 3 * s),
            top,
            text,
            s,
            TEXT_RGB,
        );
    }
    Some(rect)
}

/// `mark`, `width` pixels wide from column `left`, centred on row `middle`.
fn draw_swatch(raster: &mut Raster, mark: Swatch, left: i64, middle: i64, width: i64, s: u32) {
    let s = i64::from(s);
    match mark {
        Swatch::Line(rgb) => {
            for col in left..left + width {
                for row in middle - s / 2..middle - s / 2 + s.max(2) {
                    raster.paint(col, row, rgb);
                }
            }
        }
        Swatch::Points(rgb) => {
            for k in 0..3 {
                let col = left + k * (width - 2) / 2;
                for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    raster.paint(col + dc, middle + dr - 1, rgb);
                }
            }
        }
        Swatch::Cross(rgb) => {
            let half = width / 2 - 1;
            raster.cross_at(left + width / 2, middle, half, rgb);
        }
        Swatch::Ring(rgb) => {
            let radius = (width / 2 - 1) as f64;
            raster.ring_at(left + width / 2, middle, radius, rgb);
        }
    }
}
