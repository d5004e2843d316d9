//! Reading a log: text from any reader, or a file on disk, plain or
//! gzip-compressed.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use flate2::read::MultiGzDecoder;

use crate::error::LogError;
use crate::log::CarmenLog;
use crate::record::{Record, parse_line};

/// The first two bytes of every gzip stream.
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

impl CarmenLog {
    /// Reads a log's text. `origin` names it in errors (a path, "stdin",
    /// a test's name). Any malformed line fails the whole log.
    pub fn parse(reader: impl BufRead, origin: &str) -> Result<Self, LogError> {
        let records = read_records(reader, origin)?;
        Self::from_records(origin, records)
    }

    /// Reads a log from its text.
    pub fn parse_str(text: &str, origin: &str) -> Result<Self, LogError> {
        Self::parse(text.as_bytes(), origin)
    }

    /// Reads a log file: gzip-compressed when it starts with the gzip magic
    /// bytes or its name ends in `.gz`, plain text otherwise. Errors name
    /// the path.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LogError> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let read_error = |source| LogError::Read {
            origin: origin.clone(),
            source,
        };
        let mut file = BufReader::new(File::open(path).map_err(read_error)?);
        let gzipped = file
            .fill_buf()
            .map_err(read_error)?
            .starts_with(&GZIP_MAGIC)
            || path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
        let reader: Box<dyn BufRead> = if gzipped {
            Box::new(BufReader::new(MultiGzDecoder::new(file)))
        } else {
            Box::new(file)
        };
        Self::parse(reader, &origin)
    }
}

/// Every line's record with its 1-based number.
fn read_records(mut reader: impl BufRead, origin: &str) -> Result<Vec<(usize, Record)>, LogError> {
    let mut records = Vec::new();
    let mut buf = Vec::new();
    let mut line = 0;
    loop {
        buf.clear();
        let read = reader
            .by_ref()
            .read_until(b'\n', &mut buf)
            .map_err(|source| LogError::Read {
                origin: origin.to_owned(),
                source,
            })?;
        if read == 0 {
            return Ok(records);
        }
        line += 1;
        let text = std::str::from_utf8(&buf)
            .map_err(|_| LogError::malformed(origin, line, "not UTF-8 text"))?;
        let record =
            parse_line(text).map_err(|reason| LogError::malformed(origin, line, reason))?;
        // Skipped lines play no part in anything after this.
        if !matches!(record, Record::Skip) {
            records.push((line, record));
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use flate2::Compression;
    use flate2::write::GzEncoder;

    use super::*;

    const TEXT: &str = "ODOM 0 0 0 0 0 0 1 h 1\nFLASER 2 1 2 0 0 0 0 0 0 1 h 1\n";

    fn gzip(text: &str) -> Vec<u8> {
        let mut encoder = GzEncoder::new(Vec::new(), Compression::fast());
        encoder.write_all(text.as_bytes()).unwrap();
        encoder.finish().unwrap()
    }

    #[test]
    fn plain_and_gzip_files_read_alike() {
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("a.log");
        let gz = dir.path().join("a.log.gz");
        // Compressed though its name does not say so: the magic bytes tell.
        let hidden = dir.path().join("b.log");
        std::fs::write(&plain, TEXT).unwrap();
        std::fs::write(&gz, gzip(TEXT)).unwrap();
        std::fs::write(&hidden, gzip(TEXT)).unwrap();
        let want = CarmenLog::parse_str(TEXT, &plain.display().to_string()).unwrap();
        assert_eq!(CarmenLog::load(&plain).unwrap(), want);
        for path in [&gz, &hidden] {
            let log = CarmenLog::load(path).unwrap();
            assert_eq!(log.scans(), want.scans());
            assert_eq!(log.origin(), path.display().to_string());
        }
    }

    #[test]
    fn unreadable_files_name_their_path() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.log");
        let err = CarmenLog::load(&missing).unwrap_err();
        assert!(matches!(err, LogError::Read { .. }), "{err}");
        assert!(err.to_string().contains("missing.log"), "{err}");
        // Named .gz but not gzip.
        let fake = dir.path().join("fake.log.gz");
        std::fs::write(&fake, TEXT).unwrap();
        let err = CarmenLog::load(&fake).unwrap_err();
        assert!(
            err.to_string()
                .starts_with(&format!("reading {}", fake.display())),
            "{err}"
        );
        // Cut short.
        let cut = dir.path().join("cut.log.gz");
        let bytes = gzip(&TEXT.repeat(50));
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        assert!(matches!(CarmenLog::load(&cut), Err(LogError::Read { .. })));
    }
}
