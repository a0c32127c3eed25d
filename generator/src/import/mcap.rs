//! MCAP (`.mcap`, ROS 2 bags with the mcap storage, Foxglove recordings) reader, on the `mcap`
//! crate (Foxglove's own, with zstd chunk compression; lz4 chunks are reported as unsupported).
//!
//! Channels with `cdr` message encoding and a `ros2msg` schema (what `ros2 bag record -s mcap`
//! writes) are decoded by [`rosmsg`](super::rosmsg) from the schema itself, so any message type
//! works; `ros1` encoded channels (`ros1msg` schema, `mcap convert` of a ROS 1 bag) too. Time is
//! the message's `header.stamp` when it has one and the profile's `clock` is `header`, else the
//! recorder's log time.

use super::error::{ImportError, ImportErrorKind};
use super::profile::Clock;
use super::recording::{Recording, SeriesBuilder};
use super::rosmsg::{header_stamp, Definition, Wire};
use std::collections::HashMap;

/// The first 8 bytes of every MCAP file.
pub const MAGIC: &[u8] = b"\x89MCAP0\r\n";

enum Decoder {
    Ok(Definition, Wire),
    /// Why this channel cannot be decoded.
    Unsupported(String),
}

/// Read the requested `(topic, field)` pairs of an MCAP file held in `bytes`.
pub fn read(file: &str, bytes: &[u8], needs: &[(String, String)], clock: Clock) -> Result<Recording, ImportError> {
    if !bytes.starts_with(MAGIC) {
        return Err(ImportError::new(
            file,
            ImportErrorKind::WrongFormat,
            "not an MCAP file: it does not start with the MCAP magic bytes `\\x89MCAP0\\r\\n`",
        ));
    }
    let mut rec = Recording::new(file, "MCAP");
    let mut builders = SeriesBuilder::for_needs(needs);
    let mut decoders: HashMap<u16, Decoder> = HashMap::new();
    // A field longer than its record: read the records before it, then say where it broke
    // (the `mcap` crate would allocate the declared length first; docs/import.md).
    let damage = super::mcap_lengths::first_oversized_field(bytes);
    let bytes = match &damage {
        Some((at, _)) => &bytes[..*at],
        None => bytes,
    };
    let stream = ::mcap::MessageStream::new(bytes).map_err(|e| {
        ImportError::new(
            file,
            ImportErrorKind::Corrupt,
            format!("the MCAP header cannot be read: {e}"),
        )
    })?;
    let mut count = 0usize;
    let mut last_time: Option<f64> = None;
    let mut values: HashMap<String, f64> = HashMap::new();
    for item in stream {
        let message = match item {
            Ok(m) => m,
            Err(e) => {
                let after = match last_time {
                    Some(t) => format!("after message {count} (log time {t} s)"),
                    None => "before the first message".into(),
                };
                let what = match e {
                    ::mcap::McapError::UnexpectedEof | ::mcap::McapError::UnexpectedEoc => {
                        format!("the file is truncated {after}: {e}")
                    }
                    e => format!("the file breaks {after}: {e}"),
                };
                rec.broken = Some(what);
                break;
            }
        };
        count += 1;
        let channel = &message.channel;
        let topic = channel.topic.as_str();
        let decoder = decoders.entry(channel.id).or_insert_with(|| decoder(channel));
        if !rec.available.contains_key(topic) {
            let names = match decoder {
                Decoder::Ok(def, _) => def.field_names(),
                Decoder::Unsupported(_) => Vec::new(),
            };
            rec.available.insert(topic.to_owned(), names);
        }
        let log_time = message.log_time as f64 / 1e9;
        last_time = Some(log_time);
        let Some(builder) = builders.get_mut(topic) else {
            continue;
        };
        let (def, wire) = match decoder {
            Decoder::Ok(def, wire) => (def, *wire),
            Decoder::Unsupported(why) => {
                return Err(ImportError::new(
                    file,
                    ImportErrorKind::MissingField,
                    format!("topic `{topic}` cannot be decoded: {why}"),
                ))
            }
        };
        values.clear();
        if let Err(e) = def.decode(wire, &message.data, &mut |n, v| {
            values.insert(n.to_owned(), v);
        }) {
            rec.broken = Some(format!(
                "message {count} (topic `{topic}`, log time {log_time} s, a `{}`) cannot be decoded: {e}",
                def.root
            ));
            break;
        }
        let t = match clock {
            Clock::Header => header_stamp(&values).unwrap_or(log_time),
            Clock::Receive => log_time,
        };
        builder.push(
            file,
            topic,
            t,
            || format!("message {count} (log time {log_time} s)"),
            |f| values.get(f).copied(),
        )?;
    }
    if let Some((at, what)) = damage {
        let after = match last_time {
            Some(t) => format!("after message {count} (log time {t} s)"),
            None => "before the first message".into(),
        };
        rec.broken = Some(format!("the file breaks {after}: damaged at byte {at}: {what}"));
    }
    rec.take_series(builders);
    rec.list_carried_fields();
    Ok(rec)
}

fn decoder(channel: &::mcap::Channel) -> Decoder {
    let Some(schema) = channel.schema.as_ref() else {
        return Decoder::Unsupported("the channel has no schema".into());
    };
    let wire = match (channel.message_encoding.as_str(), schema.encoding.as_str()) {
        ("cdr", "ros2msg") => Wire::Cdr,
        ("ros1", "ros1msg") => Wire::Ros1,
        (m, s) => {
            return Decoder::Unsupported(format!(
            "message encoding `{m}` with schema encoding `{s}` (uavgen decodes `cdr`/`ros2msg` and `ros1`/`ros1msg`)"
        ))
        }
    };
    let text = String::from_utf8_lossy(&schema.data);
    match Definition::parse(&schema.name, &text) {
        Ok(def) => Decoder::Ok(def, wire),
        Err(e) => Decoder::Unsupported(format!("its schema `{}` cannot be parsed: {e}", schema.name)),
    }
}
