//! Flight logs in the `LOG_FORMAT.md` CSV contract (version 1): reading, validation, segments,
//! yaw unwrapping and a data-quality report.
//!
//! [`read_log`] / [`parse_log`] turn a log into a [`FlightLog`]: the `# key: value` metadata, the
//! data split into [`Segment`]s (a change of the `segment` column or a time gap of more than
//! [`GAP_PERIODS`] nominal periods starts a new one), yaw unwrapped within each segment, and a
//! [`QualityReport`] (sampling period and its uniformity, the metadata rate against the measured
//! one, stale sample-and-hold rows). Invalid input is a [`LogError`] naming the file, the line and
//! the column; no input makes the reader panic. See `docs/logs.md`.

mod error;
mod lines;
mod parse;
mod quality;
pub mod resample;
mod segments;
pub mod stale;

pub use error::{LogError, LogErrorKind};
pub use quality::{QualityReport, SegmentQuality, IRREGULAR_FRACTION, RATE_MISMATCH_FRACTION};
pub use segments::{median, unwrap_angle, SegmentStart, GAP_PERIODS};
pub use stale::StalePolicy;

use std::path::Path;

/// The state columns in the order of [`Segment::x`] and the input columns in the order of
/// [`Segment::u`]: the model format's default names (LOG_FORMAT.md).
pub use crate::model::{DEFAULT_INPUTS as INPUT_COLUMNS, DEFAULT_STATES as STATE_COLUMNS};

/// Index of yaw in the state vector.
pub const YAW: usize = 5;
/// Roll and pitch in the state (log order).
const ROLL: usize = 3;
const PITCH: usize = 4;

/// A row with z at or below this (m) is taken as on the ground (LOG_FORMAT.md's z is the height,
/// ground at 0): ground contact forces are not flight dynamics, and simulated logs of a heavy
/// vehicle rest there. `diagnose` leaves such samples out of every fit and score, and `evaluate` and
/// `diagnose` leave out the horizon free runs that touch them, alike.
pub const GROUND_CLEARANCE: f64 = 0.02;

/// Per row of states (the 12 logged ones first), whether it is on the ground ([`GROUND_CLEARANCE`]).
pub fn on_ground<const N: usize>(rows: &[[f64; N]]) -> Vec<bool> {
    rows.iter().map(|r| r[2] <= GROUND_CLEARANCE).collect()
}

/// Whether a free run over samples `k ..= k + len` touches the ground (`ground` from [`on_ground`]).
pub fn run_touches_ground(ground: &[bool], k: usize, len: usize) -> bool {
    ground[k..=k + len].iter().any(|g| *g)
}

/// A validated flight log.
#[derive(Clone, Debug, PartialEq)]
pub struct FlightLog {
    /// The file (or label) the log was read from.
    pub source: String,
    /// The `# key: value` lines before the header, in file order.
    pub metadata: Vec<(String, String)>,
    /// The data, one segment per continuous flight (at least one).
    pub segments: Vec<Segment>,
    pub report: QualityReport,
}

impl FlightLog {
    /// The value of the first metadata line with this key.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// Data rows over all segments.
    pub fn rows(&self) -> usize {
        self.segments.iter().map(Segment::len).sum()
    }
}

/// A continuous stretch of data: time increases, no gap.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// Index in [`FlightLog::segments`].
    pub index: usize,
    /// Time in s, strictly increasing.
    pub t: Vec<f64>,
    /// States `[x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate]` ([`STATE_COLUMNS`]);
    /// yaw is unwrapped (continuous).
    pub x: Vec<[f64; 12]>,
    /// Inputs `[u_vz u_roll u_pitch u_yaw_rate]` ([`INPUT_COLUMNS`]).
    pub u: Vec<[f64; 4]>,
    /// Present if the log has a `battery_voltage` column.
    pub battery_voltage: Option<Vec<f64>>,
    /// The line (1-based, as in an editor) of the segment's first data row.
    pub first_line: usize,
}

