//! Each observed cell's verdict (its truth against its map class) and
//! the picture of them over the world.

use deog_grid::CellIndex;

use super::truth::OCCUPIED;
use super::{Class, QualityInput, for_each_verdict, judged_truth};
use crate::error::EvaluationError;

/// One observed cell judged: its truth, then its map class.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Free, mapped free: right.
    FreeAsFree,
    /// Free, mapped occupied.
    FreeAsOccupied,
    /// Free, mapped uncertain.
    FreeAsUncertain,
    /// Occupied, mapped free.
    OccupiedAsFree,
    /// Occupied, mapped occupied: right.
    OccupiedAsOccupied,
    /// Occupied, mapped uncertain.
    OccupiedAsUncertain,
}

impl Verdict {
    pub(super) fn of(truth_occupied: bool, class: Class) -> Self {
        match (truth_occupied, class) {
            (false, Class::Free) => Self::FreeAsFree,
            (false, Class::Occupied) => Self::FreeAsOccupied,
            (false, Class::Uncertain) => Self::FreeAsUncertain,
            (true, Class::Free) => Self::OccupiedAsFree,
            (true, Class::Occupied) => Self::OccupiedAsOccupied,
            (true, Class::Uncertain) => Self::OccupiedAsUncertain,
        }
    }

    pub(super) fn map_class(self) -> Class {
        match self {
            Self::FreeAsFree | Self::OccupiedAsFree => Class::Free,
            Self::FreeAsOccupied | Self::OccupiedAsOccupied => Class::Occupied,
            Self::FreeAsUncertain | Self::OccupiedAsUncertain => Class::Uncertain,
        }
    }

    /// The colour [`verdict_image`] paints it.
    pub fn rgb(self) -> [u8; 3] {
        match self {
            Self::FreeAsFree => [255, 255, 255],
            Self::OccupiedAsOccupied => [0, 0, 0],
            Self::FreeAsUncertain => [255, 200, 0],
            Self::FreeAsOccupied => [220, 0, 0],
            Self::OccupiedAsFree => [0, 90, 255],
            Self::OccupiedAsUncertain => [170, 0, 200],
        }
    }
}

/// Never observed, free in the world.
pub const UNOBSERVED_FREE_RGB: [u8; 3] = [205, 205, 205];
/// Never observed, occupied in the world (the walls, for orientation).
pub const UNOBSERVED_OCCUPIED_RGB: [u8; 3] = [120, 120, 120];

/// Where a map is right and wrong, one RGB pixel a cell over the world's
/// bounds (one cell more each side), the top row first: each observed
/// cell in its [`Verdict::rgb`], the rest in [`UNOBSERVED_FREE_RGB`] or
/// [`UNOBSERVED_OCCUPIED_RGB`] by the world's truth.
#[derive(Debug, Clone, PartialEq)]
pub struct VerdictImage {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` RGB triples, top row first.
    pub rgb: Vec<u8>,
    /// The cell of the bottom-left pixel.
    pub min_cell: CellIndex,
}

impl VerdictImage {
    /// The image with each pixel a `factor` × `factor` square (a factor
    /// of 0 counts as 1), so that small worlds can be seen.
    pub fn scaled(&self, factor: u32) -> VerdictImage {
        let factor = factor.max(1) as usize;
        let (width, height) = (self.width as usize, self.height as usize);
        let mut rgb = Vec::with_capacity(self.rgb.len() * factor * factor);
        for row in self.rgb.chunks_exact(3 * width).take(height) {
            let mut line = Vec::with_capacity(row.len() * factor);
            for pixel in row.chunks_exact(3) {
                for _ in 0..factor {
                    line.extend_from_slice(pixel);
                }
            }
            for _ in 0..factor {
                rgb.extend_from_slice(&line);
            }
        }
        VerdictImage {
            width: (width * factor) as u32,
            height: (height * factor) as u32,
            rgb,
            min_cell: self.min_cell,
        }
    }

    /// The scale factor that brings the longer side to at most
    /// `max_side` pixels (at least 1).
    pub fn fit_factor(&self, max_side: u32) -> u32 {
        (max_side / self.width.max(self.height).max(1)).max(1)
    }
}

/// Paints `input.map`'s verdicts over its world; the same errors as
/// [`map_quality`](super::map_quality). Observed cells beyond the world's bounds (all wrong
/// unless mapped occupied) are counted by [`map_quality`](super::map_quality) but not drawn.
pub fn verdict_image(input: &QualityInput<'_>) -> Result<VerdictImage, EvaluationError> {
    let (truth, grid, _) = judged_truth(input)?;
    let (width, height) = (grid.width, grid.height);
    let mut rgb = Vec::with_capacity(3 * width * height);
    for row in (0..height).rev() {
        for col in 0..width {
            let colour = if grid.flags[row * width + col] & OCCUPIED != 0 {
                UNOBSERVED_OCCUPIED_RGB
            } else {
                UNOBSERVED_FREE_RGB
            };
            rgb.extend_from_slice(&colour);
        }
    }
    let truth_occupied = |cell: CellIndex| grid.truth_occupied(&truth, cell);
    for_each_verdict(input.map, &truth_occupied, |cell, verdict| {
        if let Some(i) = grid.index(cell) {
            let (col, row) = (i % width, height - 1 - i / width);
            let at = 3 * (row * width + col);
            rgb[at..at + 3].copy_from_slice(&verdict.rgb());
        }
    })?;
    // The raster's size passed MAX_TRUTH_CELLS, far below u32::MAX a side.
    Ok(VerdictImage {
        width: width as u32,
        height: height as u32,
        rgb,
        min_cell: grid.origin,
    })
}

/// The longer side, in pixels, that [`verdict_png`] scales a picture up to
/// (in whole cells a pixel square).
pub const VERDICT_MAX_SIDE_PX: u32 = 1000;

/// [`verdict_image`] scaled up to about [`VERDICT_MAX_SIDE_PX`] and
/// encoded as a PNG file's bytes.
pub fn verdict_png(input: &QualityInput<'_>) -> Result<Vec<u8>, EvaluationError> {
    let image = verdict_image(input)?;
    let image = image.scaled(image.fit_factor(VERDICT_MAX_SIDE_PX));
    deog_mapfile::encode_rgb_png(image.width, image.height, &image.rgb)
        .map_err(|e| EvaluationError::Plot(e.to_string()))
}
