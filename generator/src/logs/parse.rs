//! Lines → metadata, header and validated rows. One pass over the lines, so
//! the first problem in file order is the one reported.

use super::error::{LogError, LogErrorKind as K};
use super::lines::Lines;
use super::{INPUT_COLUMNS, STATE_COLUMNS};
use std::collections::HashMap;

/// One validated data row.
#[derive(Clone, Debug)]
pub(super) struct Row {
    pub line: usize,
    pub t: f64,
    pub x: [f64; 12],
    pub u: [f64; 4],
    pub battery: Option<f64>,
    pub segment: Option<i64>,
}

/// The whole file, validated row by row (segments are built afterwards).
#[derive(Clone, Debug)]
pub(super) struct Table {
    pub metadata: Vec<(String, String)>,
    /// `rate_hz` from the metadata and its line.
    pub rate_hz: Option<(f64, usize)>,
    pub has_battery: bool,
    pub rows: Vec<Row>,
}

/// Where each known column is in a row.
struct Columns {
    t: usize,
    x: [usize; 12],
    u: [usize; 4],
    battery: Option<usize>,
    segment: Option<usize>,
    names: Vec<String>,
    header_line: usize,
}

/// Longest cell text quoted in a message.
const QUOTE_MAX: usize = 40;

/// The lines as a validated table; a file of only white space is [`K::Empty`].
pub(super) fn parse(lines: &mut impl Lines, file: &str) -> Result<Table, LogError> {
    // Metadata comments, then the header.
    let mut metadata = Vec::new();
    let mut rate_hz: Option<(f64, usize)> = None;
    let mut blank = true;
    let cols = loop {
        let Some((n, line)) = lines.next_line()? else {
            if blank {
                return Err(LogError::new(
                    file,
                    None,
                    None,
                    K::Empty,
                    "the file is empty: expected `# key: value` metadata lines, a header row naming the columns, and data rows",
                ));
            }
            return Err(LogError::new(
                file,
                None,
                None,
                K::NoHeader,
                "no header row: the file has only comment and blank lines",
            ));
        };
        let trimmed = line.trim();
        if trimmed.is_empty() {
            continue;
        }
        blank = false;
        if let Some(comment) = trimmed.strip_prefix('#') {
            if let Some((key, value)) = metadata_entry(comment) {
                if key == "rate_hz" {
                    let hz = parse_rate(file, n, value)?;
                    if let Some((previous, at)) = rate_hz {
                        if previous != hz {
                            return Err(LogError::new(
                                file,
                                Some(n),
                                None,
                                K::Metadata,
                                format!("metadata `rate_hz: {value}` contradicts `rate_hz: {previous}` on line {at}"),
                            ));
                        }
                    } else {
                        rate_hz = Some((hz, n));
                    }
                }
                metadata.push((key.to_owned(), value.to_owned()));
            }
            continue;
        }
        break columns(file, n, line)?;
    };

    let mut rows: Vec<Row> = Vec::new();
    while let Some((n, line)) = lines.next_line()? {
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let row = row(file, n, line, &cols)?;
        if let Some(prev) = rows.last() {
            if prev.segment == row.segment && row.t <= prev.t {
                let what = if row.t == prev.t {
                    format!("t = {} repeats the time of line {}", row.t, prev.line)
                } else {
                    format!("t = {} goes backwards from t = {} on line {}", row.t, prev.t, prev.line)
                };
                return Err(LogError::new(
                    file,
                    Some(n),
                    Some("t"),
                    K::TimeNotIncreasing,
                    format!(
                        "column `t` (field {}): {what}; time must increase within a segment \
                         (a `segment` column value change starts a new one)",
                        cols.t + 1
                    ),
                ));
            }
        }
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(LogError::new(
            file,
            Some(cols.header_line),
            None,
            K::NoData,
            "no data rows after the header",
        ));
    }
    Ok(Table {
        metadata,
        rate_hz,
        has_battery: cols.battery.is_some(),
        rows,
    })
}

/// `key: value` after the `#`; the key is one word. Other comments are not metadata.
fn metadata_entry(comment: &str) -> Option<(&str, &str)> {
    let (key, value) = comment.split_once(':')?;
    let key = key.trim();
    if key.is_empty() || key.contains(char::is_whitespace) {
        return None;
    }
    Some((key, value.trim()))
}

fn parse_rate(file: &str, line: usize, value: &str) -> Result<f64, LogError> {
    match value.parse::<f64>() {
        Ok(hz) if hz.is_finite() && hz > 0.0 && (1.0 / hz).is_finite() => Ok(hz),
        _ => Err(LogError::new(
            file,
            Some(line),
            None,
            K::Metadata,
            format!("metadata `rate_hz: {}` is not a positive number of Hz", quote(value)),
        )),
    }
}

