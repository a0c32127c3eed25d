//! ROS 1 bag (`.bag`, format 2.0) reader, written here: the `rosbag` crate maps the file into
//! memory (`unsafe` mmap) and slices it by the header's index position without checking it, so a
//! bag whose recorder was killed (index position 0 or past the end: the common truncated bag)
//! panics instead of yielding what was recorded. The format is small (records of
//! `u32 header length, header fields name=value, u32 data length, data`), so uavgen walks the
//! records itself, which also gives every error a byte offset.
//!
//! Read: connection records (topic, type, message definition) and message-data records inside
//! uncompressed chunks; the index section is not needed. A chunk cut by the end of the file (the
//! recorder was killed while writing it) gives its complete messages. bz2 or lz4 chunks are reported
//! (`rosbag decompress` writes an uncompressed copy). Messages are decoded from the connection's
//! message definition by [`rosmsg`](super::rosmsg) (ROS 1 wire format). Time: `header.stamp` (with
//! `clock: header`) or the record's receive time.

use super::error::{ImportError, ImportErrorKind};
use super::profile::Clock;
use super::recording::{Damage, Recording, SeriesBuilder};
use super::rosmsg::{header_stamp, Definition, Wire};
use std::collections::HashMap;

/// The first 13 bytes of a ROS bag 2.0.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

const OP_MESSAGE: u8 = 0x02;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;
const OP_BAG_HEADER: u8 = 0x03;
const OP_INDEX_DATA: u8 = 0x04;
const OP_CHUNK_INFO: u8 = 0x06;

/// One record: its header fields and data, at byte `at`.
struct RawRecord<'a> {
    /// Byte offset in the file.
    at: usize,
    /// Byte offset of `data` in the file.
    data_at: usize,
    /// Position after the record in the slice it was read from.
    next: usize,
    fields: HashMap<&'a str, &'a [u8]>,
    data: &'a [u8],
    /// Set when the file ends inside the data: `data` is what there is.
    cut: Option<String>,
}

impl RawRecord<'_> {
    fn op(&self) -> Option<u8> {
        self.fields.get("op").and_then(|v| v.first().copied())
    }
    fn u32(&self, name: &str) -> Option<u32> {
        let v = self.fields.get(name)?;
        Some(u32::from_le_bytes(v.get(..4)?.try_into().ok()?))
    }
}

