//! [`MapImage`]: a map_server map in memory, its occupancy rules and its
//! world coordinates.

use std::path::{Path, PathBuf};

use crate::error::MapFileError;
use crate::pgm::{Pgm, decode_pgm};
use crate::yaml::{MapYaml, Mode};

/// What a map cell holds, by map_server's rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cell {
    /// Known to be empty.
    Free,
    /// Known to hold an obstacle.
    Occupied,
    /// Not known (never observed, or between the thresholds).
    Unknown,
}

/// An axis-aligned box in the world: its (min x, min y) and (max x, max y)
/// corners, metres.
pub type WorldBox = ((f64, f64), (f64, f64));

/// A map_server map: its YAML metadata and its image.
#[derive(Debug, Clone, PartialEq)]
pub struct MapImage {
    /// Pixels a row (columns), >= 1.
    pub width: u32,
    /// Rows, >= 1.
    pub height: u32,
    /// Metres per pixel, > 0.
    pub resolution: f64,
    /// The lower-left corner of the lower-left pixel in the world: x and y in
    /// metres, yaw in radians counter-clockwise from +x.
    pub origin: (f64, f64, f64),
    /// Whether white means occupied (map_server's `negate`).
    pub negate: bool,
    /// Occupancy probability above which a pixel is occupied, in [0, 1].
    pub occupied_thresh: f64,
    /// Occupancy probability below which a pixel is free, in [0, 1] and not
    /// above `occupied_thresh`.
    pub free_thresh: f64,
    /// How pixel values become occupancy.
    pub mode: Mode,
    /// `width * height` gray values, row-major, the first row the map's TOP
    /// (as in the file); 0 is black, 255 white.
    pub pixels: Vec<u8>,
}

impl MapImage {
    /// Reads a map_server YAML file and the image it names (a relative
    /// `image` path is relative to the YAML's folder). Any origin yaw is
    /// kept; see [`MapImage::load_axis_aligned`].
    pub fn load(yaml_path: impl AsRef<Path>) -> Result<Self, MapFileError> {
        load_with_yaml(yaml_path.as_ref()).map(|(map, _)| map)
    }

    /// As [`MapImage::load`], but rejects a rotated map (origin yaw other
    /// than 0) with an error naming the file, line and the `origin` field:
    /// what callers that use [`MapImage::cell_center`] want.
    pub fn load_axis_aligned(yaml_path: impl AsRef<Path>) -> Result<Self, MapFileError> {
        let yaml_path = yaml_path.as_ref();
        let (map, yaml) = load_with_yaml(yaml_path)?;
        if map.origin.2 != 0.0 {
            return Err(MapFileError::Yaml {
                file: yaml_path.display().to_string(),
                line: yaml.line_of("origin").unwrap_or(0),
                field: "origin".into(),
                reason: yaw_reason(map.origin.2),
            });
        }
        Ok(map)
    }

    /// A map from checked YAML metadata and a decoded image.
    pub fn from_parts(yaml: &MapYaml, image: Pgm) -> Self {
        Self {
            width: image.width,
            height: image.height,
            resolution: yaml.resolution,
            origin: yaml.origin,
            negate: yaml.negate,
            occupied_thresh: yaml.occupied_thresh,
            free_thresh: yaml.free_thresh,
            mode: yaml.mode,
            pixels: image.pixels,
        }
    }

    /// The gray value of column `col`, row `row_from_bottom` (0 = the
    /// map's bottom row); `None` outside the image.
    pub fn pixel(&self, col: u32, row_from_bottom: u32) -> Option<u8> {
        if col >= self.width || row_from_bottom >= self.height {
            return None;
        }
        let row_in_file = (self.height - 1 - row_from_bottom) as usize;
        self.pixels
            .get(row_in_file * self.width as usize + col as usize)
            .copied()
    }

    /// The occupancy probability map_server reads from a pixel value:
    /// `(255 - pixel) / 255`, or `pixel / 255` when `negate`.
    pub fn probability(&self, pixel: u8) -> f64 {
        let v = f64::from(pixel);
        if self.negate {
            v / 255.0
        } else {
            (255.0 - v) / 255.0
        }
    }

