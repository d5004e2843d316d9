//! Changes committed through another server sharing the store, and how
//! they travel between servers: one text line each, in notifications of
//! at most [`MAX_PAYLOAD`] bytes whose first line names the server that
//! made them. Names are `[A-Za-z0-9_.-]` (the service checks), so a space
//! separates fields.

use crate::events::MapEvent;
use deog_grid::TileKey;

/// The largest payload sent in one notification (PostgreSQL takes up to
/// 8000 bytes).
pub const MAX_PAYLOAD: usize = 7900;

/// A change made through another server, for watchers here.
#[derive(Debug, Clone, PartialEq)]
pub enum StoreChange {
    /// A map changed.
    Map {
        /// The map.
        map: String,
        /// What happened to it.
        event: MapEvent,
    },
    /// A frame was stored.
    Frame {
        /// Robot name.
        robot: String,
        /// Its sequence.
        sequence: u64,
    },
    /// A pose estimate was stored.
    Pose {
        /// Robot name.
        robot: String,
        /// The frame sequence it belongs to.
        sequence: u64,
    },
    /// Changes may have been missed (the feed was interrupted): watchers
    /// read again what they follow.
    Resync,
    /// The store cannot tell changes as they happen (no `NOTIFY`): look
    /// whether what watchers follow moved since the last look.
    Poll,
}

impl StoreChange {
    fn line(&self) -> Option<String> {
        Some(match self {
            Self::Map {
                map,
                event: MapEvent::TileChanged { key, version },
            } => format!("t {map} {} {} {version}", key.x, key.y),
            Self::Map {
                map,
                event: MapEvent::Cleared { version },
            } => format!("c {map} {version}"),
            Self::Map {
                map,
                event: MapEvent::Deleted,
            } => format!("d {map}"),
            Self::Map {
                event: MapEvent::Resync,
                ..
            }
            | Self::Resync
            | Self::Poll => return None,
            Self::Frame { robot, sequence } => format!("f {robot} {sequence}"),
            Self::Pose { robot, sequence } => format!("p {robot} {sequence}"),
        })
    }

    fn parse(line: &str) -> Option<Self> {
        let fields: Vec<&str> = line.split(' ').collect();
        let number = |i: usize| fields.get(i).and_then(|f| f.parse::<u64>().ok());
        let name = |i: usize| fields.get(i).map(|f| f.to_string());
        Some(match (fields.first().copied()?, fields.len()) {
            ("t", 5) => Self::Map {
                map: name(1)?,
                event: MapEvent::TileChanged {
                    key: TileKey::new(fields[2].parse().ok()?, fields[3].parse().ok()?),
                    version: number(4)?,
                },
            },
            ("c", 3) => Self::Map {
                map: name(1)?,
                event: MapEvent::Cleared {
                    version: number(2)?,
                },
            },
            ("d", 2) => Self::Map {
                map: name(1)?,
                event: MapEvent::Deleted,
            },
            ("f", 3) => Self::Frame {
                robot: name(1)?,
                sequence: number(2)?,
            },
            ("p", 3) => Self::Pose {
                robot: name(1)?,
                sequence: number(2)?,
            },
            _ => return None,
        })
    }
}

/// The payloads that carry `changes` from server `origin`.
pub fn encode_changes(origin: &str, changes: &[StoreChange]) -> Vec<String> {
    let mut payloads = Vec::new();
    let mut payload = String::new();
    for line in changes.iter().filter_map(StoreChange::line) {
        if !payload.is_empty() && payload.len() + 1 + line.len() > MAX_PAYLOAD {
            payloads.push(std::mem::take(&mut payload));
        }
        if payload.is_empty() {
            payload.push_str(origin);
        }
        payload.push('\n');
        payload.push_str(&line);
    }
    if !payload.is_empty() {
        payloads.push(payload);
    }
    payloads
}

/// The origin and changes of one payload; `Err` with the line that could
/// not be read.
pub fn decode_changes(payload: &str) -> Result<(&str, Vec<StoreChange>), String> {
    let mut lines = payload.split('\n');
    let origin = lines.next().unwrap_or_default();
    let changes = lines
        .map(|line| StoreChange::parse(line).ok_or_else(|| line.to_string()))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((origin, changes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn change() -> impl Strategy<Value = StoreChange> {
        let name = "[A-Za-z0-9_.-]{1,128}";
        prop_oneof![
            (name, any::<i32>(), any::<i32>(), any::<u64>()).prop_map(|(map, x, y, version)| {
                StoreChange::Map {
                    map,
                    event: MapEvent::TileChanged {
                        key: TileKey::new(x, y),
                        version,
                    },
                }
            }),
            (name, any::<u64>()).prop_map(|(map, version)| StoreChange::Map {
                map,
                event: MapEvent::Cleared { version },
            }),
            name.prop_map(|map| StoreChange::Map {
                map,
                event: MapEvent::Deleted,
            }),
            (name, any::<u64>())
                .prop_map(|(robot, sequence)| StoreChange::Frame { robot, sequence }),
            (name, any::<u64>())
                .prop_map(|(robot, sequence)| StoreChange::Pose { robot, sequence }),
        ]
    }

    proptest! {
        #[test]
        fn changes_arrive_as_sent_in_payloads_that_fit(
            changes in proptest::collection::vec(change(), 0..400)
        ) {
            let payloads = encode_changes("server-1", &changes);
            let mut received = Vec::new();
            for payload in &payloads {
                prop_assert!(payload.len() <= MAX_PAYLOAD);
                let (origin, part) = decode_changes(payload).unwrap();
                prop_assert_eq!(origin, "server-1");
                prop_assert!(!part.is_empty());
                received.extend(part);
            }
            prop_assert_eq!(received, changes);
        }
    }

    #[test]
    fn a_line_it_cannot_read_is_reported() {
        let error = decode_changes("s\nt m 1 2\nf r 3").unwrap_err();
        assert_eq!(error, "t m 1 2");
    }
}
