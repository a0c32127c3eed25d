//! Typed errors for model files. Every error names the file and the field,
//! entry or term at fault, so a user can fix the file without reading code.

use std::fmt;

/// What is wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelErrorKind {
    Io,
    Json,
    UnknownFormat,
    UnknownKind,
    MissingField,
    UnknownField,
    UnknownVariable,
    BadTerm,
    NonFinite,
    Duplicate,
    WrongCount,
    BadValue,
}

/// An invalid model file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelError {
    pub file: String,
    /// JSON path of the offending field (`coefficients[3].term`), or a line/column.
    pub location: String,
    pub kind: ModelErrorKind,
    pub message: String,
}

impl ModelError {
    pub fn new(file: &str, location: impl Into<String>, kind: ModelErrorKind, message: impl Into<String>) -> Self {
        Self {
            file: file.to_owned(),
            location: location.into(),
            kind,
            message: message.into(),
        }
    }
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.location.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}: {}: {}", self.file, self.location, self.message)
        }
    }
}

impl std::error::Error for ModelError {}
