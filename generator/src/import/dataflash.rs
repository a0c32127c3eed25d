//! ArduPilot DataFlash (`.bin`) reader, written here: the format is self-describing (`FMT`
//! records give each message type's length, name, field types and labels; every record is
//! `0xA3 0x95 type payload`), and the one crate for it (`ardupilot-binlog` 0.2) skips corrupt
//! bytes silently (up to 256 in a row) and drops a cut-off last record without saying where, which
//! the import contract forbids. uavgen walks the records with byte offsets instead.
//!
//! Field types (ArduPilot `LogStructure.h`): `b B h H i I q Q` integers, `f` float, `d` double,
//! `c C e E` hundredths (int16, uint16, int32, uint32 / 100), `L` latitude/longitude (int32 / 1e7),
//! `M` flight mode (uint8), `n N Z` strings (4, 16, 64 chars), `a` int16[32]. Time is the
//! `TimeUS` field (µs since boot). Messages with an instance field (`I`, or `C` for the EKF cores
//! of `XKF*`) are read for instance 0 only (a note says so).

use super::error::{ImportError, ImportErrorKind};
use super::recording::{Damage, Recording, SeriesBuilder};
use std::collections::{BTreeSet, HashMap};

/// The first two bytes of every record.
pub const HEAD: [u8; 2] = [0xA3, 0x95];
const FMT: u8 = 0x80;

/// Records in a row (each head `A3 95` and a defined type, each ending where the next begins)
/// where the reader resumes after a damaged stretch.
const RESYNC_CHAIN: usize = 3;

/// The first byte at or after `from` where [`RESYNC_CHAIN`] whole records of defined types follow
/// one another (or fewer that end exactly at the file's end).
fn resync(bytes: &[u8], from: usize, formats: &HashMap<u8, MsgFormat>) -> Option<usize> {
    let len = |p: usize| -> Option<usize> {
        let h = bytes.get(p..p + 3)?;
        if h[..2] != HEAD {
            return None;
        }
        if h[2] == FMT {
            Some(89)
        } else {
            formats.get(&h[2]).map(|f| f.len)
        }
    };
    let chain = |q: usize| {
        let mut p = q;
        for i in 0..RESYNC_CHAIN {
            if p == bytes.len() {
                return i > 0;
            }
            match len(p) {
                Some(l) if p + l <= bytes.len() => p += l,
                _ => return false,
            }
        }
        true
    };
    (from..bytes.len()).find(|&q| chain(q))
}

/// One message type.
#[derive(Clone, Debug)]
struct MsgFormat {
    name: String,
    len: usize,
    format: Vec<u8>,
    labels: Vec<String>,
}

fn type_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' => 2,
        b'i' | b'I' | b'f' | b'e' | b'E' | b'L' | b'n' => 4,
        b'q' | b'Q' | b'd' => 8,
        b'N' => 16,
        b'Z' => 64,
        b'a' => 64,
        _ => return None,
    })
}

fn decode(c: u8, b: &[u8]) -> Option<f64> {
    let i16_ = || i16::from_le_bytes([b[0], b[1]]) as f64;
    let u16_ = || u16::from_le_bytes([b[0], b[1]]) as f64;
    let i32_ = || i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
    let u32_ = || u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
    let b8 = || [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
    Some(match c {
        b'b' => b[0] as i8 as f64,
        b'B' | b'M' => b[0] as f64,
        b'h' => i16_(),
        b'H' => u16_(),
        b'c' => i16_() / 100.0,
        b'C' => u16_() / 100.0,
        b'i' => i32_(),
        b'I' => u32_(),
        b'e' => i32_() / 100.0,
        b'E' => u32_() / 100.0,
        b'L' => i32_() / 1e7,
        b'f' => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        b'd' => f64::from_le_bytes(b8()),
        b'q' => i64::from_le_bytes(b8()) as f64,
        b'Q' => u64::from_le_bytes(b8()) as f64,
        _ => return None,
    })
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b.split(|c| *c == 0).next().unwrap_or(&[]))
        .trim()
        .to_owned()
}

/// Parse an FMT payload (after the 3-byte head): type, length, name[4], format[16], labels[64].
fn parse_fmt(p: &[u8]) -> Result<(u8, MsgFormat), String> {
    if p.len() < 86 {
        return Err("an FMT record shorter than 89 bytes".into());
    }
    let (ty, len) = (p[0], p[1] as usize);
    let name = text(&p[2..6]);
    let format: Vec<u8> = p[6..22].iter().copied().take_while(|c| *c != 0).collect();
    let labels: Vec<String> = text(&p[22..86]).split(',').map(str::to_owned).collect();
    let mut size = 3;
    for c in &format {
        size += type_size(*c).ok_or_else(|| format!("`{name}`: unknown field type `{}`", *c as char))?;
    }
    if size != len && ty != FMT {
        return Err(format!("`{name}`: its fields take {size} bytes but it declares {len}"));
    }
    if labels.len() != format.len() {
        return Err(format!(
            "`{name}`: {} field types but {} labels",
            format.len(),
            labels.len()
        ));
    }
    Ok((
        ty,
        MsgFormat {
            name,
            len,
            format,
            labels,
        },
    ))
}

