//! PGM images: binary `P5` and plain `P2` in (maxval 1..=255, `#` comments
//! in the header), binary `P5` out.

use crate::error::MapFileError;

/// A decoded grayscale image, 8 bits a pixel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pgm {
    /// Pixels a row, >= 1.
    pub width: u32,
    /// Rows, >= 1.
    pub height: u32,
    /// Row-major, the file's first row first (the map's top); scaled to
    /// 0..=255 when the file's maxval is below 255, as map_server's image
    /// loader does, so 255 is always white.
    pub pixels: Vec<u8>,
}

/// Decodes a PGM; `file` names it in errors.
pub fn decode_pgm(bytes: &[u8], file: &str) -> Result<Pgm, MapFileError> {
    let mut r = Reader {
        bytes,
        pos: 0,
        file,
    };
    let binary = match bytes.get(..2) {
        Some(b"P5") => true,
        Some(b"P2") => false,
        Some(other) => {
            return Err(MapFileError::WrongMagic {
                file: file.to_owned(),
                found: String::from_utf8_lossy(other).into_owned(),
            });
        }
        None => return Err(r.truncated("the file is shorter than its magic number")),
    };
    r.pos = 2;
    let width = r.header_number("width")?;
    let height = r.header_number("height")?;
    let maxval = r.header_number("maxval")?;
    if width == 0 || height == 0 {
        return Err(r.bad(format!(
            "width and height must be >= 1, got {width} x {height}"
        )));
    }
    if !(1..=255).contains(&maxval) {
        return Err(r.bad(format!(
            "maxval must be 1..=255 (16-bit images are not supported), got {maxval}"
        )));
    }
    let count = u64::from(width) * u64::from(height);
    let count = usize::try_from(count)
        .map_err(|_| r.bad(format!("{width} x {height} pixels do not fit in memory")))?;

    let raw = if binary {
        // Exactly one whitespace byte separates maxval from the raster; the
        // raster's first byte may itself look like whitespace.
        match r.bytes.get(r.pos) {
            Some(c) if c.is_ascii_whitespace() => r.pos += 1,
            Some(_) => return Err(r.bad("no whitespace after maxval".into())),
            None => return Err(r.truncated(&format!("no pixels (expected {count} bytes)"))),
        }
        let data = &bytes[r.pos..];
        if data.len() < count {
            return Err(r.truncated(&format!(
                "expected {count} pixel bytes ({width} x {height}), got {}",
                data.len()
            )));
        }
        if data.len() > count {
            return Err(MapFileError::SizeMismatch {
                file: file.to_owned(),
                reason: format!(
                    "the header says {width} x {height} = {count} pixels but {} bytes follow it",
                    data.len()
                ),
            });
        }
        data.to_vec()
    } else {
        // A plain raster can hold no more pixels than it has bytes, so this
        // capacity never exceeds the file's size.
        let mut values = Vec::with_capacity(count.min(bytes.len()));
        while values.len() < count {
            match r.number()? {
                Some(v) if v <= maxval => values.push(v as u8), // maxval <= 255
                Some(v) => {
                    let (i, w) = (values.len(), width as usize);
                    return Err(r.bad(format!(
                        "pixel (column {}, row {}) is {v}, above maxval {maxval}",
                        i % w,
                        i / w
                    )));
                }
                None => {
                    return Err(r.truncated(&format!(
                        "expected {count} pixel values ({width} x {height}), got {}",
                        values.len()
                    )));
                }
            }
        }
        if r.number()?.is_some() {
            return Err(MapFileError::SizeMismatch {
                file: file.to_owned(),
                reason: format!(
                    "the header says {width} x {height} = {count} pixels but more values follow"
                ),
            });
        }
        values
    };

    let maxval = maxval as u8; // checked 1..=255 above
    if let Some(i) = raw.iter().position(|&v| v > maxval) {
        let w = width as usize;
        return Err(r.bad(format!(
            "pixel (column {}, row {}) is {}, above maxval {maxval}",
            i % w,
            i / w,
            raw[i]
        )));
    }
    let pixels = if maxval == u8::MAX {
        raw
    } else {
        let m = u32::from(maxval);
        raw.into_iter()
            .map(|v| ((u32::from(v) * 255 + m / 2) / m) as u8) // <= 255 since v <= m
            .collect()
    };
    Ok(Pgm {
        width,
        height,
        pixels,
    })
}

/// Encodes a binary `P5` PGM with maxval 255 and a `# CREATOR` comment, as
/// map_saver does. Does not check that `pixels` holds `width * height`
/// values; callers do.
pub fn encode_pgm(width: u32, height: u32, pixels: &[u8], comment: &str) -> Vec<u8> {
    // A newline in the comment would end it and corrupt the header.
    let comment = comment.replace(['\n', '\r'], " ");
    let mut out = format!("P5\n# {comment}\n{width} {height}\n255\n").into_bytes();
    out.extend_from_slice(pixels);
    out
}

/// A cursor over the file's bytes.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    file: &'a str,
}

