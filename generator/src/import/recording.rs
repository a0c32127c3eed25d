//! What every format reader produces: the numeric fields a profile asks for, one time series per
//! topic, plus the names of everything the file has (for "missing topic" errors) and how the
//! file ended.

use super::error::{list_names, ImportError, ImportErrorKind};
use std::collections::BTreeMap;

/// One topic's samples: strictly non-decreasing time in s and the requested fields.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    pub t: Vec<f64>,
    /// Field name → values, as long as `t`.
    pub fields: BTreeMap<String, Vec<f64>>,
}

/// A file read into the profile's topics.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// The file as given (for errors).
    pub file: String,
    /// "PX4 ULog", "MCAP", …
    pub format: &'static str,
    /// Topic → the fields it has (all topics of the file, not only the requested ones).
    pub available: BTreeMap<String, Vec<String>>,
    /// Requested topic → its samples (requested fields only).
    pub series: BTreeMap<String, Series>,
    /// Set when the file broke before its end: where and why. The samples before the break are
    /// kept.
    pub broken: Option<String>,
    /// Notes for the report (e.g. topics with several instances, the one used).
    pub notes: Vec<String>,
}

impl Recording {
    pub fn new(file: &str, format: &'static str) -> Self {
        Self {
            file: file.to_owned(),
            format,
            ..Self::default()
        }
    }

    /// The series of a topic with the named fields; errors name what is missing and list what the
    /// file has.
    pub fn series(&self, topic: &str, fields: &[&str]) -> Result<(&[f64], Vec<&[f64]>), ImportError> {
        let Some(available) = self.available.get(topic) else {
            let topics: Vec<&String> = self.available.keys().collect();
            return Err(ImportError::new(
                &self.file,
                ImportErrorKind::MissingTopic,
                format!(
                    "topic `{topic}` is not in this {} file; it has {}",
                    self.format,
                    list_names(&topics, 60)
                ),
            ));
        };
        let mut columns = Vec::new();
        for f in fields {
            let listed = available.iter().any(|a| a == f);
            let column = self.series.get(topic).and_then(|s| s.fields.get(*f)).filter(|_| listed);
            match column {
                Some(c) => columns.push(c.as_slice()),
                None => {
                    return Err(ImportError::new(
                        &self.file,
                        ImportErrorKind::MissingField,
                        format!(
                            "topic `{topic}` has no numeric field `{f}`; its fields are {}",
                            list_names(available, 80)
                        ),
                    ))
                }
            }
        }
        let t = self.series.get(topic).map(|s| s.t.as_slice()).unwrap_or(&[]);
        if t.is_empty() {
            let why = match &self.broken {
                Some(b) => format!(" before the file breaks ({b})"),
                None => String::new(),
            };
            return Err(ImportError::new(
                &self.file,
                ImportErrorKind::NoData,
                format!("topic `{topic}` has no samples{why}"),
            ));
        }
        Ok((t, columns))
    }
}

/// Collects one topic's samples while a reader walks a file, checking that time does not go
/// backwards.
#[derive(Debug, Default)]
pub struct SeriesBuilder {
    pub series: Series,
    last_where: String,
}

impl SeriesBuilder {
    pub fn new(fields: &[String]) -> Self {
        let mut series = Series::default();
        for f in fields {
            series.fields.insert(f.clone(), Vec::new());
        }
        Self {
            series,
            last_where: String::new(),
        }
    }

    /// Append one sample. `get` returns a field's value (`None`: not numeric / absent, which the
    /// reader checked earlier); `at` describes where the sample is in the file (for errors).
    pub fn push(
        &mut self,
        file: &str,
        topic: &str,
        t: f64,
        at: impl Fn() -> String,
        mut get: impl FnMut(&str) -> Option<f64>,
    ) -> Result<(), ImportError> {
        if let Some(&last) = self.series.t.last() {
            if t < last {
                return Err(ImportError::new(
                    file,
                    ImportErrorKind::TimeBackwards,
                    format!(
                        "topic `{topic}`: time goes backwards at {}: t = {t} s after t = {last} s at {}",
                        at(),
                        self.last_where
                    ),
                ));
            }
        }
        for (name, column) in self.series.fields.iter_mut() {
            column.push(get(name).unwrap_or(f64::NAN));
        }
        self.series.t.push(t);
        self.last_where = at();
        Ok(())
    }
}