    /// The cell at column `col`, row `row_from_bottom`, by map_server's
    /// rules: occupied when the probability is above `occupied_thresh`, free
    /// when below `free_thresh`, unknown otherwise. In `scale` mode the
    /// values between the thresholds are probabilities, which this also
    /// reports as unknown; in `raw` mode the pixel is the occupancy in
    /// percent (after `negate`), values above 100 unknown, and the same
    /// thresholds apply to it. Outside the image: unknown.
    pub fn occupancy(&self, col: u32, row_from_bottom: u32) -> Cell {
        let Some(pixel) = self.pixel(col, row_from_bottom) else {
            return Cell::Unknown;
        };
        let p = match self.mode {
            Mode::Trinary | Mode::Scale => self.probability(pixel),
            Mode::Raw => {
                let value = if self.negate { 255 - pixel } else { pixel };
                if value > 100 {
                    return Cell::Unknown;
                }
                f64::from(value) / 100.0
            }
        };
        if p > self.occupied_thresh {
            Cell::Occupied
        } else if p < self.free_thresh {
            Cell::Free
        } else {
            Cell::Unknown
        }
    }

    /// The value map_server would put in its `nav_msgs/OccupancyGrid` for
    /// this cell: 100 occupied, 0 free, -1 unknown; in `scale` mode
    /// `1 + 98 * ratio` between the thresholds; in `raw` mode the value
    /// itself (-1 above 100, as ROS 2's map_io). Outside the image: -1.
    pub fn value(&self, col: u32, row_from_bottom: u32) -> i8 {
        let Some(pixel) = self.pixel(col, row_from_bottom) else {
            return -1;
        };
        if self.mode == Mode::Raw {
            let value = if self.negate { 255 - pixel } else { pixel };
            return i8::try_from(value).ok().filter(|v| *v <= 100).unwrap_or(-1);
        }
        match self.occupancy(col, row_from_bottom) {
            Cell::Occupied => 100,
            Cell::Free => 0,
            Cell::Unknown if self.mode == Mode::Trinary => -1,
            Cell::Unknown => {
                let p = self.probability(pixel);
                let span = self.occupied_thresh - self.free_thresh;
                if span > 0.0 {
                    // map_server truncates the double into an int8, as `as` does.
                    (1.0 + 98.0 * (p - self.free_thresh) / span) as i8
                } else {
                    -1
                }
            }
        }
    }

    /// The world position (metres) of the centre of column `col`, row
    /// `row_from_bottom`: `origin + (col + 0.5, row + 0.5) * resolution`.
    /// Errors, naming the `origin` field, when the map is rotated (yaw not
    /// 0), which this crate does not support. Indices outside the image give
    /// the centres the grid would have there.
    pub fn cell_center(&self, col: u32, row_from_bottom: u32) -> Result<(f64, f64), MapFileError> {
        let (x, y, yaw) = self.origin;
        if yaw != 0.0 {
            return Err(MapFileError::invalid_map("origin", yaw_reason(yaw)));
        }
        Ok((
            x + (f64::from(col) + 0.5) * self.resolution,
            y + (f64::from(row_from_bottom) + 0.5) * self.resolution,
        ))
    }

    /// The map's extent in the world, (min, max) corners in metres, for an
    /// unrotated map (errors like [`MapImage::cell_center`] otherwise).
    pub fn world_bounds(&self) -> Result<WorldBox, MapFileError> {
        let (x, y, yaw) = self.origin;
        if yaw != 0.0 {
            return Err(MapFileError::invalid_map("origin", yaw_reason(yaw)));
        }
        Ok((
            (x, y),
            (
                x + f64::from(self.width) * self.resolution,
                y + f64::from(self.height) * self.resolution,
            ),
        ))
    }
}

/// Why a rotated origin is refused.
fn yaw_reason(yaw: f64) -> String {
    format!("yaw must be 0 (rotated maps are not supported), got {yaw}")
}

/// Loads the map and keeps the parsed YAML (for its line numbers).
fn load_with_yaml(yaml_path: &Path) -> Result<(MapImage, MapYaml), MapFileError> {
    let file = yaml_path.display().to_string();
    let text = std::fs::read_to_string(yaml_path).map_err(|e| MapFileError::io(&file, e))?;
    let yaml = MapYaml::parse(&text, &file)?;
    let image_path = image_path(yaml_path, &yaml.image);
    let image_file = image_path.display().to_string();
    let bytes = std::fs::read(&image_path).map_err(|e| MapFileError::io(&image_file, e))?;
    let pgm = decode_pgm(&bytes, &image_file)?;
    Ok((MapImage::from_parts(&yaml, pgm), yaml))
}

