//! A length check of MCAP records before the `mcap` crate parses them.
//!
//! The crate (through binrw) allocates every length-prefixed string or byte field by its declared
//! length before reading it, so a damaged length (a fuzzed Channel record claiming a 4 GB topic
//! name, found by `scripts/fuzz.sh`) asks for gigabytes from a 14 KB file: an abort where
//! allocations are not overcommitted. This walks the records (top level, and the records of
//! uncompressed chunks) and finds the first field whose declared length exceeds what its record
//! declares; the import then reads only the records before it and reports the damage.

/// A field of a record's fixed layout (the MCAP specification, records section).
#[derive(Clone, Copy)]
enum Field {
    /// `n` bytes.
    Fixed(usize),
    /// A u32 byte length and that many bytes (String, Bytes, a Map or an Array).
    Prefixed32,
    /// A u64 byte length and that many bytes (a Chunk's records, an Attachment's data).
    Prefixed64,
}

use Field::{Fixed, Prefixed32 as P32, Prefixed64 as P64};

/// The record's name and its fields up to the last length-prefixed one.
fn layout(opcode: u8) -> Option<(&'static str, &'static [Field])> {
    Some(match opcode {
        0x01 => ("Header", &[P32, P32]),
        0x03 => ("Schema", &[Fixed(2), P32, P32, P32]),
        0x04 => ("Channel", &[Fixed(2), Fixed(2), P32, P32, P32]),
        0x06 => ("Chunk", &[Fixed(8), Fixed(8), Fixed(8), Fixed(4), P32, P64]),
        0x07 => ("MessageIndex", &[Fixed(2), P32]),
        0x08 => ("ChunkIndex", &[Fixed(32), P32, Fixed(8), P32]),
        0x09 => ("Attachment", &[Fixed(16), P32, P32, P64]),
        0x0A => ("AttachmentIndex", &[Fixed(40), P32, P32]),
        0x0B => ("Statistics", &[Fixed(42), P32]),
        0x0C => ("Metadata", &[P32, P32]),
        0x0D => ("MetadataIndex", &[Fixed(16), P32]),
        _ => return None,
    })
}

/// The first record (its byte offset, and what is wrong) with a field longer than the record, in
/// `bytes` (a whole MCAP file, magic included). `None`: every declared length fits.
pub fn first_oversized_field(bytes: &[u8]) -> Option<(usize, String)> {
    scan(bytes, super::mcap::MAGIC.len(), bytes.len(), None)
}

/// The records in `bytes[at..end]`; inside an uncompressed chunk whose records end at
/// `chunk_end` (as declared) when given, else at the top level (where such chunks are walked too).
fn scan(bytes: &[u8], mut at: usize, end: usize, chunk_end: Option<u64>) -> Option<(usize, String)> {
    // Inside a chunk every record must fit in the chunk's records as declared: the `mcap` crate
    // slices past its buffer otherwise (a panic in mcap 0.26's linear reader, found by fuzzing).
    if let Some(found) = stub_before_chunk_end(at, end, chunk_end) {
        return Some(found);
    }
    while at.checked_add(9).is_some_and(|e| e <= end) {
        let opcode = bytes[at];
        let len = u64_at(bytes, at + 1)?;
        let body = at + 9;
        // A length no file can hold: the `mcap` crate adds the record head's 9 bytes to it in
        // usize and slices with the wrapped sum (a panic in mcap 0.26's linear reader, found by
        // fuzzing `import_csv` with an MCAP-looking input).
        if len > (usize::MAX as u64).saturating_sub(body as u64) {
            return Some((
                at,
                format!("the record (opcode 0x{opcode:02x}) declares {len} bytes, more than any file can hold"),
            ));
        }
        // The record as declared (it may run past the file: truncation is the reader's to report).
        let declared_end = (body as u64).saturating_add(len);
        if let Some(stop) = chunk_end.filter(|stop| declared_end > *stop) {
            return Some((
                at,
                format!(
                    "the record (opcode 0x{opcode:02x}) declares {len} bytes, past the end of its chunk's records at byte {stop}"
                ),
            ));
        }
        if let Some((name, fields)) = layout(opcode) {
            let mut pos = body;
            let mut last = None;
            for (i, f) in fields.iter().enumerate() {
                let (prefix, n) = match f {
                    Field::Fixed(n) => (0, *n as u64),
                    Field::Prefixed32 => (4, u32_at(bytes, pos)? as u64),
                    Field::Prefixed64 => (8, u64_at(bytes, pos)?),
                };
                let start = pos as u64 + prefix;
                // At the top level a string or map longer than the whole rest of the file is no
                // truncation's doing (a cut file ends inside it, it does not declare gigabytes): the
                // crate would allocate it whole (out of memory from an 87-byte record head, found by
                // fuzzing `import_csv` with an MCAP-looking input).
                if chunk_end.is_none() && prefix == 4 && start.saturating_add(n) > bytes.len() as u64 {
                    return Some((
                        at,
                        format!(
                            "its {name} record's field {} declares {n} bytes, more than the {} bytes left in the file",
                            i + 1,
                            (bytes.len() as u64).saturating_sub(start)
                        ),
                    ));
                }
                if start.saturating_add(n) > declared_end {
                    return Some((
                        at,
                        format!(
                            "its {name} record's field {} declares {n} bytes, more than the record's {len}",
                            i + 1
                        ),
                    ));
                }
                last = Some((start, n));
                pos = usize::try_from(start + n).ok()?;
            }
            // A chunk's records (the compression string is the 5th field): walked in place when
            // uncompressed, after decompressing them when zstd-compressed.
            if chunk_end.is_none() && opcode == 0x06 {
                let compression_len = u32_at(bytes, body + 28)?;
                let compression = bytes.get(body + 32..body + 32 + compression_len as usize);
                match (compression, last) {
                    (Some(b""), Some((start, n))) => {
                        let records_end = start + n;
                        let start = usize::try_from(start).ok()?;
                        let stop = usize::try_from(records_end).ok()?.min(bytes.len());
                        if let Some(found) = scan(bytes, start, stop, Some(records_end)) {
                            return Some(found);
                        }
                    }
                    (Some(b"zstd"), Some((start, n))) => {
                        if let Some(found) = scan_zstd_chunk(bytes, body, start, n) {
                            return Some((at, found));
                        }
                    }
                    _ => {}
                }
            }
        }
        at = usize::try_from(declared_end).ok()?;
        if let Some(found) = stub_before_chunk_end(at, end, chunk_end) {
            return Some(found);
        }
    }
    None
}

