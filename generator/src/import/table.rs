//! CSV (and other delimited) logs of another schema: a [`Recording`] with one topic,
//! [`CSV_TOPIC`], whose fields are the columns, timed by the profile's `time` column
//! (docs/import.md, "CSV of another schema").
//!
//! The delimiter is the header's most frequent of `,` `;` tab (whitespace when none occurs); line
//! ends may be LF, CRLF or CR alone; blank lines and lines starting with `#` are skipped. Every
//! cell of a column the profile maps must be a finite number: an empty, non-numeric, NaN or
//! infinite cell is an error naming the line, the column and the time.

use super::error::{list_names, ImportError, ImportErrorKind};
use super::profile::{Profile, CSV_TOPIC};
use super::recording::{Recording, SeriesBuilder};

/// How cells are separated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Delimiter {
    Char(char),
    Whitespace,
}

impl Delimiter {
    fn detect(header: &str) -> Self {
        [',', ';', '\t']
            .into_iter()
            .map(|c| (header.matches(c).count(), c))
            .filter(|(n, _)| *n > 0)
            .max_by_key(|(n, _)| *n)
            .map_or(Delimiter::Whitespace, |(_, c)| Delimiter::Char(c))
    }

    fn split(self, line: &str) -> Vec<&str> {
        match self {
            Delimiter::Char(c) => line.split(c).map(|s| s.trim().trim_matches('"')).collect(),
            Delimiter::Whitespace => line.split_whitespace().collect(),
        }
    }
}

/// The data lines of `text` with their 1-based line numbers (LF, CRLF or CR line ends; blank and
/// `#` lines skipped).
fn lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    // A CR not followed by LF ends a line too (old Mac exports).
    let cr_only = text.contains('\r') && !text.contains('\n');
    let split: Box<dyn Iterator<Item = &str>> = if cr_only {
        Box::new(text.split('\r'))
    } else {
        Box::new(text.split('\n'))
    };
    split
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r').trim_start_matches('\u{feff}')))
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
}

