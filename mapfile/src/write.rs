//! Writing a [`MapImage`]: map_server's PGM + YAML pair, and PNG: the
//! map's pixels as they are, or as a picture with a scale bar.

use std::path::{Path, PathBuf};

use crate::canvas::{Corner, GrayCanvas};
use crate::error::MapFileError;
use crate::map_image::{Cell, MapImage};
use crate::pgm::encode_pgm;
use crate::scale_bar::{BarStyle, draw_scale_bar};
use crate::yaml::{check_order, check_resolution, check_threshold};

/// Writes `<dir>/<stem>.pgm` (binary P5) and `<dir>/<stem>.yaml` in
/// map_server's format, the YAML naming the image by its file name so the
/// pair can be moved together. Returns the YAML's path. The map is checked
/// first (pixel count, resolution, thresholds, finite origin), so whatever
/// is written loads back with [`MapImage::load`]; `stem` must be a plain
/// file name.
pub fn write_map(
    dir: impl AsRef<Path>,
    stem: &str,
    map: &MapImage,
) -> Result<PathBuf, MapFileError> {
    let plain = !stem.is_empty()
        && stem != "."
        && stem != ".."
        && !stem.contains(['/', '\\', '\0', '\n', '\r']);
    if !plain {
        return Err(MapFileError::invalid_map(
            "stem",
            format!("must be a plain file name, got {stem:?}"),
        ));
    }
    let dir = dir.as_ref();
    let pgm_path = dir.join(format!("{stem}.pgm"));
    let yaml_path = dir.join(format!("{stem}.yaml"));
    check_map(map, &pgm_path)?;

    let comment = format!("CREATOR: deog-mapfile {:.3} m/pix", map.resolution);
    let pgm = encode_pgm(map.width, map.height, &map.pixels, &comment);
    let yaml = encode_yaml(map, &format!("{stem}.pgm"));
    // The image first: a YAML on disk then always has its image.
    write_file(&pgm_path, &pgm)?;
    write_file(&yaml_path, yaml.as_bytes())?;
    Ok(yaml_path)
}

/// The YAML map_server reads for `map`, naming `image`. Numbers are written
/// in Rust's shortest round-trip form, so they read back bit for bit.
pub fn encode_yaml(map: &MapImage, image: &str) -> String {
    let (x, y, yaw) = map.origin;
    // Quoted (with escapes) only when a bare scalar would not read back.
    let image = if image
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "._-/".contains(c))
    {
        image.to_owned()
    } else {
        format!("\"{}\"", image.replace('\\', "\\\\").replace('"', "\\\""))
    };
    format!(
        "image: {image}\nresolution: {:?}\norigin: [{x:?}, {y:?}, {yaw:?}]\nnegate: {}\noccupied_thresh: {:?}\nfree_thresh: {:?}\nmode: {}\n",
        map.resolution,
        u8::from(map.negate),
        map.occupied_thresh,
        map.free_thresh,
        map.mode.as_str(),
    )
}

/// Encodes `map` as an 8-bit grayscale PNG, the map's top row first, as a
/// viewer shows it.
pub fn encode_png(map: &MapImage) -> Result<Vec<u8>, MapFileError> {
    check_size(map, "<png>")?;
    png_bytes(map).map_err(|e| MapFileError::io("<png>", std::io::Error::other(e)))
}

/// Writes `map` to `path` as an 8-bit grayscale PNG.
pub fn to_png(path: impl AsRef<Path>, map: &MapImage) -> Result<(), MapFileError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    check_size(map, &file)?;
    let bytes = png_bytes(map).map_err(|e| MapFileError::io(&file, std::io::Error::other(e)))?;
    write_file(path, &bytes)
}

/// The map as a picture for people, an 8-bit grayscale PNG: its pixels
/// with a scale bar (a round length in metres, see [`crate::scale_bar`])
/// in the corner holding the fewest known cells. A map too small for a
/// readable bar is encoded as it is. The PGM stays the map's data: only
/// this picture carries the bar.
pub fn encode_png_with_scale_bar(map: &MapImage) -> Result<Vec<u8>, MapFileError> {
    check_size(map, "<png>")?;
    let picture = with_scale_bar(map);
    png_bytes(&picture).map_err(|e| MapFileError::io("<png>", std::io::Error::other(e)))
}

/// Writes `map` to `path` as [`encode_png_with_scale_bar`] encodes it.
pub fn to_png_with_scale_bar(path: impl AsRef<Path>, map: &MapImage) -> Result<(), MapFileError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    check_size(map, &file)?;
    let picture = with_scale_bar(map);
    let bytes =
        png_bytes(&picture).map_err(|e| MapFileError::io(&file, std::io::Error::other(e)))?;
    write_file(path, &bytes)
}