/// Header fields of a record or a connection: `u32 length, name=value` repeated.
fn fields(bytes: &[u8]) -> Result<HashMap<&str, &[u8]>, String> {
    let mut out = HashMap::new();
    let mut pos = 0;
    while pos < bytes.len() {
        let len = bytes
            .get(pos..pos + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or("a header field length is cut off")?;
        let field = bytes
            .get(pos + 4..pos + 4 + len)
            .ok_or("a header field runs past its header")?;
        let eq = field
            .iter()
            .position(|b| *b == b'=')
            .ok_or("a header field has no `=`")?;
        let name = std::str::from_utf8(&field[..eq]).map_err(|_| "a header field name is not UTF-8")?;
        out.insert(name, &field[eq + 1..]);
        pos += 4 + len;
    }
    Ok(out)
}

/// The record at `pos` of `bytes` (`base` is the offset of `bytes` in the file, for messages);
/// `Err((truncated, message))` when it cannot be read.
fn record(bytes: &[u8], pos: usize, base: usize) -> Result<RawRecord<'_>, (bool, String)> {
    let at = base + pos;
    let u32_at = |p: usize| {
        bytes
            .get(p..p + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let header_len = u32_at(pos).ok_or((true, format!("the record at byte {at} is cut off in its header length")))?;
    let header = bytes.get(pos + 4..pos + 4 + header_len).ok_or((
        true,
        format!("the record at byte {at} announces a {header_len}-byte header, the file ends first"),
    ))?;
    let data_len =
        u32_at(pos + 4 + header_len).ok_or((true, format!("the record at byte {at} is cut off in its data length")))?;
    let start = pos + 8 + header_len;
    let (data, cut) = match bytes.get(start..start + data_len) {
        Some(d) => (d, None),
        None => (
            bytes.get(start..).unwrap_or(&[]),
            Some(format!(
                "the record at byte {at} announces {data_len} bytes of data, the file ends first"
            )),
        ),
    };
    let fields = fields(header).map_err(|e| (false, format!("the record at byte {at}: {e}")))?;
    Ok(RawRecord {
        at,
        data_at: base + start,
        next: start + data_len,
        fields,
        data,
        cut,
    })
}

struct Connection {
    topic: String,
    decoder: Result<Definition, String>,
}

/// Read the requested `(topic, field)` pairs of a ROS 1 bag held in `bytes`.
pub fn read(file: &str, bytes: &[u8], needs: &[(String, String)], clock: Clock) -> Result<Recording, ImportError> {
    if !bytes.starts_with(MAGIC) {
        return Err(ImportError::new(
            file,
            ImportErrorKind::WrongFormat,
            "not a ROS 1 bag: it does not start with `#ROSBAG V2.0`",
        ));
    }
    let mut rec = Recording::new(file, "ROS 1 bag");
    let mut builders = SeriesBuilder::for_needs(needs);
    let mut connections: HashMap<u32, Connection> = HashMap::new();
    let mut values: HashMap<String, f64> = HashMap::new();

    // The outer records, and the records inside each chunk, in file order.
    let mut pos = MAGIC.len();
    while pos < bytes.len() {
        let r = match record(bytes, pos, 0) {
            Ok(r) => r,
            Err((truncated, m)) => {
                rec.broken = Some(if truncated {
                    format!("the file is truncated: {m}")
                } else {
                    m
                });
                break;
            }
        };
        pos = r.next;
        // A record cut by the end of the file: a chunk's complete messages are kept (a recorder
        // killed while writing it), anything else ends the walk.
        let cut = r.cut.as_ref().map(|m| format!("the file is truncated: {m}"));
        if cut.is_some() && r.op() != Some(OP_CHUNK) {
            rec.broken = cut;
            break;
        }
        let inner: Vec<(&[u8], usize)> = match r.op() {
            Some(OP_CHUNK) => {
                let compression = r.fields.get("compression").copied().unwrap_or(b"none");
                if compression != b"none" {
                    return Err(ImportError::new(
                        file,
                        ImportErrorKind::WrongFormat,
                        format!(
                            "the chunk at byte {} is `{}`-compressed: uavgen reads uncompressed bags (`rosbag decompress {file}` writes one)",
                            r.at,
                            String::from_utf8_lossy(compression)
                        ),
                    ));
                }
                vec![(r.data, r.data_at)]
            }
            Some(OP_CONNECTION) => {
                add_connection(&r, &mut connections, &mut rec);
                continue;
            }
            Some(OP_BAG_HEADER | OP_INDEX_DATA | OP_CHUNK_INFO) => continue,
            op => {
                // Not a record of the format: nothing says where the next one starts.
                let mut d = Damage::new(
                    r.at,
                    format!(
                        "the record at byte {} is not a ROS 1 bag record (op {})",
                        r.at,
                        op.map_or("missing".to_owned(), |o| format!("{o:#04x}"))
                    ),
                    &builders,
                );
                d.close(bytes, bytes.len(), false);
                rec.damage.push(d);
                break;
            }
        };
        // A damaged record inside a chunk: (its byte, why). The chunk's length (in its outer
        // record) says where the next record starts: the reader resumes there.
        let mut damage: Option<(usize, String)> = None;
        for (chunk, base) in inner {
            let mut p = 0;
            while p < chunk.len() {
                let m = match record(chunk, p, base) {
                    Ok(m) if m.cut.is_none() => m,
                    Ok(m) => {
                        damage = Some((base + p, m.cut.unwrap_or_default()));
                        break;
                    }
                    Err((_, m)) => {
                        damage = Some((base + p, m));
                        break;
                    }
                };
                p = m.next;
                match m.op() {
                    Some(OP_CONNECTION) => add_connection(&m, &mut connections, &mut rec),
                    Some(OP_MESSAGE) => {
                        let (Some(conn), Some(time)) = (m.u32("conn"), m.fields.get("time")) else {
                            damage = Some((
                                m.at,
                                format!("the message record at byte {} has no `conn` or `time`", m.at),
                            ));
                            break;
                        };
                        let receive = match time.get(..8) {
                            Some(t) => {
                                let s = u32::from_le_bytes([t[0], t[1], t[2], t[3]]) as f64;
                                let ns = u32::from_le_bytes([t[4], t[5], t[6], t[7]]) as f64;
                                s + ns / 1e9
                            }
                            None => {
                                damage =
                                    Some((m.at, format!("the message record at byte {} has a short `time`", m.at)));
                                break;
                            }
                        };
                        let Some(c) = connections.get(&conn) else {
                            damage = Some((
                                m.at,
                                format!(
                                    "the message record at byte {} names connection {conn}, which no record defined before it",
                                    m.at
                                ),
                            ));
                            break;
                        };
                        let Some(builder) = builders.get_mut(&c.topic) else {
                            continue;
                        };
                        let def = c.decoder.as_ref().map_err(|why| {
                            ImportError::new(
                                file,
                                ImportErrorKind::MissingField,
                                format!("topic `{}` cannot be decoded: {why}", c.topic),
                            )
                        })?;
                        values.clear();
                        if let Err(e) = def.decode(Wire::Ros1, m.data, &mut |n, v| {
                            values.insert(n.to_owned(), v);
                        }) {
                            damage = Some((
                                m.at,
                                format!(
                                    "the message at byte {} (topic `{}`, a `{}`) cannot be decoded: {e}",
                                    m.at, c.topic, def.root
                                ),
                            ));
                            break;
                        }
                        let t = match clock {
                            Clock::Header => header_stamp(&values).unwrap_or(receive),
                            Clock::Receive => receive,
                        };
                        let at = m.at;
                        builder.push(
                            file,
                            &c.topic,
                            t,
                            || format!("the message at byte {at}"),
                            |f| values.get(f).copied(),
                        )?;
                    }
                    op => {
                        // Inside a chunk only messages and connections are written; anything
                        // else (a zeroed stretch reads as records without an `op`) is damage.
                        damage = Some((
                            m.at,
                            format!(
                                "the record at byte {} is not a message or connection record (op {})",
                                m.at,
                                op.map_or("missing".to_owned(), |o| format!("{o:#04x}"))
                            ),
                        ));
                        break;
                    }
                }
            }
        }
        if let Some((at, why)) = damage {
            if let Some(c) = cut {
                rec.broken = Some(c);
                break;
            }
            let mut d = Damage::new(at, format!("inside the chunk at byte {}: {why}", r.at), &builders);
            d.close(bytes, pos, pos < bytes.len());
            rec.damage.push(d);
            continue;
        }
        if let Some(c) = cut {
            rec.broken = Some(c);
            break;
        }
    }
    rec.take_series(builders);
    rec.list_carried_fields();
    Ok(rec)
}

fn add_connection(r: &RawRecord, connections: &mut HashMap<u32, Connection>, rec: &mut Recording) {
    let Some(id) = r.u32("conn") else { return };
    if connections.contains_key(&id) {
        return;
    }
    let topic = r
        .fields
        .get("topic")
        .map(|t| String::from_utf8_lossy(t).into_owned())
        .unwrap_or_default();
    let decoder = match fields(r.data) {
        Ok(h) => {
            let ty = h
                .get("type")
                .map(|t| String::from_utf8_lossy(t).into_owned())
                .unwrap_or_default();
            let text = h
                .get("message_definition")
                .map(|t| String::from_utf8_lossy(t).into_owned())
                .unwrap_or_default();
            Definition::parse(&ty, &text).map_err(|e| format!("its message definition (`{ty}`) cannot be parsed: {e}"))
        }
        Err(e) => Err(format!("its connection header cannot be read: {e}")),
    };
    if !rec.available.contains_key(&topic) {
        let names = decoder.as_ref().map(Definition::field_names).unwrap_or_default();
        rec.available.insert(topic.clone(), names);
    }
    connections.insert(id, Connection { topic, decoder });
}
