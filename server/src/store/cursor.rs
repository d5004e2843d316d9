//! What a map remembers of one client's batches: the highest applied
//! sequence and the most recent applied ones, so that a resend (applied
//! before, acknowledged again) can be told from a batch that arrives out of
//! order (never applied, and now too late to be).
//!
//! Encoding, little-endian: the highest sequence (u64), then, from format 2
//! on, a format byte, a flags byte (bit 0: the list holds every sequence ever
//! applied), a count (u16) and that many sequences (u64, ascending). A record
//! of the highest sequence alone is what servers before format 2 wrote; it
//! loads with an empty, incomplete list. Servers before format 2 read the
//! first eight bytes and ignore the rest.

use crate::error::StoreError;
use std::collections::VecDeque;

const FORMAT: u8 = 2;
const COMPLETE: u8 = 1;

/// Applied sequences a cursor keeps beyond the highest: enough to tell any
/// resend of a client's pipeline window from a batch out of order.
pub const RECENT_SEQUENCES: usize = 1024;

/// One client's applied batches on one map.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ClientCursor {
    /// Highest applied sequence; 0 if none.
    pub last: u64,
    /// The most recent applied sequences, ascending, the last of them
    /// `last`; at most [`RECENT_SEQUENCES`].
    pub recent: VecDeque<u64>,
    /// Whether `recent` holds every sequence ever applied: it was never
    /// trimmed, and it was not loaded from a record that kept no list.
    pub complete: bool,
}

/// What a batch's sequence is to a cursor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceCheck {
    /// Above the highest applied: apply it.
    Next,
    /// Applied before: a resend, acknowledged without applying it again.
    Applied,
    /// Below the highest applied and, as the kept sequences show, never
    /// applied: the client's sequences went backwards.
    NeverApplied,
    /// Below every kept sequence (or no list was kept): applied or not
    /// cannot be told, so it is taken for a resend, as before the list.
    Unknown,
}

impl ClientCursor {
    /// A cursor with no batch applied.
    pub fn new() -> Self {
        Self {
            last: 0,
            recent: VecDeque::new(),
            complete: true,
        }
    }

    /// What `sequence` is to this cursor.
    pub fn check(&self, sequence: u64) -> SequenceCheck {
        if sequence > self.last {
            return SequenceCheck::Next;
        }
        if self.recent.binary_search(&sequence).is_ok() {
            return SequenceCheck::Applied;
        }
        let kept_from = if self.complete {
            Some(0)
        } else {
            self.recent.front().copied()
        };
        match kept_from {
            Some(lowest) if sequence > lowest => SequenceCheck::NeverApplied,
            _ => SequenceCheck::Unknown,
        }
    }

    /// Records `sequence` as applied; it must be above `last`.
    pub fn applied(&mut self, sequence: u64) {
        debug_assert!(sequence > self.last);
        self.last = sequence;
        self.recent.push_back(sequence);
        while self.recent.len() > RECENT_SEQUENCES {
            self.recent.pop_front();
            self.complete = false;
        }
    }