/// A copy of `map` (of a checked size) with the scale bar drawn in.
fn with_scale_bar(map: &MapImage) -> MapImage {
    let mut picture = map.clone();
    let (width, height) = (map.width, map.height);
    let mut canvas = GrayCanvas {
        width,
        height,
        pixels: &mut picture.pixels,
    };
    let style = BarStyle {
        ink: [0, 0, 0],
        backing: [255, 255, 255],
        scale: if width >= 600 { 2 } else { 1 },
        margin: 6,
    };
    // A known cell is busy; the image's rows run from the top, the map's
    // from the bottom.
    let busy = |col: i64, row: i64| {
        let (Ok(col), Ok(row)) = (u32::try_from(col), u32::try_from(row)) else {
            return false;
        };
        row < height && map.occupancy(col, height - 1 - row) != Cell::Unknown
    };
    draw_scale_bar(
        &mut canvas,
        1.0 / map.resolution,
        &style,
        &[
            Corner::BottomLeft,
            Corner::BottomRight,
            Corner::TopLeft,
            Corner::TopRight,
        ],
        &[],
        busy,
    );
    picture
}

fn png_bytes(map: &MapImage) -> Result<Vec<u8>, png::EncodingError> {
    encode(
        map.width,
        map.height,
        png::ColorType::Grayscale,
        &map.pixels,
    )
}

/// Encodes `width * height` RGB triples, the top row first, as an 8-bit
/// RGB PNG (a picture drawn over a map, not a map).
pub fn encode_rgb_png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, MapFileError> {
    let expected = 3 * u64::from(width) * u64::from(height);
    if width == 0 || height == 0 || rgb.len() as u64 != expected {
        return Err(MapFileError::SizeMismatch {
            file: "<png>".to_owned(),
            reason: format!(
                "{width} x {height} RGB needs {expected} bytes (and neither side may be 0), got {}",
                rgb.len()
            ),
        });
    }
    encode(width, height, png::ColorType::Rgb, rgb)
        .map_err(|e| MapFileError::io("<png>", std::io::Error::other(e)))
}

fn encode(
    width: u32,
    height: u32,
    colour: png::ColorType,
    data: &[u8],
) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(colour);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(data)?;
    writer.finish()?;
    Ok(out)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), MapFileError> {
    std::fs::write(path, bytes).map_err(|e| MapFileError::io(&path.display().to_string(), e))
}

/// `pixels` holds `width * height` values, and neither is 0; `file` is
/// what the error names.
fn check_size(map: &MapImage, file: &str) -> Result<(), MapFileError> {
    let expected = u64::from(map.width) * u64::from(map.height);
    if map.width == 0 || map.height == 0 || map.pixels.len() as u64 != expected {
        return Err(MapFileError::SizeMismatch {
            file: file.to_owned(),
            reason: format!(
                "{} x {} needs {expected} pixels (and neither may be 0), the map holds {}",
                map.width,
                map.height,
                map.pixels.len()
            ),
        });
    }
    Ok(())
}

