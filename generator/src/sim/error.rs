//! Typed errors of the simulator: a bad plant file (naming the file and the JSON field) or bad
//! simulation options (naming the option).

use std::fmt;

/// What is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlantErrorKind {
    /// The file cannot be read.
    Io,
    /// Not JSON, or not UTF-8.
    Json,
    /// `format` is missing or not `uavgen-plant/1`.
    UnknownFormat,
    MissingField,
    UnknownField,
    /// A key of `effects` that is not one of [`super::EFFECT_NAMES`].
    UnknownEffect,
    /// NaN or an infinite number (JSON has neither; Python writes them anyway).
    NonFinite,
    /// A value of the wrong type (a string for a number, a fraction for an integer, …).
    BadType,
    /// A number outside its allowed range (negative mass, zero rate, probability above 1, …).
    OutOfRange,
    /// Two fields that contradict each other, or an effect that has nothing to act on.
    Inconsistent,
    /// A bad simulation option (profile list, durations).
    Options,
    /// Writing the log failed.
    Write,
}

/// An invalid plant file or simulation request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlantError {
    /// The plant file (as given), or empty for an option error.
    pub file: String,
    /// The JSON path of the offending field (`effects.latency.delay`), the option
    /// (`--profile`), or a line and column for JSON syntax errors; empty if none applies.
    pub field: String,
    pub kind: PlantErrorKind,
    pub message: String,
}

impl PlantError {
    pub fn new(file: &str, field: impl Into<String>, kind: PlantErrorKind, message: impl Into<String>) -> Self {
        Self {
            file: file.to_owned(),
            field: field.into(),
            kind,
            message: message.into(),
        }
    }

    /// An error in the simulation options rather than in a file.
    pub fn option(field: &str, message: impl Into<String>) -> Self {
        Self::new("", field, PlantErrorKind::Options, message)
    }
}

impl fmt::Display for PlantError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.file.is_empty(), self.field.is_empty()) {
            (false, false) => write!(f, "{}: {}: {}", self.file, self.field, self.message),
            (false, true) => write!(f, "{}: {}", self.file, self.message),
            (true, false) => write!(f, "{}: {}", self.field, self.message),
            (true, true) => f.write_str(&self.message),
        }
    }
}

impl std::error::Error for PlantError {}
