//! A recording's channels read by topic, and the topics an import takes:
//! the ones asked for, checked, or the one of each kind there is.

use std::collections::BTreeMap;

use mcap::sans_io::{LinearReaderOptions, MessageReadEvent, MessageReader};

use crate::error::RecordingError;
use crate::messages::{
    LaserScan, Odometry, PoseStamped, PoseWithCovarianceStamped, Range, RosMessage, TfMessage,
    Time, decode, names_type,
};
use crate::record::MESSAGE_ENCODING;

/// One channel's messages, as stored.
#[derive(Debug, Default)]
pub(crate) struct Topic {
    /// The schema's name.
    pub(crate) schema: String,
    schema_encoding: String,
    message_encoding: String,
    /// (log time in nanoseconds, CDR bytes).
    pub(crate) messages: Vec<(u64, Vec<u8>)>,
}

/// A scan's kind of message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ScanKind {
    Laser,
    Sonar,
}

/// Every channel's messages, for the types read here (others are only
/// named, for the errors that list topics).
pub(crate) fn read_topics(mcap: &[u8]) -> Result<BTreeMap<String, Topic>, RecordingError> {
    if !mcap.starts_with(mcap::MAGIC) {
        return Err(RecordingError::NotMcap);
    }
    let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
    // The reader allocates what a record claims before reading it: a
    // bound on records keeps a corrupt length an error, not an abort.
    let limit = (mcap.len() as u64)
        .saturating_mul(MAX_INFLATION)
        .clamp(MIN_RECORD_LIMIT, MAX_RECORD_LIMIT);
    let options = LinearReaderOptions::default()
        .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX));
    let mut reader = MessageReader::new_with_options(options);
    let mut unread = mcap;
    while let Some(event) = reader.next_event() {
        let message = match event? {
            MessageReadEvent::ReadRequest(wanted) => {
                let n = wanted.min(unread.len());
                reader.insert(n).copy_from_slice(&unread[..n]);
                reader.notify_read(n);
                unread = &unread[n..];
                continue;
            }
            MessageReadEvent::Message(message) => message,
        };
        let channel = &message.channel;
        let topic = topics
            .entry(channel.topic.clone())
            .or_insert_with(|| Topic {
                schema: channel
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                schema_encoding: channel
                    .schema
                    .as_ref()
                    .map(|s| s.encoding.clone())
                    .unwrap_or_default(),
                message_encoding: channel.message_encoding.clone(),
                messages: Vec::new(),
            });
        if is_read_here(&topic.schema) {
            topic
                .messages
                .push((message.log_time, message.data.into_owned()));
        }
    }
    if topics.is_empty() {
        return Err(RecordingError::Empty(
            "the recording holds no message".into(),
        ));
    }
    Ok(topics)
}

/// The most bytes a record inside a chunk may take for each byte of the
/// file: far beyond what zstd or lz4 reach on sensor data.
const MAX_INFLATION: u64 = 1024;

/// Records of up to this size are taken whatever the file's size.
const MIN_RECORD_LIMIT: u64 = 64 << 20;

/// No record may take more than this.
const MAX_RECORD_LIMIT: u64 = 4 << 30;

pub(crate) fn is_read_here(schema: &str) -> bool {
    names_type::<LaserScan>(schema)
        || names_type::<Range>(schema)
        || names_type::<Odometry>(schema)
        || names_type::<PoseStamped>(schema)
        || names_type::<PoseWithCovarianceStamped>(schema)
        || names_type::<TfMessage>(schema)
}

/// The topics and their schemas, for an error message.
pub(crate) fn inventory(topics: &BTreeMap<String, Topic>) -> String {
    topics
        .iter()
        .map(|(name, t)| format!("{name} ({})", t.schema))
        .collect::<Vec<_>>()
        .join(", ")
}