/// Everything [`MapImage::load`] would check, so a written map reads back.
fn check_map(map: &MapImage, pgm_path: &Path) -> Result<(), MapFileError> {
    check_size(map, &pgm_path.display().to_string())?;
    check_resolution(map.resolution).map_err(|r| MapFileError::invalid_map("resolution", r))?;
    let (x, y, yaw) = map.origin;
    if !(x.is_finite() && y.is_finite() && yaw.is_finite()) {
        return Err(MapFileError::invalid_map(
            "origin",
            format!("must be 3 finite numbers, got [{x}, {y}, {yaw}]"),
        ));
    }
    check_threshold(map.occupied_thresh)
        .map_err(|r| MapFileError::invalid_map("occupied_thresh", r))?;
    check_threshold(map.free_thresh).map_err(|r| MapFileError::invalid_map("free_thresh", r))?;
    check_order(map.occupied_thresh, map.free_thresh)
        .map_err(|r| MapFileError::invalid_map("free_thresh", r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::yaml::Mode;

    fn tiny() -> MapImage {
        MapImage {
            width: 2,
            height: 2,
            resolution: 0.1,
            origin: (-0.5, 1.25, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: Mode::Trinary,
            pixels: vec![0, 205, 254, 255],
        }
    }

    #[test]
    fn writes_a_pair_that_loads_back() {
        let dir = tempfile::tempdir().expect("tempdir");
        let map = tiny();
        let yaml = write_map(dir.path(), "tiny", &map).expect("write");
        assert_eq!(yaml, dir.path().join("tiny.yaml"));
        let text = std::fs::read_to_string(&yaml).expect("yaml");
        assert!(text.starts_with("image: tiny.pgm\nresolution: 0.1\norigin: [-0.5, 1.25, 0.0]\n"));
        assert_eq!(MapImage::load(&yaml).expect("load"), map);
    }

    #[test]
    fn rgb_pictures_decode_to_their_pixels_and_bad_sizes_are_refused() {
        let rgb = [255, 0, 0, 0, 255, 0, 0, 0, 255, 1, 2, 3, 4, 5, 6, 7, 8, 9];
        let png = encode_rgb_png(3, 2, &rgb).expect("encode");
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().expect("a PNG");
        let mut out = vec![0; reader.output_buffer_size().expect("size")];
        let frame = reader.next_frame(&mut out).expect("decodes");
        assert_eq!(frame.color_type, png::ColorType::Rgb);
        assert_eq!((frame.width, frame.height), (3, 2));
        assert_eq!(&out[..frame.buffer_size()], &rgb);
        for (w, h, len) in [(3, 2, 17), (0, 2, 0), (3, 0, 0)] {
            let e = encode_rgb_png(w, h, &rgb[..len]).expect_err("refused");
            assert!(matches!(e, MapFileError::SizeMismatch { .. }), "{e}");
        }
    }

    #[test]
    fn odd_image_names_are_quoted() {
        let yaml = encode_yaml(&tiny(), "my \"map\" #1.pgm");
        assert!(
            yaml.starts_with("image: \"my \\\"map\\\" #1.pgm\"\n"),
            "{yaml}"
        );
        let back = crate::yaml::MapYaml::parse(&yaml, "m.yaml").expect("parse");
        assert_eq!(back.image, "my \"map\" #1.pgm");
    }

    #[test]
    fn a_wrong_pixel_count_is_a_size_mismatch() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut map = tiny();
        map.pixels.pop();
        let e = write_map(dir.path(), "tiny", &map).expect_err("size");
        assert!(e.to_string().ends_with(
            "tiny.pgm: size mismatch: 2 x 2 needs 4 pixels (and neither may be 0), the map holds 3"
        ), "{e}");
        assert!(matches!(
            encode_png(&map),
            Err(MapFileError::SizeMismatch { .. })
        ));
        assert!(!dir.path().join("tiny.yaml").exists());
    }

    #[test]
    fn invalid_fields_are_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut map = tiny();
        map.free_thresh = 0.9;
        let e = write_map(dir.path(), "tiny", &map).expect_err("order");
        assert_eq!(
            e.to_string(),
            "free_thresh: must not exceed occupied_thresh (0.65), got 0.9"
        );
        let mut map = tiny();
        map.resolution = f64::NAN;
        let e = write_map(dir.path(), "tiny", &map).expect_err("nan");
        assert_eq!(
            e.to_string(),
            "resolution: must be a positive number, got NaN"
        );
        for stem in ["", "..", "a/b"] {
            let e = write_map(dir.path(), stem, &tiny()).expect_err("stem");
            assert!(e.to_string().starts_with("stem: must be a plain file name"));
        }
    }

    fn decode_gray(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().expect("info");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("frame");
        assert_eq!(info.color_type, png::ColorType::Grayscale);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    #[test]
    fn the_picture_carries_a_scale_bar_of_its_metres_over_the_resolution() {
        // 300 x 200 free cells of 5 cm: at most 75 px of bar, so 2 m, 40 px.
        let map = MapImage {
            width: 300,
            height: 200,
            resolution: 0.05,
            pixels: vec![254; 300 * 200],
            ..tiny()
        };
        let (width, height, pixels) = decode_gray(&encode_png_with_scale_bar(&map).expect("png"));
        assert_eq!((width, height), (300, 200));
        let black_in_row = |row: usize| {
            pixels[row * 300..(row + 1) * 300]
                .iter()
                .filter(|&&p| p == 0)
                .count()
        };
        let longest = (0..200).map(black_in_row).max().expect("rows");
        assert_eq!(longest as f64, (2.0f64 / 0.05).round());
        // In the bottom left corner, and the rest of the map untouched.
        let bar_row = (0..200).find(|&r| black_in_row(r) == longest).expect("bar");
        assert!(bar_row > 150, "{bar_row}");
        assert_eq!(pixels[bar_row * 300 + 250], 254);
        assert_eq!(pixels[10 * 300 + 150], 254);
        // The map's own PNG and PGM stay the cells alone.
        let (_, _, plain) = decode_gray(&encode_png(&map).expect("png"));
        assert!(plain.iter().all(|&p| p == 254));
    }

    #[test]
    fn a_map_too_small_for_a_bar_is_pictured_as_it_is() {
        let (_, _, pixels) = decode_gray(&encode_png_with_scale_bar(&tiny()).expect("png"));
        assert_eq!(pixels, tiny().pixels);
        let mut bad = tiny();
        bad.pixels.pop();
        assert!(matches!(
            encode_png_with_scale_bar(&bad),
            Err(MapFileError::SizeMismatch { .. })
        ));
    }

    #[test]
    fn png_decodes_to_the_same_pixels() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("tiny.png");
        to_png(&path, &tiny()).expect("png");
        let decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(&path).expect("open"),
        ));
        let mut reader = decoder.read_info().expect("info");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("frame");
        assert_eq!((info.width, info.height), (2, 2));
        assert_eq!(info.color_type, png::ColorType::Grayscale);
        assert_eq!(&buf[..info.buffer_size()], &tiny().pixels[..]);
    }
}