/// Inside a chunk whose records end at `chunk_end`, a stub of 1–8 bytes at `at` (before `end`): too
/// short for a record head, so no record.
fn stub_before_chunk_end(at: usize, end: usize, chunk_end: Option<u64>) -> Option<(usize, String)> {
    let left = chunk_end?.saturating_sub(at as u64);
    ((1..9).contains(&left) && at < end).then(|| {
        (
            at,
            format!("{left} bytes at the end of a chunk's records are no record"),
        )
    })
}

/// What is wrong in the records of the zstd-compressed chunk whose body starts at `body`, with its
/// compressed records at `bytes[start..start + n]`: they are decompressed (at most the chunk's
/// declared uncompressed size, growing only with the bytes the stream really yields, so a damaged
/// size asks for nothing) and walked as an uncompressed chunk's. A stream that does not decompress
/// is not this check's: the `mcap` crate reports it.
fn scan_zstd_chunk(bytes: &[u8], body: usize, start: u64, n: u64) -> Option<String> {
    use std::io::Read;
    let declared = u64_at(bytes, body + 16)?;
    let start = usize::try_from(start).ok()?;
    let stop = usize::try_from(start as u64 + n).ok()?.min(bytes.len());
    let compressed = bytes.get(start..stop)?;
    let mut records = Vec::new();
    zstd::stream::read::Decoder::new(compressed)
        .ok()?
        .take(declared)
        .read_to_end(&mut records)
        .ok()?;
    let (at, what) = scan(&records, 0, records.len(), Some(records.len() as u64))?;
    Some(format!(
        "in its zstd-compressed records, at byte {at} of {} decompressed: {what}",
        records.len()
    ))
}

