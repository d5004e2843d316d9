//! The scans as the OctoMap script reads them: per scan, the sensor's
//! origin and the echoes as points, world frame, in a small binary file
//! that Python reads with `struct` and `numpy.frombuffer`.
//!
//! Layout, little-endian throughout:
//!
//! ```text
//! magic    8 bytes   "DEOGPC01"
//! scans    u32
//! per scan:
//!   origin x, y      f64, f64   metres, world frame
//!   points           u32
//!   per point: x, y  f64, f64   metres, world frame
//! ```
//!
//! The plane is z = 0: the script adds the third coordinate.

use std::io::{self, Write};

/// The file's first eight bytes.
const MAGIC: &[u8; 8] = b"DEOGPC01";

/// One scan, world frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ScanCloud {
    /// Where the rays start, metres.
    pub origin: [f64; 2],
    /// Where each echo is, metres; beams without one are left out.
    pub points: Vec<[f64; 2]>,
}

/// Writes `scans` in the layout above.
pub(crate) fn write_clouds(mut out: impl Write, scans: &[ScanCloud]) -> io::Result<()> {
    out.write_all(MAGIC)?;
    out.write_all(&count_u32(scans.len())?.to_le_bytes())?;
    for scan in scans {
        for v in scan.origin {
            out.write_all(&v.to_le_bytes())?;
        }
        out.write_all(&count_u32(scan.points.len())?.to_le_bytes())?;
        for point in &scan.points {
            for v in point {
                out.write_all(&v.to_le_bytes())?;
            }
        }
    }
    out.flush()
}

fn count_u32(n: usize) -> io::Result<u32> {
    u32::try_from(n).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{n} is too many for the file's u32 count"),
        )
    })
}

#[cfg(test)]
mod tests {
    use std::io::{self, Read};

    use super::*;

    /// Reads the file as `bench/octomap_insert.py` does, field by field.
    fn read_clouds(mut input: impl Read) -> io::Result<Vec<ScanCloud>> {
        let mut magic = [0u8; 8];
        input.read_exact(&mut magic)?;
        if &magic != MAGIC {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "not a deog point-cloud file (bad magic)",
            ));
        }
        let scans = read_u32(&mut input)?;
        let mut out = Vec::new();
        for _ in 0..scans {
            let origin = [read_f64(&mut input)?, read_f64(&mut input)?];
            let count = read_u32(&mut input)?;
            let points = (0..count)
                .map(|_| Ok([read_f64(&mut input)?, read_f64(&mut input)?]))
                .collect::<io::Result<Vec<_>>>()?;
            out.push(ScanCloud { origin, points });
        }
        Ok(out)
    }

    fn read_u32(input: &mut impl Read) -> io::Result<u32> {
        let mut bytes = [0u8; 4];
        input.read_exact(&mut bytes)?;
        Ok(u32::from_le_bytes(bytes))
    }

    fn read_f64(input: &mut impl Read) -> io::Result<f64> {
        let mut bytes = [0u8; 8];
        input.read_exact(&mut bytes)?;
        Ok(f64::from_le_bytes(bytes))
    }

    #[test]
    fn clouds_round_trip_bit_for_bit() {
        let scans = vec![
            ScanCloud {
                origin: [1.5, -2.25],
                points: vec![[0.1, 0.2], [-1e-9, 81.83], [f64::MIN_POSITIVE, -0.0]],
            },
            ScanCloud {
                origin: [0.0, 0.0],
                points: vec![],
            },
            ScanCloud {
                origin: [-30.0, 12.0],
                points: vec![[3.0, 4.0]],
            },
        ];
        let mut bytes = Vec::new();
        write_clouds(&mut bytes, &scans).expect("write");
        // magic, count, then 3 scans of (16 + 4) bytes and 4 points of 16.
        assert_eq!(bytes.len(), 8 + 4 + 3 * 20 + 4 * 16);
        assert_eq!(&bytes[..8], MAGIC);
        let back = read_clouds(bytes.as_slice()).expect("read");
        assert_eq!(back, scans);
        assert!(back[0].points[2][1].is_sign_negative(), "-0.0 kept");
    }

    #[test]
    fn a_file_of_another_kind_or_cut_short_is_refused() {
        let mut bytes = Vec::new();
        write_clouds(
            &mut bytes,
            &[ScanCloud {
                origin: [0.0, 0.0],
                points: vec![[1.0, 1.0]],
            }],
        )
        .expect("write");
        let mut wrong = bytes.clone();
        wrong[0] = b'X';
        assert_eq!(
            read_clouds(wrong.as_slice()).expect_err("magic").kind(),
            io::ErrorKind::InvalidData
        );
        let short = &bytes[..bytes.len() - 1];
        assert_eq!(
            read_clouds(short).expect_err("short").kind(),
            io::ErrorKind::UnexpectedEof
        );
    }
}
