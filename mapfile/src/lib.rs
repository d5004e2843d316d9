//! Read and write ROS `map_server` maps: a YAML file of metadata beside a
//! PGM image, one pixel a cell, the image's first row the map's top.
//!
//! # Layout
//! - [`yaml`]: the flat `key: value` YAML, parsed by hand; [`MapYaml`] and
//!   [`Mode`].
//! - [`pgm`]: PGM images, binary `P5` and plain `P2` in, `P5` out.
//! - [`map_image`]: [`MapImage`], a map in memory: loading, map_server's
//!   occupancy rules ([`Cell`]) and cell centres in world coordinates.
//! - [`write`](mod@write): [`write_map`] (PGM + YAML), [`to_png`] (the pixels as
//!   they are) and [`to_png_with_scale_bar`] (the picture people read).
//! - [`canvas`]: [`Canvas`], what the picture helpers draw on (an RGB
//!   plot, a grayscale map), and the quietest corner for a box.
//! - [`font`]: a built-in 5 by 7 bitmap font for legends and labels.
//! - [`scale_bar`]: [`ScaleBar`], a round length in metres drawn to scale.
//! - [`error`]: [`MapFileError`], the crate's one error type.
//!
//! # Example
//! ```
//! use deog_mapfile::{Cell, MapImage, Mode, write_map};
//!
//! let map = MapImage {
//!     width: 2,
//!     height: 1,
//!     resolution: 0.05,
//!     origin: (-1.0, -1.0, 0.0),
//!     negate: false,
//!     occupied_thresh: 0.65,
//!     free_thresh: 0.196,
//!     mode: Mode::Trinary,
//!     pixels: vec![0, 254], // black = occupied, near white = free
//! };
//! assert_eq!(map.occupancy(0, 0), Cell::Occupied);
//! assert_eq!(map.cell_center(1, 0)?, (-0.925, -0.975));
//! let dir = tempfile::tempdir()?;
//! let yaml = write_map(dir.path(), "tiny", &map)?;
//! assert_eq!(MapImage::load(yaml)?, map);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod canvas;
pub mod error;
pub mod font;
pub mod map_image;
pub mod pgm;
pub mod scale_bar;
pub mod write;
pub mod yaml;

pub use canvas::{Canvas, Corner, GrayCanvas, Rect};
pub use error::MapFileError;
pub use map_image::{Cell, MapImage, WorldBox};
pub use pgm::{Pgm, decode_pgm, encode_pgm};
pub use scale_bar::{BarStyle, ScaleBar};
pub use write::{
    encode_png, encode_png_with_scale_bar, encode_rgb_png, encode_yaml, to_png,
    to_png_with_scale_bar, write_map,
};
pub use yaml::{MapYaml, Mode};
