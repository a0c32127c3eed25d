//! PX4 ULog (`.ulg`) reader, on the `px4-ulog` crate (PX4's own parser: streaming, keeps the
//! valid prefix of a cut-off log).
//!
//! uavgen frames the records itself (16-byte header, then `u16 size, u8 type, payload`) and hands
//! the crate one whole record at a time, so that an error names the byte offset of the record
//! at fault. Data messages of the topics the profile asks for are decoded through the crate's
//! flattened formats (field names as PX4 tools show them: `x`, `q[0]`, `xyz[2]`, nested
//! `a.b`). Only the first instance (`multi_id` 0) of a topic is read; other instances are noted.
//! Time is the message's `timestamp` field (µs since boot) in s.

use super::error::{ImportError, ImportErrorKind};
use super::recording::{Damage, Recording, SeriesBuilder};
use px4_ulog::stream_parser::model::{FlattenedFieldType, FlattenedFormat};
use px4_ulog::stream_parser::{DataMessage, LittleEndianParser, LogParser};
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// The first 7 bytes of every ULog file.
pub const MAGIC: [u8; 7] = [b'U', b'L', b'o', b'g', 0x01, 0x12, 0x35];

/// The payload of every `S` (sync) record.
pub const SYNC_MAGIC: [u8; 8] = [0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12];

/// Records in a row that must be plausible where the reader resumes after a damaged stretch.
const RESYNC_CHAIN: usize = 4;

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect::<Vec<_>>().join(" ")
}

/// The msg_id an `A` (subscription) record at `pos` adds, if it is one.
fn subscribed(bytes: &[u8], pos: usize) -> Option<u16> {
    let h = bytes.get(pos..pos + 6)?;
    (h[2] == b'A' && u16::from_le_bytes([h[0], h[1]]) >= 4).then(|| u16::from_le_bytes([h[4], h[5]]))
}

/// Whether a plausible record head of the data section is at `pos` (its end within the file is
/// not checked here): a known kind with a payload of the kind's size, a `D` record of a
/// subscribed msg_id (of the size its earlier records had), an `S` record with the sync magic.
/// `pending`: a msg_id subscribed by the record just before. `strict` (resynchronising): unknown
/// kinds are not accepted (a reader skips them otherwise, as the format asks).
fn plausible(bytes: &[u8], pos: usize, subs: &HashMap<u16, Option<usize>>, pending: Option<u16>, strict: bool) -> bool {
    let Some(h) = bytes.get(pos..pos + 3) else { return false };
    let size = u16::from_le_bytes([h[0], h[1]]) as usize;
    let payload = bytes.get(pos + 3..).unwrap_or(&[]);
    let payload = &payload[..payload.len().min(size)];
    let printable = |b: &[u8]| b.iter().all(|c| (0x20..0x7f).contains(c));
    match h[2] {
        b'D' => {
            let Some(id) = payload.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])) else {
                return false;
            };
            match subs.get(&id) {
                Some(Some(known)) => size == *known,
                Some(None) => size >= 10,
                None => pending == Some(id) && size >= 10,
            }
        }
        b'A' => size >= 4 && payload.len() >= 4 && printable(&payload[3..]),
        b'R' | b'O' => size == 2,
        b'S' => size == 8 && payload == SYNC_MAGIC,
        // Logged strings: a log level and a 64-bit time stamp (`C`: and a tag) before the text.
        b'L' => size >= 9 && (!strict || printable(payload.get(9..).unwrap_or(&[]))),
        b'C' => size >= 11 && (!strict || printable(payload.get(11..).unwrap_or(&[]))),
        // Resynchronising, only the kinds above: their checks are strong enough for bytes that
        // are not records (a double's bytes) to fail them.
        _ if strict => false,
        // Information and parameters: a key length and a key (`M`, `Q`: a flag byte first).
        b'I' | b'P' => size >= 2 && payload.len() >= 2 && (payload[0] as usize) < size,
        b'M' | b'Q' => size >= 3 && payload.len() >= 3 && (payload[1] as usize) + 1 < size,
        b'F' => size >= 3 && printable(payload),
        k => k.is_ascii_alphabetic() && size > 0,
    }
}

/// The first byte at or after `from` where [`RESYNC_CHAIN`] plausible records follow one another
/// (or fewer that end exactly at `end`).
fn resync(bytes: &[u8], from: usize, end: usize, subs: &HashMap<u16, Option<usize>>) -> Option<usize> {
    let chain = |q: usize| {
        let mut p = q;
        let mut pending = None;
        for i in 0..RESYNC_CHAIN {
            if p == end {
                return i > 0;
            }
            if p + 3 > end || !plausible(&bytes[..end], p, subs, pending, true) {
                return false;
            }
            pending = subscribed(bytes, p);
            p += 3 + u16::from_le_bytes([bytes[p], bytes[p + 1]]) as usize;
            if p > end {
                return false;
            }
        }
        true
    };
    (from..end.saturating_sub(2)).find(|&q| chain(q))
}

