//! CDR, the byte layout ROS 2 messages travel and are recorded in: a
//! four-byte encapsulation header, then each field aligned to its own size
//! (counted from the end of the header), sequences and strings led by a
//! `u32` count, strings ending in a NUL.
//!
//! The writer writes little-endian (`CDR_LE`, what rosbag2 records); the
//! reader takes either byte order.

use crate::error::RecordingError;

/// The encapsulation header of little-endian plain CDR.
const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// The bytes before the aligned body.
const HEADER_LEN: usize = 4;

/// Builds one message's CDR bytes.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    bytes: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    /// A message with its encapsulation header written.
    pub fn new() -> Self {
        Self {
            bytes: CDR_LE_HEADER.to_vec(),
        }
    }

    /// The finished message.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    fn align(&mut self, size: usize) {
        while (self.bytes.len() - HEADER_LEN) % size != 0 {
            self.bytes.push(0);
        }
    }

    /// An `uint8`.
    pub fn u8(&mut self, value: u8) {
        self.bytes.push(value);
    }

    /// An `int8`.
    pub fn i8(&mut self, value: i8) {
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// An `int32`.
    pub fn i32(&mut self, value: i32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// An `uint32`.
    pub fn u32(&mut self, value: u32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// A `float32`.
    pub fn f32(&mut self, value: f32) {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, value: f64) {
        self.align(8);
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    /// The count that leads a sequence. Messages longer than `u32::MAX`
    /// elements cannot be written in CDR; callers bound their sequences
    /// well below it.
    pub fn sequence_len(&mut self, len: usize) {
        self.u32(u32::try_from(len).unwrap_or(u32::MAX));
    }

    /// A `string`: its length with the NUL, its bytes, the NUL.
    pub fn string(&mut self, value: &str) {
        self.sequence_len(value.len() + 1);
        self.bytes.extend_from_slice(value.as_bytes());
        self.bytes.push(0);
    }

    /// A `float32[]`.
    pub fn f32_sequence(&mut self, values: &[f32]) {
        self.sequence_len(values.len());
        for &v in values {
            self.f32(v);
        }
    }

    /// An `int8[]`.
    pub fn i8_sequence(&mut self, values: &[i8]) {
        self.sequence_len(values.len());
        for &v in values {
            self.i8(v);
        }
    }
}

/// Reads one message's CDR bytes, field by field. Every read checks the
/// bytes left, so a short or corrupt message is an error, never a panic;
/// bytes after the last field read are ignored (a newer definition may
/// append fields).
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    position: usize,
    little_endian: bool,
}

impl<'a> CdrReader<'a> {
    /// A reader of `bytes`, its encapsulation header checked: plain CDR,
    /// either byte order.
    pub fn new(bytes: &'a [u8]) -> Result<Self, RecordingError> {
        let Some((header, body)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(RecordingError::Cdr(format!(
                "{} bytes are too short for the CDR encapsulation header",
                bytes.len()
            )));
        };
        let little_endian = match header[..2] {
            [0x00, 0x00] => false,
            [0x00, 0x01] => true,
            _ => {
                return Err(RecordingError::Cdr(format!(
                    "encapsulation {:02x} {:02x} is not plain CDR (00 00 or 00 01)",
                    header[0], header[1]
                )));
            }
        };
        Ok(Self {
            body,
            position: 0,
            little_endian,
        })
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], RecordingError> {
        // Primitives are aligned to their own size.
        let start = self.position.next_multiple_of(N.max(1));
        let bytes = start
            .checked_add(N)
            .and_then(|end| self.body.get(start..end))
            .ok_or_else(|| {
                RecordingError::Cdr(format!(
                    "the message ends before its {what} (byte {start} of {})",
                    self.body.len()
                ))
            })?;
        self.position = start + N;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        if !self.little_endian {
            out.reverse();
        }
        Ok(out)
    }

    /// An `uint8`.
    pub fn u8(&mut self, what: &str) -> Result<u8, RecordingError> {
        Ok(self.take::<1>(what)?[0])
    }

    /// An `int8`.
    pub fn i8(&mut self, what: &str) -> Result<i8, RecordingError> {
        Ok(i8::from_le_bytes(self.take::<1>(what)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, what: &str) -> Result<i32, RecordingError> {
        Ok(i32::from_le_bytes(self.take::<4>(what)?))
    }

    /// An `uint32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, RecordingError> {
        Ok(u32::from_le_bytes(self.take::<4>(what)?))
    }

    /// A `float32`.
    pub fn f32(&mut self, what: &str) -> Result<f32, RecordingError> {
        Ok(f32::from_le_bytes(self.take::<4>(what)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, RecordingError> {
        Ok(f64::from_le_bytes(self.take::<8>(what)?))
    }

    /// A sequence's count, checked against the bytes left: each element
    /// takes at least `element_size` bytes, so a corrupt count cannot make
    /// the reader allocate more than the message holds.
    pub fn sequence_len(
        &mut self,
        what: &str,
        element_size: usize,
    ) -> Result<usize, RecordingError> {
        let len = self.u32(what)? as usize;
        let left = self.body.len() - self.position;
        if len.saturating_mul(element_size) > left {
            return Err(RecordingError::Cdr(format!(
                "{what} claims {len} elements, more than the {left} bytes left hold"
            )));
        }
        Ok(len)
    }

    /// A `string`.
    pub fn string(&mut self, what: &str) -> Result<String, RecordingError> {
        let len = self.sequence_len(what, 1)?;
        let bytes = &self.body[self.position..self.position + len];
        self.position += len;
        // The count includes the NUL; some writers leave it out of an empty
        // string (a count of 0).
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec())
            .map_err(|_| RecordingError::Cdr(format!("{what} is not UTF-8")))
    }

    /// A `float32[]`.
    pub fn f32_sequence(&mut self, what: &str) -> Result<Vec<f32>, RecordingError> {
        let len = self.sequence_len(what, 4)?;
        (0..len).map(|_| self.f32(what)).collect()
    }

    /// An `int8[]`.
    pub fn i8_sequence(&mut self, what: &str) -> Result<Vec<i8>, RecordingError> {
        let len = self.sequence_len(what, 1)?;
        (0..len).map(|_| self.i8(what)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_aligned_to_their_size_after_the_header() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("ab");
        w.f32(2.0);
        let bytes = w.into_bytes();
        // header, u8, 7 pad, f64, u32 len 3, "ab\0", pad 1, f32
        assert_eq!(bytes.len(), 4 + 1 + 7 + 8 + 4 + 3 + 1 + 4);
        assert_eq!(&bytes[..4], &CDR_LE_HEADER);
        assert_eq!(&bytes[12..20], &1.5f64.to_le_bytes());
        assert_eq!(&bytes[20..24], &3u32.to_le_bytes());
        assert_eq!(&bytes[24..27], b"ab\0");
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u8("a").unwrap(), 7);
        assert_eq!(r.f64("b").unwrap(), 1.5);
        assert_eq!(r.string("c").unwrap(), "ab");
        assert_eq!(r.f32("d").unwrap(), 2.0);
        assert!(r.u8("e").is_err());
    }

    #[test]
    fn big_endian_messages_read_too() {
        // 00 00: CDR_BE; an int32 of 1 then a float64 of 2.0.
        let mut bytes = vec![0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0];
        bytes.extend_from_slice(&2.0f64.to_be_bytes());
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.i32("a").unwrap(), 1);
        assert_eq!(r.f64("b").unwrap(), 2.0);
    }

    #[test]
    fn short_headers_other_encapsulations_and_huge_counts_are_errors() {
        assert!(CdrReader::new(&[0, 1]).is_err());
        let err = CdrReader::new(&[0, 3, 0, 0]).unwrap_err().to_string();
        assert!(err.contains("not plain CDR"), "{err}");
        let mut bytes = CDR_LE_HEADER.to_vec();
        bytes.extend_from_slice(&u32::MAX.to_le_bytes());
        let err = CdrReader::new(&bytes)
            .unwrap()
            .f32_sequence("ranges")
            .unwrap_err()
            .to_string();
        assert!(err.contains("ranges claims"), "{err}");
    }
}
