//! [`Mutator`]: new inputs from a corpus, by the mutations that break
//! decoders most often, drawn from a seeded ChaCha generator so a seed
//! names the whole sequence of inputs.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Bytes that sit on the edges of signed and unsigned ranges.
const INTERESTING_BYTES: [u8; 6] = [0x00, 0x01, 0x7F, 0x80, 0xFE, 0xFF];

/// Little-endian 16-bit values on the edges: i16::MIN marks an unknown cell,
/// a tile's area and one past it are where sparse indices end.
const INTERESTING_U16: [u16; 8] = [0, 1, 0x7FFF, 0x8000, 0xFFFF, 64, 4095, 4096];

/// Varint values that make a protobuf length or count lie.
const INTERESTING_VARINTS: [u64; 8] = [
    0,
    1,
    127,
    128,
    0x7FFF_FFFF,
    0xFFFF_FFFF,
    u64::MAX >> 1,
    u64::MAX,
];

/// Words text decoders meet at their edges: numbers out of range or not
/// numbers at all, separators, and the keys of the formats fuzzed.
const TOKENS: [&str; 24] = [
    "0",
    "-1",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "-0",
    "4294967296",
    "99999999999999999999",
    " ",
    "\n",
    "\t",
    ":",
    "=",
    "[",
    "]",
    "{",
    "}",
    ",",
    "\"",
    "#",
    "FLASER",
    "[[obstacle]]",
    "P5\n",
];

/// Longest input made; longer ones are cut, so each exec stays fast.
pub const MAX_LEN: usize = 64 << 10;

/// New inputs from a corpus, deterministically for a seed.
pub struct Mutator {
    rng: ChaCha8Rng,
}

impl Mutator {
    /// A mutator whose sequence of inputs `seed` fixes.
    pub fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// One new input: a corpus entry with one to four mutations stacked.
    /// An empty corpus starts from no bytes.
    pub fn next_input(&mut self, corpus: &[Vec<u8>]) -> Vec<u8> {
        let mut data = if corpus.is_empty() {
            Vec::new()
        } else {
            corpus[self.rng.random_range(0..corpus.len())].clone()
        };
        for _ in 0..self.rng.random_range(1..=4) {
            self.mutate(&mut data, corpus);
        }
        data.truncate(MAX_LEN);
        data
    }

    fn mutate(&mut self, data: &mut Vec<u8>, corpus: &[Vec<u8>]) {
        if data.is_empty() {
            self.insert_random(data);
            return;
        }
        let len = data.len();
        match self.rng.random_range(0..11) {
            0 => {
                let at = self.rng.random_range(0..len);
                data[at] ^= 1 << self.rng.random_range(0..8);
            }
            1 => {
                let at = self.rng.random_range(0..len);
                data[at] = INTERESTING_BYTES[self.rng.random_range(0..INTERESTING_BYTES.len())];
            }
            2 => {
                let at = self.rng.random_range(0..len);
                data[at] = self.rng.random();
            }
            3 => self.insert_random(data),
            4 => {
                let (start, end) = self.range(len);
                data.drain(start..end);
            }
            5 => {
                let (start, end) = self.range(len);
                let copy = data[start..end].to_vec();
                let at = self.rng.random_range(0..=len);
                data.splice(at..at, copy);
            }
            6 => {
                // Splice: this entry's head, another's tail.
                if corpus.is_empty() {
                    return;
                }
                let other = &corpus[self.rng.random_range(0..corpus.len())];
                let cut = self.rng.random_range(0..=len);
                let from = self.rng.random_range(0..=other.len());
                data.truncate(cut);
                data.extend_from_slice(&other[from..]);
            }
            7 => {
                let keep = self.rng.random_range(0..len);
                data.truncate(keep);
            }
            8 => self.tamper_varint(data),
            9 => {
                let value = INTERESTING_U16[self.rng.random_range(0..INTERESTING_U16.len())];
                let at = self.rng.random_range(0..len);
                for (i, b) in value.to_le_bytes().into_iter().enumerate() {
                    if let Some(slot) = data.get_mut(at + i) {
                        *slot = b;
                    }
                }
            }
            _ => {
                let token = TOKENS[self.rng.random_range(0..TOKENS.len())].as_bytes();
                let at = self.rng.random_range(0..=len);
                if self.rng.random() {
                    data.splice(at..at, token.iter().copied());
                } else {
                    // Overwrite a word: the token replaces what was there.
                    let end = (at + token.len()).min(len);
                    data.splice(at..end, token.iter().copied());
                }
            }
        }
    }