/// The fields of a line: comma separated, white space around a field and one pair of
/// surrounding double quotes removed.
fn fields(line: &str) -> Vec<&str> {
    line.split(',')
        .map(|f| {
            let f = f.trim();
            f.strip_prefix('"').and_then(|g| g.strip_suffix('"')).unwrap_or(f)
        })
        .collect()
}

fn required_columns() -> impl Iterator<Item = &'static str> {
    std::iter::once("t").chain(STATE_COLUMNS).chain(INPUT_COLUMNS)
}

fn columns(file: &str, line: usize, header: &str) -> Result<Columns, LogError> {
    let names = fields(header);
    if names.iter().all(|n| n.parse::<f64>().is_ok()) {
        return Err(LogError::new(
            file,
            Some(line),
            None,
            K::NoHeader,
            format!(
                "no header row: this line is numbers, but the first line that is not a `#` comment must name the \
                 columns ({})",
                required_columns().collect::<Vec<_>>().join(",")
            ),
        ));
    }
    let mut index: HashMap<&str, usize> = HashMap::new();
    for (i, &name) in names.iter().enumerate() {
        if name.is_empty() {
            continue;
        }
        if let Some(first) = index.insert(name, i) {
            return Err(LogError::new(
                file,
                Some(line),
                Some(name),
                K::DuplicateColumn,
                format!(
                    "column `{}` appears twice in the header (fields {} and {})",
                    quote(name),
                    first + 1,
                    i + 1
                ),
            ));
        }
    }
    let missing: Vec<&str> = required_columns().filter(|c| !index.contains_key(c)).collect();
    if !missing.is_empty() {
        let list = missing.iter().map(|c| format!("`{c}`")).collect::<Vec<_>>().join(", ");
        let mut message = format!(
            "missing required column{} {list}",
            if missing.len() == 1 { "" } else { "s" }
        );
        let near: Vec<String> = missing
            .iter()
            .filter_map(|m| {
                names
                    .iter()
                    .find(|n| n.eq_ignore_ascii_case(m))
                    .map(|n| format!("`{}`", quote(n)))
            })
            .collect();
        if !near.is_empty() {
            message.push_str(&format!(
                " (the header has {}: column names are case-sensitive)",
                near.join(", ")
            ));
        } else if names.len() == 1 && (header.contains(';') || header.contains('\t')) {
            message.push_str(" (the header has one field: the file must be comma separated)");
        }
        if missing.len() >= 4 {
            message.push_str(
                ". A CSV of another schema is read through an import profile that maps its columns, units and frames: \
                 `uavgen import --print-profile csv > my.json`, edit it, then `uavgen import FILE --profile my.json --out log.csv` \
                 (or `--profile my.json` on identify, evaluate, diagnose; docs/import.md)",
            );
        }
        return Err(LogError::new(
            file,
            Some(line),
            Some(&missing.join(",")),
            K::MissingColumns,
            message,
        ));
    }
    let at = |name: &str| index.get(name).copied().unwrap_or(0);
    Ok(Columns {
        t: at("t"),
        x: STATE_COLUMNS.map(at),
        u: INPUT_COLUMNS.map(at),
        battery: index.get("battery_voltage").copied(),
        segment: index.get("segment").copied(),
        names: names.iter().map(|n| (*n).to_owned()).collect(),
        header_line: line,
    })
}

fn row(file: &str, line: usize, text: &str, cols: &Columns) -> Result<Row, LogError> {
    let cells = fields(text);
    let expected = cols.names.len();
    if cells.len() != expected {
        let (column, what) = if cells.len() < expected {
            let name = cols.names.get(cells.len()).map(String::as_str).unwrap_or("");
            (
                name,
                format!(
                    "column `{}` (field {}) and after are missing",
                    quote(name),
                    cells.len() + 1
                ),
            )
        } else {
            let name = cols.names.last().map(String::as_str).unwrap_or("");
            (
                name,
                format!("field {} is after the last column `{}`", expected + 1, quote(name)),
            )
        };
        return Err(LogError::new(
            file,
            Some(line),
            Some(column),
            K::FieldCount,
            format!(
                "the row has {} fields but the header (line {}) has {expected}: {what}",
                cells.len(),
                cols.header_line
            ),
        ));
    }
    let cell = |i: usize| -> Result<f64, LogError> { number(file, line, &cols.names[i], i, cells[i]) };
    let t = cell(cols.t)?;
    let mut x = [0.0; 12];
    for (k, &i) in cols.x.iter().enumerate() {
        x[k] = cell(i)?;
    }
    let mut u = [0.0; 4];
    for (k, &i) in cols.u.iter().enumerate() {
        u[k] = cell(i)?;
    }
    let battery = cols.battery.map(cell).transpose()?;
    let segment = match cols.segment {
        Some(i) => Some(integer(file, line, i, cells[i])?),
        None => None,
    };
    Ok(Row {
        line,
        t,
        x,
        u,
        battery,
        segment,
    })
}