/// Read a delimited log with `profile` (which must have `time`; only the columns it maps are
/// read as numbers).
pub fn read(file: &str, bytes: &[u8], profile: &Profile) -> Result<Recording, ImportError> {
    let fail = |kind, m: String| ImportError::new(file, kind, m);
    let Some(time) = &profile.time else {
        return Err(fail(
            ImportErrorKind::Profile,
            format!(
                "profile `{}` has no `time` column: a CSV of another schema needs one (`\"time\": {{ \"field\": \"t\", \"unit\": \"s\" }}`; `uavgen import --print-profile csv` prints a template)",
                profile.name
            ),
        ));
    };
    let text = std::str::from_utf8(bytes).map_err(|e| {
        fail(
            ImportErrorKind::WrongFormat,
            format!("not UTF-8 text (byte {})", e.valid_up_to()),
        )
    })?;
    let mut rows = lines(text);
    let Some((_, header)) = rows.next() else {
        return Err(fail(
            ImportErrorKind::NoData,
            "no header row: the file has only comment and blank lines".into(),
        ));
    };
    let delimiter = Delimiter::detect(header);
    let columns: Vec<String> = delimiter.split(header).into_iter().map(str::to_owned).collect();
    let mut rec = Recording::new(file, "CSV of another schema");
    rec.available.insert(CSV_TOPIC.to_owned(), columns.clone());
    let index = |name: &str| columns.iter().position(|c| c == name);
    let t_col = index(&time.field).ok_or_else(|| {
        fail(
            ImportErrorKind::MissingField,
            format!(
                "no time column `{}`; the columns are {}",
                time.field,
                list_names(&columns, 80)
            ),
        )
    })?;
    // The mapped columns of the one topic (others are not read: they may hold text).
    let mut wanted: Vec<String> = Vec::new();
    for (topic, field) in profile.needs() {
        if topic == CSV_TOPIC && index(&field).is_some() && !wanted.contains(&field) {
            wanted.push(field);
        }
    }
    let mut builder = SeriesBuilder::new(&wanted);
    let wanted_idx: Vec<(String, usize)> = wanted.iter().map(|f| (f.clone(), index(f).unwrap_or(0))).collect();
    let unit = time.unit.seconds();
    let mut values = std::collections::HashMap::new();
    for (line, text) in rows {
        let cells = delimiter.split(text);
        if cells.len() != columns.len() {
            return Err(fail(
                ImportErrorKind::BadValue,
                format!(
                    "line {line}: {} cells, the header has {} columns (delimiter {})",
                    cells.len(),
                    columns.len(),
                    match delimiter {
                        Delimiter::Char('\t') => "tab".to_string(),
                        Delimiter::Char(c) => format!("`{c}`"),
                        Delimiter::Whitespace => "whitespace".to_string(),
                    }
                ),
            ));
        }
        let number = |col: usize| -> Result<f64, ImportError> {
            let cell = cells[col];
            match cell.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(fail(
                    ImportErrorKind::BadValue,
                    format!(
                        "line {line}, column `{}`: `{cell}` is not a finite number{}",
                        columns[col],
                        if col == t_col {
                            String::new()
                        } else {
                            format!(" (time `{}` = {})", columns[t_col], cells[t_col])
                        }
                    ),
                )),
            }
        };
        let t = number(t_col)? * unit;
        values.clear();
        for (name, col) in &wanted_idx {
            values.insert(name.as_str(), number(*col)?);
        }
        builder.push(
            file,
            CSV_TOPIC,
            t,
            || format!("line {line}"),
            |name| values.get(name).copied(),
        )?;
    }
    if builder.series.t.is_empty() {
        return Err(fail(ImportErrorKind::NoData, "no data rows after the header".into()));
    }
    rec.series.insert(CSV_TOPIC.to_owned(), builder.series);
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile() -> Profile {
        Profile::resolve("csv").unwrap()
    }

    #[test]
    fn delimiters_and_line_ends() {
        assert_eq!(Delimiter::detect("a;b;c"), Delimiter::Char(';'));
        assert_eq!(Delimiter::detect("a\tb,c\td"), Delimiter::Char('\t'));
        assert_eq!(Delimiter::detect("a b  c"), Delimiter::Whitespace);
        let got: Vec<(usize, &str)> = lines("# c\ra,b\r1,2\r\r3,4").collect();
        assert_eq!(got, vec![(2, "a,b"), (3, "1,2"), (5, "3,4")]);
        let got: Vec<(usize, &str)> = lines("a,b\r\n1,2\r\n").collect();
        assert_eq!(got, vec![(1, "a,b"), (2, "1,2")]);
    }

    #[test]
    fn a_bad_cell_names_line_column_and_time() {
        let p = profile();
        let header = p.needs().iter().map(|(_, f)| f.clone()).collect::<Vec<_>>();
        let mut cols = vec![p.time.as_ref().unwrap().field.clone()];
        cols.extend(header);
        let row = |t: &str, v: &str| {
            let mut r = vec![t.to_string()];
            r.extend((1..cols.len()).map(|_| v.to_string()));
            r.join(",")
        };
        let text = format!("{}\n{}\n{}\n", cols.join(","), row("0", "1"), row("10", "nan"));
        let e = read("m.csv", text.as_bytes(), &p).unwrap_err();
        assert_eq!(e.kind, ImportErrorKind::BadValue);
        assert!(e.message.starts_with("line 3, column `"), "{e}");
        assert!(e.message.contains("`nan` is not a finite number (time `"), "{e}");
        let text = format!("{}\n{}\n{}\n", cols.join(","), row("10", "1"), row("0", "1"));
        let e = read("m.csv", text.as_bytes(), &p).unwrap_err();
        assert_eq!(e.kind, ImportErrorKind::TimeBackwards);
        assert!(e.message.contains("line 3"), "{e}");
    }
}
