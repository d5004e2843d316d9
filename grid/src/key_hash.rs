//! A hasher for small integer keys (tile keys, histogram bins): a
//! multiply and a rotate a word. The standard library's hasher is built
//! to resist keys chosen to collide; these keys come from the program's
//! own cells and particles, never from outside, and are hashed at every
//! cell of a cone or every particle of a frame.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// The hasher: each word is rotated in and multiplied by the golden
/// ratio's odd constant, which spreads low bits upwards.
#[derive(Debug, Default, Clone, Copy)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    #[inline]
    fn write_u64(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }

    #[inline]
    fn write_i64(&mut self, word: i64) {
        self.write_u64(word as u64);
    }

    #[inline]
    fn write_u32(&mut self, word: u32) {
        self.write_u64(u64::from(word));
    }

    #[inline]
    fn write_i32(&mut self, word: i32) {
        self.write_u64(word as u64);
    }
}

/// A map keyed by small integers with [`KeyHasher`].
pub type KeyMap<K, V> = HashMap<K, V, BuildHasherDefault<KeyHasher>>;

/// A set of small integers with [`KeyHasher`].
pub type KeySet<K> = HashSet<K, BuildHasherDefault<KeyHasher>>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TileKey;

    #[test]
    fn neighbouring_tile_keys_hash_apart() {
        let mut seen = KeySet::default();
        let mut hashes = std::collections::HashSet::new();
        for x in -20..20 {
            for y in -20..20 {
                let key = TileKey { x, y };
                assert!(seen.insert(key));
                let mut h = KeyHasher::default();
                std::hash::Hash::hash(&key, &mut h);
                hashes.insert(h.finish());
            }
        }
        assert_eq!(hashes.len(), 1600);
        let map: KeyMap<TileKey, usize> = seen.iter().map(|&k| (k, 1)).collect();
        assert_eq!(map.values().sum::<usize>(), 1600);
    }
}