fn number(file: &str, line: usize, column: &str, field: usize, cell: &str) -> Result<f64, LogError> {
    let at = format!("column `{column}` (field {})", field + 1);
    if cell.is_empty() {
        return Err(LogError::new(
            file,
            Some(line),
            Some(column),
            K::NotNumeric,
            format!("{at} is empty"),
        ));
    }
    match cell.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= max_abs(column) => Ok(v),
        Ok(v) if v.is_finite() => Err(LogError::new(
            file,
            Some(line),
            Some(column),
            K::OutOfRange,
            format!(
                "{at}: {} is out of range: this column's values must be within ±{} (docs/logs.md)",
                crate::validate::short(v),
                crate::validate::short(max_abs(column))
            ),
        )),
        Ok(_) => Err(LogError::new(
            file,
            Some(line),
            Some(column),
            K::NonFinite,
            format!("{at}: `{}` is not a finite number", quote(cell)),
        )),
        Err(_) => Err(LogError::new(
            file,
            Some(line),
            Some(column),
            K::NotNumeric,
            format!("{at}: `{}` is not a number", quote(cell)),
        )),
    }
}

/// The largest magnitude a column's values may have: time stamps may be Unix times.
fn max_abs(column: &str) -> f64 {
    if column == "t" {
        crate::validate::LOG_TIME_MAX_ABS
    } else {
        crate::validate::LOG_MAX_ABS
    }
}

/// A `segment` cell: an integer, also written as a float with no fraction (`2.0`).
fn integer(file: &str, line: usize, field: usize, cell: &str) -> Result<i64, LogError> {
    if let Ok(v) = cell.parse::<i64>() {
        return Ok(v);
    }
    let v = number(file, line, "segment", field, cell)?;
    if v.fract() == 0.0 && v.abs() < 9.0e15 {
        return Ok(v as i64);
    }
    Err(LogError::new(
        file,
        Some(line),
        Some("segment"),
        K::NotNumeric,
        format!(
            "column `segment` (field {}): `{}` is not an integer",
            field + 1,
            quote(cell)
        ),
    ))
}

/// The text of a cell for a message, cut to [`QUOTE_MAX`] characters.
fn quote(s: &str) -> String {
    if s.chars().count() <= QUOTE_MAX {
        s.to_owned()
    } else {
        let mut q: String = s.chars().take(QUOTE_MAX).collect();
        q.push('…');
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_trim_white_space_and_quotes() {
        assert_eq!(fields(" t , \"x\",y,"), vec!["t", "x", "y", ""]);
        assert_eq!(fields("\""), vec!["\""]);
    }

    #[test]
    fn metadata_keys_are_one_word() {
        assert_eq!(metadata_entry(" rate_hz: 30"), Some(("rate_hz", "30")));
        assert_eq!(
            metadata_entry("frame: ENU, z up; Euler ZYX"),
            Some(("frame", "ENU, z up; Euler ZYX"))
        );
        assert_eq!(metadata_entry(" a note: not metadata"), None);
        assert_eq!(metadata_entry(" no colon"), None);
        assert_eq!(metadata_entry(": empty key"), None);
    }

    #[test]
    fn segment_values_are_integers() {
        assert_eq!(integer("f", 1, 0, "3").unwrap(), 3);
        assert_eq!(integer("f", 1, 0, "-2.0").unwrap(), -2);
        assert_eq!(integer("f", 1, 0, "1.5").unwrap_err().kind, K::NotNumeric);
        assert_eq!(integer("f", 1, 0, "nan").unwrap_err().kind, K::NonFinite);
        assert_eq!(integer("f", 1, 0, "1e300").unwrap_err().kind, K::OutOfRange);
    }

    #[test]
    fn numbers_must_be_finite() {
        assert_eq!(number("f", 1, "x", 0, "1e5").unwrap(), 1e5);
        assert_eq!(number("f", 1, "x", 0, ".5").unwrap(), 0.5);
        for bad in ["NaN", "nan", "inf", "-Infinity", "1e999"] {
            assert_eq!(number("f", 1, "x", 0, bad).unwrap_err().kind, K::NonFinite, "{bad}");
        }
        for bad in ["", "abc", "1,0", "0x10", "1.2.3"] {
            assert_eq!(number("f", 1, "x", 0, bad).unwrap_err().kind, K::NotNumeric, "{bad}");
        }
    }

    #[test]
    fn quotes_are_cut_on_a_character_boundary() {
        let long = "é".repeat(100);
        assert_eq!(quote(&long).chars().count(), QUOTE_MAX + 1);
        assert_eq!(quote("short"), "short");
    }
}
