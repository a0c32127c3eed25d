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
    /// Damaged stretches of the file that the reader skipped, resynchronising on the records
    /// after them (a zero-filled block: the usual SD-card fault). Never silent: without
    /// `--partial` the import is an error that says where and what was lost ([`Recording::damage_report`]).
    pub damage: Vec<Damage>,
}

/// A stretch of a file that could not be read as records, skipped by the reader.
#[derive(Clone, Debug, PartialEq)]
pub struct Damage {
    /// First byte that could not be read (the start of the record the damage begins in).
    pub from: usize,
    /// First byte read again (the record the reader resynchronised on), or the file's end.
    pub to: usize,
    /// Whether the reader found records again after it (`false`: the rest of the file is lost).
    pub resynced: bool,
    /// Why the reader stopped at `from`.
    pub why: String,
    /// How many of the stretch's bytes are zero.
    pub zeros: usize,
    /// Requested topic → how many samples it had when the damage was met (its samples before).
    pub marks: BTreeMap<String, usize>,
}

/// What one damaged stretch cost one topic.
#[derive(Clone, Debug, PartialEq)]
pub struct Loss {
    pub topic: String,
    /// Samples missing (estimated from the gap and the topic's median period).
    pub samples: usize,
    /// The last sample before and the first after the damage (s); `None` after: to the end.
    pub before: Option<f64>,
    pub after: Option<f64>,
    /// Seconds without a sample: `samples` × the median period.
    pub seconds: f64,
}

impl Damage {
    /// A damaged stretch met at byte `from`; `marks` from the readers' builders.
    pub fn new(from: usize, why: String, builders: &BTreeMap<String, SeriesBuilder>) -> Damage {
        Damage {
            from,
            to: from,
            resynced: false,
            why,
            zeros: 0,
            marks: builders.iter().map(|(t, b)| (t.clone(), b.series.t.len())).collect(),
        }
    }

    /// Close the stretch at `to` (`resynced`: records are read again from there).
    pub fn close(&mut self, bytes: &[u8], to: usize, resynced: bool) {
        self.to = to.max(self.from);
        self.resynced = resynced;
        self.zeros = bytes
            .get(self.from..self.to)
            .map_or(0, |b| b.iter().filter(|x| **x == 0).count());
    }

    /// The samples each requested topic lost here (topics that lost none are left out).
    pub fn losses(&self, series: &BTreeMap<String, Series>) -> Vec<Loss> {
        let mut out = Vec::new();
        for (topic, &n) in &self.marks {
            let Some(s) = series.get(topic) else { continue };
            let before = n.checked_sub(1).and_then(|i| s.t.get(i)).copied();
            let after = if self.resynced { s.t.get(n).copied() } else { None };
            let steps: Vec<f64> = s.t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
            let period = crate::logs::median(&steps);
            let (samples, seconds) = match (before, after, period) {
                (Some(a), Some(b), Some(p)) => {
                    let k = (((b - a) / p).round() as usize).saturating_sub(1);
                    (k, k as f64 * p)
                }
                // Nothing after the damage: everything the topic would have logged to the end.
                (_, None, _) if !self.resynced => {
                    let end = series
                        .values()
                        .filter_map(|s| s.t.last())
                        .fold(f64::NAN, |m, t| m.max(*t));
                    let from = before.unwrap_or(f64::NAN);
                    let k = match period {
                        Some(p) if end > from => ((end - from) / p).round() as usize,
                        _ => 0,
                    };
                    // Whatever came after the last sample read is unknown: at least one sample.
                    (k.max(1), period.map_or(0.0, |p| k.max(1) as f64 * p))
                }
                _ => (0, 0.0),
            };
            if samples > 0 {
                out.push(Loss {
                    topic: topic.clone(),
                    samples,
                    before,
                    after,
                    seconds,
                });
            }
        }
        out
    }

