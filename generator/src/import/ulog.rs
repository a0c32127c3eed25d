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
use super::recording::{Recording, SeriesBuilder};
use px4_ulog::stream_parser::model::{FlattenedFieldType, FlattenedFormat};
use px4_ulog::stream_parser::{DataMessage, LittleEndianParser, LogParser};
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};

/// The first 7 bytes of every ULog file.
pub const MAGIC: [u8; 7] = [b'U', b'L', b'o', b'g', 0x01, 0x12, 0x35];

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
            if end - pos < 3 + size {
                rec.broken = Some(format!(
                    "the file is truncated: the `{}` record at byte {pos} announces {size} bytes, {} are left",
                    kind as char,
                    end - pos - 3
                ));
                break;
            }
            state.borrow_mut().offset = pos;
            let result = feed(&mut parser, &bytes[pos..pos + 3 + size]);
            let problem = match result {
                Ok(Ok(())) => None,
                Ok(Err(e)) => Some(e.description),
                Err(_) => Some("the ULog parser failed on it".to_owned()),
            };
            if let Some(e) = state.borrow_mut().error.take() {
                return Err(e);
            }
            if let Some(problem) = problem {
                let what = format!(
                    "the `{}` record at byte {pos} cannot be decoded: {problem}",
                    kind as char
                );
                if parser.in_data() {
                    rec.broken = Some(what);
                    break;
                }
                return Err(ImportError::new(
                    file,
                    ImportErrorKind::Corrupt,
                    format!("{what} (in the definitions section, before any data)"),
                ));
            }
            pos += 3 + size;
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