/// How to read one requested field of one msg_id.
struct FieldPlan {
    name: String,
    offset: usize,
    kind: FlattenedFieldType,
}

fn value(data: &[u8], offset: usize, kind: &FlattenedFieldType) -> Option<f64> {
    let size = match kind {
        FlattenedFieldType::Int8 | FlattenedFieldType::UInt8 | FlattenedFieldType::Bool | FlattenedFieldType::Char => 1,
        FlattenedFieldType::Int16 | FlattenedFieldType::UInt16 => 2,
        FlattenedFieldType::Int32 | FlattenedFieldType::UInt32 | FlattenedFieldType::Float => 4,
        FlattenedFieldType::Int64 | FlattenedFieldType::UInt64 | FlattenedFieldType::Double => 8,
    };
    let b = data.get(offset..offset + size)?;
    Some(match kind {
        FlattenedFieldType::Int8 => i8::parse(b) as f64,
        FlattenedFieldType::UInt8 | FlattenedFieldType::Bool => u8::parse(b) as f64,
        FlattenedFieldType::Int16 => i16::parse(b) as f64,
        FlattenedFieldType::UInt16 => u16::parse(b) as f64,
        FlattenedFieldType::Int32 => i32::parse(b) as f64,
        FlattenedFieldType::UInt32 => u32::parse(b) as f64,
        FlattenedFieldType::Int64 => i64::parse(b) as f64,
        FlattenedFieldType::UInt64 => u64::parse(b) as f64,
        FlattenedFieldType::Float => f32::parse(b) as f64,
        FlattenedFieldType::Double => f64::parse(b),
        FlattenedFieldType::Char => return None,
    })
}

fn numeric(kind: &FlattenedFieldType) -> bool {
    !matches!(kind, FlattenedFieldType::Char)
}

#[derive(Default)]
struct State {
    available: BTreeMap<String, Vec<String>>,
    builders: BTreeMap<String, SeriesBuilder>,
    /// msg_id → plans (None: not a requested topic or not instance 0).
    plans: BTreeMap<u16, Option<Vec<FieldPlan>>>,
    other_instances: BTreeSet<String>,
    no_timestamp: BTreeSet<String>,
    error: Option<ImportError>,
    /// Byte offset of the record being fed (for errors).
    offset: usize,
}