impl Segment {
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Last minus first time stamp.
    pub fn duration(&self) -> f64 {
        match (self.t.first(), self.t.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }
}

/// Read and validate a flight log; errors name the file as `path` displays.
///
/// The file is read line by line through a buffer and never held whole as text (the rows are:
/// docs/logs.md, "Memory"); the errors are those of [`parse_log`] on the file's text, and a file
/// that is not UTF-8 is an encoding error wherever its first invalid byte lies.
pub fn read_log(path: &Path) -> Result<FlightLog, LogError> {
    let label = path.display().to_string();
    let file = std::fs::File::open(path)
        .map_err(|e| LogError::new(&label, None, None, LogErrorKind::Io, format!("cannot read: {e}")))?;
    let mut lines = lines::ReaderLines::new(std::io::BufReader::with_capacity(1 << 16, file), &label);
    let table = match parse::parse(&mut lines, &label) {
        Ok(table) => table,
        Err(e) => {
            // Reading the whole text first would have found a read or encoding error anywhere.
            let first = match e.kind {
                LogErrorKind::Io | LogErrorKind::Encoding => None,
                _ => lines.error_in_rest(),
            };
            return Err(first.unwrap_or(e));
        }
    };
    drop(lines);
    from_table(table, &label)
}

/// Validate log text; `label` names the file in errors and in [`FlightLog::source`].
pub fn parse_log(text: &str, label: &str) -> Result<FlightLog, LogError> {
    from_table(parse::parse(&mut lines::TextLines::new(text), label)?, label)
}

/// The segments and the quality report of a validated table.
fn from_table(table: parse::Table, label: &str) -> Result<FlightLog, LogError> {
    let measured = segments::measured_period(&table.rows);
    // The nominal period: the metadata rate if given (a contradicting time column shows in the
    // report's warnings), else the median step. A metadata rate under which more than 90 % of the
    // steps of a log of more than [`quality::RATE_TRUSTED_ROWS`] rows would be gaps is not used to
    // find them: a wrong `# rate_hz` would split the log into single rows.
    let gap_share = |hz: f64| {
        let steps: Vec<bool> = table
            .rows
            .windows(2)
            .filter(|w| w[0].segment == w[1].segment)
            .map(|w| w[1].t - w[0].t > GAP_PERIODS / hz)
            .collect();
        steps.iter().filter(|g| **g).count() as f64 / steps.len().max(1) as f64
    };
    let nominal = match (table.rate_hz, measured) {
        (Some((hz, _)), Some(p)) if table.rows.len() > quality::RATE_TRUSTED_ROWS && gap_share(hz) > 0.9 => Some(p),
        (Some((hz, _)), _) => Some(1.0 / hz),
        (None, m) => m,
    };

    let rows = &table.rows;
    let mut segments = Vec::new();
    let mut qualities = Vec::new();
    for (index, (range, start)) in segments::split(rows, nominal).into_iter().enumerate() {
        let part = &rows[range];
        let (Some(first), Some(last)) = (part.first(), part.last()) else {
            continue;
        };
        let mut x: Vec<[f64; 12]> = part.iter().map(|r| r.x).collect();
        let mut yaw: Vec<f64> = x.iter().map(|s| s[YAW]).collect();
        let yaw_wraps = unwrap_angle(&mut yaw);
        for (s, y) in x.iter_mut().zip(yaw) {
            s[YAW] = y;
        }
        let segment = Segment {
            index,
            t: part.iter().map(|r| r.t).collect(),
            x,
            u: part.iter().map(|r| r.u).collect(),
            battery_voltage: if table.has_battery {
                Some(part.iter().filter_map(|r| r.battery).collect())
            } else {
                None
            },
            first_line: first.line,
        };
        let mut q = quality::segment_quality(&segment, last.line, start, first.segment, nominal);
        q.yaw_wraps = yaw_wraps;
        segments.push(segment);
        qualities.push(q);
    }
    let report = QualityReport {
        source: label.to_owned(),
        rows: rows.len(),
        metadata_rate_hz: table.rate_hz.map(|(hz, _)| hz),
        measured_period: measured,
        nominal_period: nominal,
        segments: qualities,
    };
    Ok(FlightLog {
        source: label.to_owned(),
        metadata: table.metadata,
        segments,
        report,
    })
}

/// Why [`load_any`] failed: the CSV reader's error or the importer's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LoadError {
    Log(LogError),
    Import(crate::import::ImportError),
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoadError::Log(e) => e.fmt(f),
            LoadError::Import(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for LoadError {}

/// A roll or pitch beyond ±π/2 (+ 0.05 rad for noise): no multirotor log in radians has one, a
/// log in degrees almost always does. The error names the time, the column and the fix.
/// [`load_any`] (identify, evaluate, diagnose) applies it; [`read_log`] reads any valid table.
pub fn refuse_degrees(log: &FlightLog) -> Result<(), LogError> {
    const LIMIT: f64 = std::f64::consts::FRAC_PI_2 + 0.05;
    let worst = log
        .segments
        .iter()
        .flat_map(|s| {
            s.t.iter()
                .zip(&s.x)
                .flat_map(|(t, x)| [(*t, ROLL, x[ROLL]), (*t, PITCH, x[PITCH])])
        })
        .max_by(|a, b| a.2.abs().total_cmp(&b.2.abs()));
    match worst {
        Some((t, col, v)) if v.abs() > LIMIT => Err(LogError::new(
            &log.source,
            None,
            Some(STATE_COLUMNS[col]),
            LogErrorKind::Degrees,
            format!(
                "`{}` is {v} at t = {t} s, beyond ±π/2: the angles look like degrees, and the log contract is in radians (roll, pitch, yaw in rad, their rates in rad/s): convert them, or import the file with a profile whose `scale` is 0.017453292519943295 (docs/import.md)",
                STATE_COLUMNS[col]
            ),
        )),
        _ => Ok(()),
    }
}

/// Read a flight log of any format uavgen reads: a CSV of the contract as [`read_log`] does, or
/// a PX4 ULog / MCAP / ROS 1 bag / DataFlash file imported with `profile` (a preset name or a
/// profile file; docs/import.md) at the position topic's own time stamps, or a CSV of another schema with a profile
/// that maps its columns. Angles that look like degrees are refused ([`refuse_degrees`]). What `--log` and
/// `--profile` of identify, evaluate and diagnose do.
pub fn load_any(path: &Path, profile: Option<&str>) -> Result<FlightLog, LoadError> {
    let log = load_any_table(path, profile)?;
    refuse_degrees(&log).map_err(LoadError::Log)?;
    Ok(log)
}

fn load_any_table(path: &Path, profile: Option<&str>) -> Result<FlightLog, LoadError> {
    use crate::import::{Format, ImportError, ImportErrorKind, ImportOptions, Profile};
    let label = path.display().to_string();
    let format = match Format::from_extension(path) {
        Some(f) => Some(f),
        None => {
            // Look at the first bytes of a file without a known extension.
            let mut head = [0u8; 16];
            let n = std::fs::File::open(path)
                .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
                .unwrap_or(0);
            Format::sniff(&head[..n])
        }
    };
    // A CSV is the contract unless the profile maps CSV columns (it has a `time` column).
    let csv_profile = match (format, profile) {
        (None | Some(Format::Csv), Some(p)) => {
            Some(Profile::resolve(p).map_err(LoadError::Import)?).filter(|p| p.time.is_some())
        }
        _ => None,
    };
    let format = match (format, csv_profile) {
        (None | Some(Format::Csv), None) => return read_log(path).map_err(LoadError::Log),
        (None, Some(_)) => Format::Csv,
        (Some(f), _) => f,
    };
    let Some(profile) = profile else {
        return Err(LoadError::Import(ImportError::new(
            &label,
            ImportErrorKind::Profile,
            format!(
                "a {} file needs --profile: a preset ({}) or a profile file (docs/import.md)",
                format.name(),
                crate::import::PRESETS.map(|(n, _)| n).join(", ")
            ),
        )));
    };
    let profile = Profile::resolve(profile).map_err(LoadError::Import)?;
    let imported = crate::import::import_file(path, &profile, &ImportOptions::default()).map_err(LoadError::Import)?;
    parse_log(&imported.to_csv(), &label).map_err(LoadError::Log)
}
