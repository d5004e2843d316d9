//! Writing a [`MapImage`]: map_server's PGM + YAML pair, and PNG: the
//! map's pixels as they are, or as a picture with a scale bar.

use std::path::{Path, PathBuf};

use crate::canvas::{GrayCanvas, Rect};
use crate::error::MapFileError;
use crate::map_image::MapImage;
use crate::pgm::encode_pgm;
use crate::scale_bar::{BarStyle, MOST_WIDTH_FRACTION, ScaleBar, box_size, draw_bar};
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
/// as they are, over a white strip holding a scale bar (a round length in
/// metres, see [`crate::scale_bar`]), so the bar hides no cell. A map too
/// narrow for a readable bar is encoded as it is. The PGM stays the map's
/// data: only this picture carries the bar.
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

/// A copy of `map` (of a checked size) with the strip and its bar below.
fn with_scale_bar(map: &MapImage) -> MapImage {
    let style = BarStyle {
        ink: [0, 0, 0],
        backing: [255, 255, 255],
        scale: if map.width >= 600 { 2 } else { 1 },
        margin: 4,
    };
    let most = (f64::from(map.width) * MOST_WIDTH_FRACTION).floor() as u32;
    let Some(bar) = ScaleBar::choose(1.0 / map.resolution, most) else {
        return map.clone();
    };
    let (width, height) = box_size(&bar, &style);
    if u64::from(width) + 2 * u64::from(style.margin) > u64::from(map.width) {
        return map.clone();
    }
    let strip = height + 2 * style.margin;
    let mut picture = map.clone();
    picture.height += strip;
    picture
        .pixels
        .resize(map.width as usize * picture.height as usize, 255);
    let mut canvas = GrayCanvas {
        width: picture.width,
        height: picture.height,
        pixels: &mut picture.pixels,
    };
    let rect = Rect {
        col: i64::from(style.margin),
        row: i64::from(map.height + style.margin),
        width,
        height,
    };
    draw_bar(&mut canvas, rect, &bar, &style);
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
        // 300 x 200 cells of 5 cm, a wall along the bottom row: at most
        // 75 px of bar, so 2 m, 40 px.
        let mut pixels = vec![254; 300 * 200];
        pixels[199 * 300..].fill(0);
        let map = MapImage {
            width: 300,
            height: 200,
            resolution: 0.05,
            pixels,
            ..tiny()
        };
        let (width, height, picture) = decode_gray(&encode_png_with_scale_bar(&map).expect("png"));
        assert_eq!(width, 300);
        // The map's rows first, every cell as it is; the strip below.
        assert!(height > 200 + 15, "{height}");
        assert_eq!(&picture[..300 * 200], &map.pixels[..]);
        let black_in_row = |row: usize| {
            picture[row * 300..(row + 1) * 300]
                .iter()
                .filter(|&&p| p == 0)
                .count()
        };
        let longest = (200..height as usize)
            .map(black_in_row)
            .max()
            .expect("rows");
        assert_eq!(longest as f64, (2.0f64 / 0.05).round());
        // Unbroken.
        let bar_row = (200..height as usize)
            .find(|&r| black_in_row(r) == longest)
            .expect("bar");
        let row = &picture[bar_row * 300..(bar_row + 1) * 300];
        let first = row.iter().position(|&p| p == 0).expect("ink");
        assert!(row[first..first + longest].iter().all(|&p| p == 0));
        // The map's own PNG stays the cells alone.
        let (_, plain_height, plain) = decode_gray(&encode_png(&map).expect("png"));
        assert_eq!((plain_height, &plain), (200, &map.pixels));
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