/// The little-endian u32 at `at`, if the bytes are there.
fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(bytes.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

/// The little-endian u64 at `at`, if the bytes are there.
fn u64_at(bytes: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An MCAP file of `records` (opcode, body) after the magic.
    fn file(records: &[(u8, Vec<u8>)]) -> Vec<u8> {
        let mut out = super::super::mcap::MAGIC.to_vec();
        for (op, body) in records {
            out.push(*op);
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(body);
        }
        out
    }

    fn string(s: &[u8]) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s);
        out
    }

    fn channel(topic_len: u32) -> Vec<u8> {
        let mut body = vec![1, 0, 1, 0];
        body.extend_from_slice(&topic_len.to_le_bytes());
        body.extend_from_slice(b"/pose");
        body.extend(string(b"cdr"));
        body.extend_from_slice(&0u32.to_le_bytes());
        body
    }

    fn chunk(records: &[u8]) -> Vec<u8> {
        let mut body = vec![0; 24];
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend(string(b""));
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(records);
        body
    }

    /// A zstd-compressed chunk of `records`, declaring `declared` uncompressed bytes.
    fn zstd_chunk(records: &[u8], declared: u64) -> Vec<u8> {
        let packed = zstd::bulk::compress(records, 3).expect("compress");
        let mut body = vec![0; 16];
        body.extend_from_slice(&declared.to_le_bytes());
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend(string(b"zstd"));
        body.extend_from_slice(&(packed.len() as u64).to_le_bytes());
        body.extend_from_slice(&packed);
        body
    }

    #[test]
    fn well_formed_records_pass() {
        let header = [string(b"ros2"), string(b"uavgen")].concat();
        let f = file(&[(0x01, header), (0x04, channel(5))]);
        assert_eq!(first_oversized_field(&f), None);
    }

    #[test]
    fn a_string_longer_than_its_record_is_found_at_the_record() {
        let header = [string(b"ros2"), string(b"uavgen")].concat();
        let f = file(&[(0x01, header.clone()), (0x04, channel(0xFFFF_FF00))]);
        let (at, what) = first_oversized_field(&f).expect("found");
        assert_eq!(at, 8 + 9 + header.len());
        assert!(
            what.contains("Channel record's field 3 declares 4294967040 bytes"),
            "{what}"
        );
    }

    #[test]
    fn inside_an_uncompressed_chunk_too() {
        let inner = file(&[(0x04, channel(1 << 30))]);
        let f = file(&[(0x06, chunk(&inner[8..]))]);
        let (at, what) = first_oversized_field(&f).expect("found");
        assert_eq!(at, 8 + 9 + 24 + 4 + 4 + 8);
        assert!(what.contains("Channel"), "{what}");
        // A record running past its chunk's records.
        let mut inner = file(&[(0x04, channel(5))]);
        let n = inner.len();
        inner[9..17].copy_from_slice(&((n - 8 - 9 + 4) as u64).to_le_bytes());
        let f = file(&[(0x06, chunk(&inner[8..]))]);
        let (_, what) = first_oversized_field(&f).expect("found");
        assert!(what.contains("past the end of its chunk's records"), "{what}");
        // A truncated file (the chunk declared longer than the bytes left) is not this check's.
        let mut cut = file(&[(0x06, chunk(&file(&[(0x04, channel(5))])[8..]))]);
        cut.truncate(cut.len() - 3);
        assert_eq!(first_oversized_field(&cut), None);
    }

    #[test]
    fn a_length_no_file_can_hold_is_found() {
        // The fuzzed input: the magic, a record of opcode 0xFF declaring u64::MAX bytes.
        let mut f = super::super::mcap::MAGIC.to_vec();
        f.push(0xFF);
        f.extend_from_slice(&u64::MAX.to_le_bytes());
        f.extend_from_slice(&[0xFF; 8]);
        let (at, what) = first_oversized_field(&f).expect("found");
        assert_eq!(at, 8);
        assert!(what.contains("more than any file can hold"), "{what}");
    }

    #[test]
    fn a_string_longer_than_the_rest_of_the_file_is_found() {
        // A Chunk record whose declared length runs past the file, its compression string
        // declaring 4 GB: found at the record (the crate would allocate the string first).
        let mut f = super::super::mcap::MAGIC.to_vec();
        f.push(0x06);
        f.extend_from_slice(&(1u64 << 40).to_le_bytes());
        f.extend_from_slice(&[0; 28]);
        f.extend_from_slice(&u32::MAX.to_le_bytes());
        f.extend_from_slice(b"zstd");
        let (at, what) = first_oversized_field(&f).expect("found");
        assert_eq!(at, 8);
        assert!(
            what.contains("Chunk record's field 5 declares 4294967295 bytes, more than the 4 bytes left"),
            "{what}"
        );
    }

    #[test]
    fn inside_a_zstd_chunk_too() {
        let good = file(&[(0x04, channel(5))]);
        let f = file(&[(0x06, zstd_chunk(&good[8..], (good.len() - 8) as u64))]);
        assert_eq!(first_oversized_field(&f), None);
        // A 1 GiB topic name inside the compressed records: found at the chunk, located inside.
        let bad = file(&[(0x04, channel(1 << 30))]);
        let n = (bad.len() - 8) as u64;
        let f = file(&[(0x06, zstd_chunk(&bad[8..], n))]);
        let (at, what) = first_oversized_field(&f).expect("found");
        assert_eq!(at, 8);
        assert!(
            what.contains("zstd-compressed records, at byte 0 of 33 decompressed")
                && what.contains("Channel record's field 3 declares 1073741824 bytes"),
            "{what}"
        );
        // A damaged declared size (2^60) allocates nothing: the stream yields what it holds.
        let f = file(&[(0x06, zstd_chunk(&bad[8..], 1 << 60))]);
        assert!(first_oversized_field(&f).is_some());
        // A stream that is no zstd is left to the mcap crate.
        let mut f = file(&[(0x06, zstd_chunk(&good[8..], (good.len() - 8) as u64))]);
        let magic = f
            .windows(4)
            .position(|w| w == [0x28, 0xB5, 0x2F, 0xFD])
            .expect("zstd magic");
        f[magic..magic + 4].fill(0xAB);
        assert_eq!(first_oversized_field(&f), None);
    }
}