    fn insert_random(&mut self, data: &mut Vec<u8>) {
        let at = self.rng.random_range(0..=data.len());
        let count = self.rng.random_range(1..=8);
        let bytes: Vec<u8> = (0..count).map(|_| self.rng.random()).collect();
        data.splice(at..at, bytes);
    }

    /// A non-empty range within `len` bytes, at most 64 long.
    fn range(&mut self, len: usize) -> (usize, usize) {
        let start = self.rng.random_range(0..len);
        let end = self.rng.random_range(start + 1..=len.min(start + 64));
        (start, end)
    }

    /// Replaces the length after a length-delimited protobuf tag (wire
    /// type 2) with an edge value, so a nested message or string claims
    /// more or fewer bytes than follow.
    fn tamper_varint(&mut self, data: &mut Vec<u8>) {
        let tags: Vec<usize> = (0..data.len().saturating_sub(1))
            .filter(|&i| data[i] & 0x07 == 2)
            .collect();
        let at = if tags.is_empty() {
            self.rng.random_range(0..data.len())
        } else {
            tags[self.rng.random_range(0..tags.len())] + 1
        };
        let value = if self.rng.random_range(0..4) == 0 {
            self.rng.random_range(0..=data.len() as u64 + 2)
        } else {
            INTERESTING_VARINTS[self.rng.random_range(0..INTERESTING_VARINTS.len())]
        };
        let old_end = varint_end(data, at);
        data.splice(at..old_end, encode_varint(value));
    }
}

/// Where the varint starting at `at` ends (its last byte has the high bit
/// clear); the data's end when it never does.
fn varint_end(data: &[u8], at: usize) -> usize {
    data[at..]
        .iter()
        .position(|b| b & 0x80 == 0)
        .map_or(data.len(), |p| at + p + 1)
}

fn encode_varint(mut value: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(10);
    loop {
        let byte = (value & 0x7F) as u8;
        value >>= 7;
        if value == 0 {
            out.push(byte);
            return out;
        }
        out.push(byte | 0x80);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corpus() -> Vec<Vec<u8>> {
        vec![
            b"hello world".to_vec(),
            vec![0x0a, 0x03, b'a', b'b', b'c'],
            Vec::new(),
        ]
    }

    #[test]
    fn the_same_seed_makes_the_same_inputs() {
        let corpus = corpus();
        let (mut a, mut b) = (Mutator::new(7), Mutator::new(7));
        for _ in 0..2000 {
            assert_eq!(a.next_input(&corpus), b.next_input(&corpus));
        }
    }

    #[test]
    fn another_seed_makes_other_inputs() {
        let corpus = corpus();
        let (mut a, mut b) = (Mutator::new(7), Mutator::new(8));
        let differ = (0..100)
            .filter(|_| a.next_input(&corpus) != b.next_input(&corpus))
            .count();
        assert!(differ > 50, "only {differ} of 100 inputs differ");
    }

    #[test]
    fn inputs_stay_within_the_length_cap() {
        let corpus = vec![vec![0xAB; MAX_LEN]];
        let mut m = Mutator::new(1);
        for _ in 0..200 {
            assert!(m.next_input(&corpus).len() <= MAX_LEN);
        }
    }

    #[test]
    fn varints_round_trip_their_length() {
        assert_eq!(encode_varint(0), vec![0]);
        assert_eq!(encode_varint(300), vec![0xAC, 0x02]);
        assert_eq!(encode_varint(u64::MAX).len(), 10);
        assert_eq!(varint_end(&[0xAC, 0x02, 0x05], 0), 2);
        assert_eq!(varint_end(&[0x80, 0x80], 0), 2);
    }
}
