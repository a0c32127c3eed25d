//! Typed import errors. Every error names the file; where it applies, the topic, the field and
//! the byte offset (or message index), and what the file has instead, so that the user can fix the
//! profile or see where a file broke without reading code.

use std::fmt;

/// What is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ImportErrorKind {
    /// The file cannot be read (or the output cannot be written).
    Io,
    /// The file is not of a format uavgen imports, or not the one its extension says.
    WrongFormat,
    /// The profile is invalid (unknown preset, bad JSON, inconsistent mapping).
    Profile,
    /// A topic the profile maps is not in the file.
    MissingTopic,
    /// A field the profile maps is not in the topic (or not numeric).
    MissingField,
    /// The file breaks before its end (truncated or corrupt) and too little was read before the
    /// break to import anything; or a record inside it cannot be decoded.
    Corrupt,
    /// A topic's time stamps go backwards.
    TimeBackwards,
    /// The mapped channels do not overlap in time, or leave fewer than two rows.
    NoData,
    /// A value cannot be converted (a zero quaternion, pitch at ±90° for body → Euler rates).
    BadValue,
}

/// An import failure.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportError {
    /// The input file as given.
    pub file: String,
    pub kind: ImportErrorKind,
    /// The description, naming topic, field and offset where they apply.
    pub message: String,
}

impl ImportError {
    pub fn new(file: &str, kind: ImportErrorKind, message: impl Into<String>) -> Self {
        Self {
            file: file.to_owned(),
            kind,
            message: message.into(),
        }
    }
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.file, self.message)
    }
}

impl std::error::Error for ImportError {}

/// A comma list of names for messages, at most `max` shown (`a, b, c and 12 more`).
pub fn list_names<S: AsRef<str>>(names: &[S], max: usize) -> String {
    if names.is_empty() {
        return "none".into();
    }
    let shown: Vec<String> = names.iter().take(max).map(|s| format!("`{}`", s.as_ref())).collect();
    let mut out = shown.join(", ");
    if names.len() > max {
        out.push_str(&format!(" and {} more", names.len() - max));
    }
    out
}
