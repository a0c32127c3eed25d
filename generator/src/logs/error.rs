//! Typed errors for flight logs. Every error names the file, and where it
//! applies the line (1-based, counting comment and blank lines, as an editor
//! shows it) and the column, so a user can fix the log without reading code.

use std::fmt;

/// What is wrong with a log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LogErrorKind {
    /// The file cannot be read.
    Io,
    /// The file is not UTF-8.
    Encoding,
    /// The file is empty (or only white space).
    Empty,
    /// No header row: only comments, or the first non-comment line is numbers.
    NoHeader,
    /// One or more required columns are missing from the header.
    MissingColumns,
    /// A column name appears twice in the header.
    DuplicateColumn,
    /// A data row has a different number of fields than the header.
    FieldCount,
    /// A cell of a known column is empty or not a number (or, for `segment`, not an integer).
    NotNumeric,
    /// A cell of a known column is NaN or infinite (or overflows f64).
    NonFinite,
    /// A cell of a known column is finite but beyond the range of any flight
    /// (|value| > [`crate::validate::LOG_MAX_ABS`]; docs/logs.md).
    OutOfRange,
    /// `t` goes backwards or repeats within a segment.
    TimeNotIncreasing,
    /// A header but no data rows.
    NoData,
    /// Roll or pitch beyond ±π/2: the angles look like degrees (the contract is in radians).
    Degrees,
    /// A metadata line the reader uses is invalid: `rate_hz` not a positive number, or given twice
    /// with different values.
    Metadata,
}

/// An invalid flight log.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogError {
    /// The file as given to [`read_log`](super::read_log) or the label given to [`parse_log`](super::parse_log).
    pub file: String,
    /// 1-based line number (comment and blank lines count), if the error is on one line.
    pub line: Option<usize>,
    /// The column (or columns, comma separated) at fault, if any.
    pub column: Option<String>,
    pub kind: LogErrorKind,
    /// The description, without the file and line; it names the column.
    pub message: String,
}

impl LogError {
    pub(crate) fn new(
        file: &str,
        line: Option<usize>,
        column: Option<&str>,
        kind: LogErrorKind,
        message: impl Into<String>,
    ) -> Self {
        Self {
            file: file.to_owned(),
            line,
            column: column.map(str::to_owned),
            kind,
            message: message.into(),
        }
    }
}

/// `FILE:LINE: message` (as compilers print it, so editors can jump to it), or `FILE: message`.
impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.file, line, self.message),
            None => write!(f, "{}: {}", self.file, self.message),
        }
    }
}

impl std::error::Error for LogError {}