/// Read the requested `(topic, field)` pairs (topic = message name) of a DataFlash log.
pub fn read(file: &str, bytes: &[u8], needs: &[(String, String)]) -> Result<Recording, ImportError> {
    if !bytes.starts_with(&HEAD) {
        return Err(ImportError::new(
            file,
            ImportErrorKind::WrongFormat,
            "not an ArduPilot DataFlash log: it does not start with the record head A3 95",
        ));
    }
    let mut rec = Recording::new(file, "ArduPilot DataFlash");
    let mut builders = SeriesBuilder::for_needs(needs);
    let mut formats: HashMap<u8, MsgFormat> = HashMap::new();
    let mut instances: BTreeSet<String> = BTreeSet::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        let at = pos;
        let Some(head) = bytes.get(pos..pos + 3) else {
            rec.broken = Some(format!("the file is truncated: a record head at byte {at} is cut off"));
            break;
        };
        let ty = head[2];
        let len = if ty == FMT {
            Some(89)
        } else {
            formats.get(&ty).map(|f| f.len)
        };
        // A record is read only when the record after it starts with a head too: a damaged
        // stretch (zeros, garbage) may begin inside the record before the first bad head.
        let next = at + len.unwrap_or(0);
        let problem = if head[..2] != HEAD {
            Some(format!(
                "{:02x} {:02x} where a record head A3 95 should be",
                head[0], head[1]
            ))
        } else if len.is_none() {
            Some(format!(
                "the record has type {ty}, which no FMT record defined before it"
            ))
        } else if next + 2 <= bytes.len() && bytes[next..next + 2] != HEAD {
            Some(format!(
                "{:02x} {:02x} at byte {next}, after the record at byte {at}, where a record head A3 95 should be",
                bytes[next],
                bytes[next + 1]
            ))
        } else {
            None
        };
        if let Some(problem) = problem {
            // Skip the damaged stretch: resume at the next run of whole records (never silent:
            // the stretch and what each mapped message lost are reported).
            let mut damage = Damage::new(at, problem, &builders);
            let resume = resync(bytes, at + 1, &formats);
            damage.close(bytes, resume.unwrap_or(bytes.len()), resume.is_some());
            rec.damage.push(damage);
            match resume {
                Some(q) => {
                    pos = q;
                    continue;
                }
                None => break,
            }
        }
        let len = len.unwrap_or(0);
        let Some(record) = bytes.get(pos..pos + len) else {
            rec.broken = Some(format!(
                "the file is truncated: the record at byte {at} needs {len} bytes, {} are left",
                bytes.len() - pos
            ));
            break;
        };
        pos += len;
        let payload = &record[3..];
        if ty == FMT {
            match parse_fmt(payload) {
                Ok((t, f)) => {
                    if !rec.available.contains_key(&f.name) {
                        let fields = f
                            .labels
                            .iter()
                            .zip(&f.format)
                            .filter(|(_, c)| decode(**c, &[0u8; 8]).is_some())
                            .map(|(l, _)| l.clone())
                            .collect();
                        rec.available.insert(f.name.clone(), fields);
                    }
                    formats.insert(t, f);
                }
                Err(e) => {
                    rec.broken = Some(format!("the FMT record at byte {at} is invalid: {e}"));
                    break;
                }
            }
            continue;
        }
        let f = &formats[&ty];
        let Some(builder) = builders.get_mut(&f.name) else {
            continue;
        };
        let mut values: HashMap<&str, f64> = HashMap::new();
        let mut offset = 0;
        for (c, label) in f.format.iter().zip(&f.labels) {
            let size = type_size(*c).unwrap_or(0);
            if let Some(v) = payload.get(offset..offset + size).and_then(|b| decode(*c, b)) {
                values.insert(label.as_str(), v);
            }
            offset += size;
        }
        let instance = if f.name.starts_with("XK") { "C" } else { "I" };
        if values.get(instance).is_some_and(|v| *v != 0.0) {
            instances.insert(f.name.clone());
            continue;
        }
        let Some(us) = values.get("TimeUS") else {
            return Err(ImportError::new(
                file,
                ImportErrorKind::MissingField,
                format!("message `{}` has no `TimeUS` field: it cannot be timed", f.name),
            ));
        };
        builder.push(
            file,
            &f.name,
            us / 1e6,
            || format!("the record at byte {at}"),
            |name| values.get(name).copied(),
        )?;
    }
    rec.take_series(builders);
    for name in instances {
        rec.notes
            .push(format!("`{name}` has several instances: instance 0 is used"));
    }
    Ok(rec)
}