/// Where the image is: `image` itself when absolute, else beside the YAML.
fn image_path(yaml_path: &Path, image: &str) -> PathBuf {
    let image = Path::new(image);
    if image.is_absolute() {
        image.to_path_buf()
    } else {
        yaml_path
            .parent()
            .unwrap_or_else(|| Path::new(""))
            .join(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 x 2 map, top row black / mid-gray / white, bottom row the reverse.
    fn tiny(mode: Mode, negate: bool) -> MapImage {
        MapImage {
            width: 3,
            height: 2,
            resolution: 0.5,
            origin: (-1.0, 2.0, 0.0),
            negate,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode,
            pixels: vec![0, 128, 255, 255, 128, 0],
        }
    }

    #[test]
    fn occupancy_follows_map_server() {
        let m = tiny(Mode::Trinary, false);
        // Row 0 from the bottom is the file's last row.
        assert_eq!(m.occupancy(0, 0), Cell::Free);
        assert_eq!(m.occupancy(1, 0), Cell::Unknown);
        assert_eq!(m.occupancy(2, 0), Cell::Occupied);
        assert_eq!(m.occupancy(0, 1), Cell::Occupied);
        assert_eq!(m.occupancy(3, 0), Cell::Unknown);
        assert_eq!(m.occupancy(0, 2), Cell::Unknown);
        assert_eq!((m.value(0, 0), m.value(1, 0), m.value(2, 0)), (0, -1, 100));
        let n = tiny(Mode::Trinary, true);
        assert_eq!(n.occupancy(0, 0), Cell::Occupied);
        assert_eq!(n.occupancy(2, 0), Cell::Free);
    }

    #[test]
    fn thresholds_are_strict() {
        let mut m = tiny(Mode::Trinary, false);
        // 205 gives p = 50/255 = 0.19608 > 0.196: unknown, as in map_saver's
        // own unknown gray; 254 gives 0.0039: free.
        m.pixels = vec![205, 254, 0, 0, 0, 0];
        assert_eq!(m.occupancy(0, 1), Cell::Unknown);
        assert_eq!(m.occupancy(1, 1), Cell::Free);
        // p exactly at a threshold is neither above nor below it.
        m.occupied_thresh = 1.0;
        assert_eq!(m.occupancy(2, 1), Cell::Unknown);
    }

    #[test]
    fn scale_and_raw_modes() {
        let s = tiny(Mode::Scale, false);
        assert_eq!(s.occupancy(1, 0), Cell::Unknown);
        let v = s.value(1, 0);
        assert!((1..=99).contains(&v), "{v}");
        let mut r = tiny(Mode::Raw, false);
        r.pixels = vec![0, 50, 100, 101, 255, 70];
        assert_eq!((r.value(0, 1), r.value(1, 1), r.value(2, 1)), (0, 50, 100));
        assert_eq!((r.value(0, 0), r.value(1, 0)), (-1, -1));
        assert_eq!(r.occupancy(0, 1), Cell::Free);
        assert_eq!(r.occupancy(2, 1), Cell::Occupied);
        assert_eq!(r.occupancy(1, 0), Cell::Unknown);
    }

    #[test]
    fn cell_centres_are_offset_by_half_a_cell() {
        let m = tiny(Mode::Trinary, false);
        assert_eq!(m.cell_center(0, 0).expect("centre"), (-0.75, 2.25));
        assert_eq!(m.cell_center(2, 1).expect("centre"), (0.25, 2.75));
        assert_eq!(m.world_bounds().expect("bounds"), ((-1.0, 2.0), (0.5, 3.0)));
    }

    #[test]
    fn a_rotated_origin_is_refused_naming_origin() {
        let mut m = tiny(Mode::Trinary, false);
        m.origin.2 = 0.5;
        let e = m.cell_center(0, 0).expect_err("rotated");
        assert_eq!(
            e.to_string(),
            "origin: yaw must be 0 (rotated maps are not supported), got 0.5"
        );
        assert!(m.world_bounds().is_err());
    }

    #[test]
    fn short_pixels_never_panic() {
        let mut m = tiny(Mode::Trinary, false);
        m.pixels.truncate(2);
        assert_eq!(m.occupancy(0, 0), Cell::Unknown);
        assert_eq!(m.value(2, 1), -1);
    }
}