impl Reader<'_> {
    fn truncated(&self, reason: &str) -> MapFileError {
        MapFileError::Truncated {
            file: self.file.to_owned(),
            reason: reason.to_owned(),
        }
    }

    fn bad(&self, reason: String) -> MapFileError {
        MapFileError::BadImage {
            file: self.file.to_owned(),
            reason,
        }
    }

    /// Skips whitespace and `#` comments (which run to the end of the line).
    fn skip_space(&mut self) {
        while let Some(&c) = self.bytes.get(self.pos) {
            if c == b'#' {
                while let Some(&c) = self.bytes.get(self.pos) {
                    if c == b'\n' || c == b'\r' {
                        break;
                    }
                    self.pos += 1;
                }
            } else if c.is_ascii_whitespace() {
                self.pos += 1;
            } else {
                break;
            }
        }
    }

    /// The next decimal number, `None` at the end of the file.
    fn number(&mut self) -> Result<Option<u32>, MapFileError> {
        self.skip_space();
        let start = self.pos;
        let mut value: u32 = 0;
        while let Some(&c) = self.bytes.get(self.pos) {
            if !c.is_ascii_digit() {
                break;
            }
            value = value
                .checked_mul(10)
                .and_then(|v| v.checked_add(u32::from(c - b'0')))
                .ok_or_else(|| self.bad(format!("number too large at byte {start}")))?;
            self.pos += 1;
        }
        match self.bytes.get(self.pos) {
            _ if self.pos > start => Ok(Some(value)),
            None => Ok(None),
            Some(&c) => Err(self.bad(format!(
                "expected a decimal number at byte {start}, got {:?}",
                char::from(c)
            ))),
        }
    }

    /// A header number, named in errors.
    fn header_number(&mut self, what: &str) -> Result<u32, MapFileError> {
        match self.number() {
            Ok(Some(v)) => Ok(v),
            Ok(None) => Err(self.truncated(&format!("the header ends before {what}"))),
            Err(MapFileError::BadImage { reason, .. }) => {
                Err(self.bad(format!("{what}: {reason}")))
            }
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(bytes: &[u8]) -> String {
        match decode_pgm(bytes, "map.pgm") {
            Ok(p) => panic!("decoded {p:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn decodes_binary_with_comments() {
        let p = decode_pgm(b"P5\n# hi\n3 # w\n2\n255\n\x00\x01\x02\x03\x0a\xff", "m").expect("pgm");
        assert_eq!((p.width, p.height), (3, 2));
        assert_eq!(p.pixels, vec![0, 1, 2, 3, 10, 255]);
    }

    #[test]
    fn decodes_plain_and_scales_maxval() {
        let p = decode_pgm(b"P2\n2 2\n15\n0 15\n# mid\n 5 10\n", "m").expect("pgm");
        assert_eq!(p.pixels, vec![0, 255, 85, 170]);
    }

    #[test]
    fn round_trips_through_encode() {
        let pixels: Vec<u8> = (0..=255).collect();
        let bytes = encode_pgm(16, 16, &pixels, "CREATOR: test\nsneaky");
        let p = decode_pgm(&bytes, "m").expect("pgm");
        assert_eq!(p.pixels, pixels);
    }

    #[test]
    fn wrong_magic_is_named() {
        assert_eq!(
            err(b"P6\n1 1\n255\n\0\0\0"),
            "map.pgm: not a grayscale PGM: magic \"P6\", expected \"P5\" or \"P2\""
        );
        assert!(err(b"\x89PNG\r\n").contains("not a grayscale PGM"));
    }

    #[test]
    fn truncated_files_are_errors() {
        assert_eq!(
            err(b""),
            "map.pgm: truncated: the file is shorter than its magic number"
        );
        assert_eq!(
            err(b"P5\n3 2\n"),
            "map.pgm: truncated: the header ends before maxval"
        );
        assert_eq!(
            err(b"P5\n3 2\n255\n\0\0\0"),
            "map.pgm: truncated: expected 6 pixel bytes (3 x 2), got 3"
        );
        assert_eq!(
            err(b"P2\n3 2\n255\n1 2 3 4"),
            "map.pgm: truncated: expected 6 pixel values (3 x 2), got 4"
        );
        assert!(err(b"P5\n1 1\n255").contains("truncated: no pixels"));
    }

    #[test]
    fn extra_pixels_are_a_size_mismatch() {
        assert_eq!(
            err(b"P5\n2 1\n255\n\0\0\0"),
            "map.pgm: size mismatch: the header says 2 x 1 = 2 pixels but 3 bytes follow it"
        );
        assert!(err(b"P2\n1 1\n255\n1 2\n").contains("size mismatch"));
    }

    #[test]
    fn bad_headers_and_pixels_are_errors() {
        assert!(err(b"P5\n0 2\n255\n").contains("width and height must be >= 1"));
        assert!(err(b"P5\n2 2\n65535\n").contains("maxval must be 1..=255"));
        assert!(err(b"P5\nx 2\n255\n").contains("width: expected a decimal number"));
        assert!(err(b"P5\n99999999999 2\n255\n").contains("width: number too large"));
        assert_eq!(
            err(b"P5\n2 1\n100\n\x05\xc8"),
            "map.pgm: pixel (column 1, row 0) is 200, above maxval 100"
        );
        assert!(err(b"P2\n2 1\n255\n1 300\n").contains("above maxval"));
        assert!(err(b"P2\n2 1\n255\n1 x\n").contains("expected a decimal number"));
    }

    #[test]
    fn a_huge_header_does_not_allocate_it() {
        // 4 billion x 4 billion pixels claimed, four bytes given.
        assert!(err(b"P5\n4000000000 4000000000\n255\n\0\0\0\0").contains("truncated"));
        assert!(err(b"P2\n4000000000 4000000000\n255\n1 2").contains("truncated"));
    }
}