pub(crate) fn pick_scan_topic(
    topics: &BTreeMap<String, Topic>,
    asked: Option<&str>,
) -> Result<(String, ScanKind), RecordingError> {
    let kind_of = |t: &Topic| {
        if names_type::<LaserScan>(&t.schema) {
            Some(ScanKind::Laser)
        } else if names_type::<Range>(&t.schema) {
            Some(ScanKind::Sonar)
        } else {
            None
        }
    };
    let laser_topics = topics
        .values()
        .filter(|t| names_type::<LaserScan>(&t.schema))
        .count();
    // Asked for by name, either kind; else the one laser, or the one
    // topic of sonars where there is no laser.
    let types: &[&str] = match (asked, laser_topics) {
        (Some(_), _) => &[LaserScan::TYPE_NAME, Range::TYPE_NAME],
        (None, 0) => &[Range::TYPE_NAME],
        (None, _) => &[LaserScan::TYPE_NAME],
    };
    let name = pick_topic(topics, asked, "scan", "--scan-topic", types)?;
    let kind = kind_of(&topics[&name]).ok_or_else(|| {
        RecordingError::Topic(format!("{name} holds neither LaserScan nor Range messages"))
    })?;
    Ok((name, kind))
}

/// The topic asked for, checked to hold one of `types` in CDR; or the
/// one topic that does.
pub(crate) fn pick_topic(
    topics: &BTreeMap<String, Topic>,
    asked: Option<&str>,
    what: &str,
    option: &str,
    types: &[&str],
) -> Result<String, RecordingError> {
    let fits = |t: &Topic| {
        types
            .iter()
            .any(|ty| t.schema == *ty || t.schema == ty.replacen("/msg/", "/", 1))
    };
    let type_list = types.join(" or ");
    let name = match asked {
        Some(name) => {
            let Some(topic) = topics.get(name) else {
                return Err(RecordingError::Topic(format!(
                    "the recording has no topic {name} (it has {})",
                    inventory(topics)
                )));
            };
            if !fits(topic) {
                return Err(RecordingError::Topic(format!(
                    "{name} holds {} messages, not {type_list}",
                    topic.schema
                )));
            }
            name.to_owned()
        }
        None => {
            let candidates: Vec<&String> = topics
                .iter()
                .filter(|(_, t)| fits(t))
                .map(|(name, _)| name)
                .collect();
            match candidates.as_slice() {
                [one] => (*one).clone(),
                [] => {
                    return Err(RecordingError::Topic(format!(
                        "the recording has no {what} topic ({type_list}); it has {}",
                        inventory(topics)
                    )));
                }
                several => {
                    let names: Vec<&str> = several.iter().map(|s| s.as_str()).collect();
                    return Err(RecordingError::Topic(format!(
                        "the recording has several {what} topics ({}): choose one with {option}",
                        names.join(", ")
                    )));
                }
            }
        }
    };
    let topic = &topics[&name];
    if topic.message_encoding != MESSAGE_ENCODING {
        return Err(RecordingError::Topic(format!(
            "{name}'s messages are in {:?}, not {MESSAGE_ENCODING:?} (a ROS 2 recording's)",
            topic.message_encoding
        )));
    }
    if !topic.schema_encoding.is_empty()
        && topic.schema_encoding != "ros2msg"
        && topic.schema_encoding != "ros2idl"
    {
        return Err(RecordingError::Topic(format!(
            "{name}'s schema is in {:?}, not a ROS 2 one",
            topic.schema_encoding
        )));
    }
    Ok(name)
}

pub(crate) fn decode_on<M: RosMessage>(
    name: &str,
    topic: &Topic,
    index: usize,
    bytes: &[u8],
) -> Result<M, RecordingError> {
    decode::<M>(bytes).map_err(|error| RecordingError::Message {
        topic: name.to_owned(),
        schema: topic.schema.clone(),
        index: index + 1,
        reason: error.to_string(),
    })
}

/// A message's time: its header's stamp, or where that was never set, the
/// time it was logged.
pub(crate) fn stamp_seconds(stamp: Time, log_time: u64) -> f64 {
    if stamp.is_zero() {
        log_time as f64 * 1e-9
    } else {
        stamp.seconds()
    }
}

pub(crate) fn bad(name: &str, topic: &Topic, index: usize, reason: &str) -> RecordingError {
    RecordingError::Message {
        topic: name.to_owned(),
        schema: topic.schema.clone(),
        index: index + 1,
        reason: reason.to_owned(),
    }
}