/// Read the requested `(topic, field)` pairs of a ULog file held in `bytes`.
pub fn read(file: &str, bytes: &[u8], needs: &[(String, String)]) -> Result<Recording, ImportError> {
    if bytes.len() < 16 || bytes[..7] != MAGIC {
        return Err(ImportError::new(
            file,
            ImportErrorKind::WrongFormat,
            "not a PX4 ULog file: it does not start with the ULog magic bytes `ULog\\x01\\x12\\x35`",
        ));
    }
    let mut wanted: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (topic, field) in needs {
        wanted.entry(topic.clone()).or_default().push(field.clone());
    }
    let state = RefCell::new(State::default());
    for (topic, fields) in &wanted {
        state
            .borrow_mut()
            .builders
            .insert(topic.clone(), SeriesBuilder::new(fields));
    }
    let mut rec = Recording::new(file, "PX4 ULog");

    let mut callback = |msg: &DataMessage| {
        let mut guard = state.borrow_mut();
        let st = &mut *guard;
        if st.error.is_some() {
            return;
        }
        let format: &FlattenedFormat = msg.flattened_format;
        let name = format.message_name();
        if !st.available.contains_key(name) {
            let fields = format
                .fields
                .iter()
                .filter(|f| numeric(&f.field_type))
                .map(|f| f.flattened_field_name.clone())
                .collect();
            st.available.insert(name.to_owned(), fields);
        }
        let plan = st.plans.entry(msg.msg_id).or_insert_with(|| {
            let fields = wanted.get(name)?;
            if msg.multi_id.value() != 0 {
                return None;
            }
            Some(
                fields
                    .iter()
                    .filter_map(|want| {
                        let f = format.fields.iter().find(|f| &f.flattened_field_name == want)?;
                        numeric(&f.field_type).then(|| FieldPlan {
                            name: want.clone(),
                            offset: f.offset as usize,
                            kind: f.field_type.clone(),
                        })
                    })
                    .collect(),
            )
        });
        let Some(plan) = plan else {
            if wanted.contains_key(name) && msg.multi_id.value() != 0 {
                st.other_instances.insert(name.to_owned());
            }
            return;
        };
        let Some(ts) = format.timestamp_field.as_ref().and_then(|f| {
            let o = f.offset as usize;
            msg.data.get(o..o + 8).map(u64::parse)
        }) else {
            st.no_timestamp.insert(name.to_owned());
            return;
        };
        let t = ts as f64 / 1e6;
        let offset = st.offset;
        let Some(builder) = st.builders.get_mut(name) else {
            return;
        };
        let values: BTreeMap<&str, f64> = plan
            .iter()
            .filter_map(|p| value(msg.data, p.offset, &p.kind).map(|v| (p.name.as_str(), v)))
            .collect();
        if let Err(e) = builder.push(
            file,
            name,
            t,
            || format!("the record at byte {offset}"),
            |f| values.get(f).copied(),
        ) {
            st.error = Some(e);
        }
    };

    {
        let mut parser = LogParser::default();
        parser.set_data_message_callback(&mut callback);
        let feed = |parser: &mut LogParser, chunk: &[u8]| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parser.consume_bytes(chunk)))
        };
        let header = feed(&mut parser, &bytes[..16]);
        if !matches!(header, Ok(Ok(()))) {
            return Err(ImportError::new(
                file,
                ImportErrorKind::Corrupt,
                "the ULog header (bytes 0..16) cannot be read",
            ));
        }
        // msg_id → the size of its `D` records, once one was read (`None`: subscribed, no data yet).
        let mut subs: HashMap<u16, Option<usize>> = HashMap::new();
        let mut pos = 16usize;
        let mut end = bytes.len();
        while pos < end {
            if end - pos < 3 {
                rec.broken = Some(format!(
                    "the file ends inside a record header at byte {pos} ({} of 3 bytes)",
                    end - pos
                ));
                break;
            }
            let size = u16::from_le_bytes([bytes[pos], bytes[pos + 1]]) as usize;
            let kind = bytes[pos + 2];
            let next = pos + 3 + size;
            // A record is read only when its head and the head after it are plausible: a damaged
            // stretch (zeros, garbage) may begin inside the record before the first bad head.
            let problem = if !plausible(bytes, pos, &subs, None, false) {
                Some(format!(
                    "no valid ULog record at byte {pos} (head {})",
                    hex(&bytes[pos..pos + 3])
                ))
            } else if next > end {
                rec.broken = Some(format!(
                    "the file is truncated: the `{}` record at byte {pos} announces {size} bytes, {} are left",
                    kind as char,
                    end - pos - 3
                ));
                break;
            } else if next + 3 <= end && !plausible(bytes, next, &subs, subscribed(bytes, pos), false) {
                Some(format!(
                    "no valid ULog record at byte {next} (head {}) after the `{}` record at byte {pos}",
                    hex(&bytes[next..(next + 5).min(end)]),
                    kind as char
                ))
            } else {
                state.borrow_mut().offset = pos;
                let result = feed(&mut parser, &bytes[pos..next]);
                let failed = match result {
                    Ok(Ok(())) => None,
                    Ok(Err(e)) => Some(e.description),
                    Err(_) => Some("the ULog parser failed on it".to_owned()),
                };
                if let Some(e) = state.borrow_mut().error.take() {
                    return Err(e);
                }
                failed.map(|f| format!("the `{}` record at byte {pos} cannot be decoded: {f}", kind as char))
            };
            if let Some(problem) = problem {
                if !parser.in_data() {
                    return Err(ImportError::new(
                        file,
                        ImportErrorKind::Corrupt,
                        format!("{problem} (in the definitions section, before any data)"),
                    ));
                }
                let mut damage = Damage::new(pos, problem, &state.borrow().builders);
                let resume = resync(bytes, pos + 1, end, &subs);
                damage.close(bytes, resume.unwrap_or(end), resume.is_some());
                rec.damage.push(damage);
                match resume {
                    Some(q) => {
                        pos = q;
                        continue;
                    }
                    None => break,
                }
            }
            if let Some(id) = subscribed(bytes, pos) {
                subs.entry(id).or_insert(None);
            }
            if kind == b'D' && size >= 2 {
                let id = u16::from_le_bytes([bytes[pos + 3], bytes[pos + 4]]);
                subs.insert(id, Some(size));
            }
            pos = next;
            // Appended data (crash dumps) starts at the first non-zero appended offset.
            if let Some(&first) = parser.appended_offsets().iter().find(|o| **o != 0) {
                let first = first as usize;
                if first > pos && first < end {
                    rec.notes.push(format!(
                        "the primary data section ends at byte {first}; appended data after it is not read"
                    ));
                    end = first;
                }
            }
        }
    }
    let st = state.into_inner();
    rec.available = st.available;
    for (topic, builder) in st.builders {
        rec.series.insert(topic, builder.series);
    }
    for topic in st.other_instances {
        rec.notes
            .push(format!("`{topic}` has several instances: instance 0 is used"));
    }
    for topic in st.no_timestamp {
        rec.notes
            .push(format!("`{topic}` has no uint64 `timestamp` field: not usable"));
    }
    Ok(rec)
}