    /// One sentence: where, how many bytes, what was lost.
    pub fn describe(&self, series: &BTreeMap<String, Series>, format: &str) -> String {
        let unit = format!("{format} record");
        let len = self.to - self.from;
        let kind = if len > 0 && self.zeros * 10 >= len * 9 {
            ", zero-filled"
        } else {
            ""
        };
        let span = if self.resynced {
            format!(
                "bytes {} … {} ({len} bytes{kind}) cannot be read as {unit}s, the reader resumes at byte {}",
                self.from, self.to, self.to
            )
        } else {
            format!(
                "from byte {} to the end ({len} bytes{kind}) nothing can be read as {unit}s",
                self.from
            )
        };
        let losses = self.losses(series);
        let lost = if losses.is_empty() {
            "no sample of a mapped topic is lost (only records of other topics)".to_owned()
        } else {
            let parts: Vec<String> = losses
                .iter()
                .map(|l| {
                    let fmt = |t: Option<f64>| t.map_or("?".to_owned(), |t| format!("{t}"));
                    match l.after {
                        Some(_) => format!(
                            "`{}` {} sample{}, {:.3} s (none between t = {} and {} s)",
                            l.topic,
                            l.samples,
                            if l.samples == 1 { "" } else { "s" },
                            l.seconds,
                            fmt(l.before),
                            fmt(l.after)
                        ),
                        None => format!(
                            "`{}` everything after t = {} s (about {} samples, {:.3} s)",
                            l.topic,
                            fmt(l.before),
                            l.samples,
                            l.seconds
                        ),
                    }
                })
                .collect();
            format!("lost: {}", parts.join("; "))
        };
        format!("damaged at byte {}: {} ({}); {lost}", self.from, span, self.why)
    }
}

impl Recording {
    pub fn new(file: &str, format: &'static str) -> Self {
        Self {
            file: file.to_owned(),
            format,
            ..Self::default()
        }
    }

    /// The builders' samples become the recording's series.
    pub fn take_series(&mut self, builders: BTreeMap<String, SeriesBuilder>) {
        for (topic, b) in builders {
            self.series.insert(topic, b.series);
        }
    }

    /// For formats whose schema lists a sequence's fields as `name[i]` only as messages carry them:
    /// a requested field some message carried (a finite sample) joins its topic's available
    /// fields; one the schema has but no message carried (an empty sequence) is not listed.
    pub fn list_carried_fields(&mut self) {
        for (topic, series) in self.series.iter() {
            if let Some(fields) = self.available.get_mut(topic) {
                for (f, v) in &series.fields {
                    if !fields.contains(f) && v.iter().any(|x| !x.is_nan()) {
                        fields.push(f.clone());
                    }
                }
            }
        }
    }

    /// Every damaged stretch in one line each (empty: none).
    pub fn damage_report(&self) -> Vec<String> {
        self.damage
            .iter()
            .map(|d| d.describe(&self.series, self.format))
            .collect()
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
    /// One builder per topic of the requested `(topic, field)` pairs, each collecting its fields.
    pub fn for_needs(needs: &[(String, String)]) -> BTreeMap<String, SeriesBuilder> {
        let mut wanted: BTreeMap<&str, Vec<String>> = BTreeMap::new();
        for (topic, field) in needs {
            wanted.entry(topic.as_str()).or_default().push(field.clone());
        }
        wanted
            .into_iter()
            .map(|(t, f)| (t.to_string(), SeriesBuilder::new(&f)))
            .collect()
    }

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

impl super::profile::Available for Recording {
    fn usable(&self, topic: &str, fields: &[String]) -> Option<bool> {
        let available = self.available.get(topic)?;
        if !fields.iter().all(|f| available.contains(f)) {
            return None;
        }
        let Some(series) = self.series.get(topic) else {
            return Some(false);
        };
        let columns: Vec<&Vec<f64>> = fields.iter().filter_map(|f| series.fields.get(f)).collect();
        if columns.len() != fields.len() {
            return Some(false);
        }
        Some((0..series.t.len()).any(|i| columns.iter().all(|c| c[i].is_finite())))
    }

    fn topics(&self) -> Vec<String> {
        self.available.keys().cloned().collect()
    }

    fn fields(&self, topic: &str) -> Option<Vec<String>> {
        self.available.get(topic).cloned()
    }
}