    /// The stored form.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(12 + self.recent.len() * 8);
        out.extend_from_slice(&self.last.to_le_bytes());
        out.push(FORMAT);
        out.push(if self.complete { COMPLETE } else { 0 });
        // At most RECENT_SEQUENCES, well inside u16.
        let count = u16::try_from(self.recent.len()).unwrap_or(u16::MAX);
        out.extend_from_slice(&count.to_le_bytes());
        for sequence in self.recent.iter().take(usize::from(count)) {
            out.extend_from_slice(&sequence.to_le_bytes());
        }
        out
    }

    /// Decodes the cursor of `client`, in either format.
    pub fn decode(client: &str, bytes: &[u8]) -> Result<Self, StoreError> {
        let corrupt = |reason: &str| StoreError::Corrupt {
            what: format!("cursor of client {client:?}"),
            reason: reason.to_string(),
        };
        let (last, rest) = bytes
            .split_first_chunk::<8>()
            .ok_or_else(|| corrupt("truncated"))?;
        let last = u64::from_le_bytes(*last);
        let Some((&format, rest)) = rest.split_first() else {
            // Written before the list was kept.
            return Ok(Self {
                last,
                recent: VecDeque::new(),
                complete: last == 0,
            });
        };
        if format != FORMAT {
            return Err(corrupt("unknown format"));
        }
        let (&flags, rest) = rest.split_first().ok_or_else(|| corrupt("truncated"))?;
        let (count, mut rest) = rest
            .split_first_chunk::<2>()
            .ok_or_else(|| corrupt("truncated"))?;
        let count = usize::from(u16::from_le_bytes(*count));
        let mut recent = VecDeque::with_capacity(count);
        for _ in 0..count {
            let (sequence, tail) = rest
                .split_first_chunk::<8>()
                .ok_or_else(|| corrupt("truncated"))?;
            recent.push_back(u64::from_le_bytes(*sequence));
            rest = tail;
        }
        if recent.back().is_some_and(|&s| s != last) {
            return Err(corrupt("the kept sequences do not end at the highest"));
        }
        Ok(Self {
            last,
            recent,
            complete: flags & COMPLETE != 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cursor_of(sequences: impl IntoIterator<Item = u64>) -> ClientCursor {
        let mut cursor = ClientCursor::new();
        for s in sequences {
            cursor.applied(s);
        }
        cursor
    }

    #[test]
    fn resends_gaps_and_sequences_out_of_order_are_told_apart() {
        let cursor = cursor_of([3, 5, 9]);
        assert_eq!(cursor.check(10), SequenceCheck::Next);
        assert_eq!(cursor.check(9), SequenceCheck::Applied);
        assert_eq!(cursor.check(3), SequenceCheck::Applied);
        assert_eq!(cursor.check(7), SequenceCheck::NeverApplied);
        // Never trimmed: even below the first kept one is known.
        assert_eq!(cursor.check(1), SequenceCheck::NeverApplied);
    }

    #[test]
    fn below_a_trimmed_window_cannot_be_told() {
        let cursor = cursor_of((1..=RECENT_SEQUENCES as u64 + 10).map(|s| s * 2));
        assert!(!cursor.complete);
        assert_eq!(cursor.recent.len(), RECENT_SEQUENCES);
        let lowest = *cursor.recent.front().unwrap();
        assert_eq!(cursor.check(lowest), SequenceCheck::Applied);
        assert_eq!(cursor.check(lowest + 1), SequenceCheck::NeverApplied);
        assert_eq!(cursor.check(lowest - 1), SequenceCheck::Unknown);
        assert_eq!(cursor.check(2), SequenceCheck::Unknown);
    }

    #[test]
    fn cursors_round_trip_and_old_records_still_load() {
        for cursor in [
            ClientCursor::new(),
            cursor_of([1, 2, 7]),
            cursor_of(1..=RECENT_SEQUENCES as u64 + 3),
        ] {
            assert_eq!(ClientCursor::decode("c", &cursor.encode()).unwrap(), cursor);
        }
        let old = ClientCursor::decode("c", &41u64.to_le_bytes()).unwrap();
        assert_eq!((old.last, old.recent.len(), old.complete), (41, 0, false));
        assert_eq!(old.check(41), SequenceCheck::Unknown);
        assert_eq!(old.check(42), SequenceCheck::Next);
        let mut upgraded = old;
        upgraded.applied(50);
        assert_eq!(upgraded.check(45), SequenceCheck::Unknown);
        assert_eq!(upgraded.check(50), SequenceCheck::Applied);
        // What servers before the list read: the first eight bytes.
        assert_eq!(upgraded.encode()[..8], 50u64.to_le_bytes());
        let encoded = cursor_of([1, 2]).encode();
        assert!(ClientCursor::decode("c", &encoded[..encoded.len() - 1]).is_err());
        assert!(ClientCursor::decode("c", &encoded[..5]).is_err());
    }
}
