//! Import flight logs of other flight stacks into the log contract (docs/import.md).
//!
//! A format reader ([`ulog`], [`dataflash`]; [`mcap`] and [`bag`] with [`rosmsg`]) turns a file into a [`Recording`] (the profile's
//! topics and fields as time series, the names of everything else in the file, and where the file
//! broke if it did); [`assemble`] converts it with a [`Profile`] into rows of the log contract
//! (frames, Euler angles and their rates, zero-order hold onto the row times, stale flags,
//! segments); [`Imported::to_csv`] writes them. [`import_file`] does all three;
//! [`crate::logs::load_any`] lets identify, evaluate and diagnose read such files directly.

pub mod assemble;
pub mod bag;
pub mod dataflash;
pub mod error;
pub mod frames;
pub mod mcap;
mod mcap_lengths;
pub mod profile;
pub mod recording;
pub mod rosmsg;
pub mod table;
pub mod ulog;

pub use assemble::{GridOptions, Row, Summary, GROUPS};
pub use error::{ImportError, ImportErrorKind};
pub use profile::{Profile, PRESETS, PROFILE_FORMAT};
pub use recording::{Recording, Series};

use std::fmt::Write as _;
use std::path::Path;

/// The file formats uavgen reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The log contract itself.
    Csv,
    /// PX4 ULog, `.ulg`.
    Ulog,
    /// MCAP (ROS 2, Foxglove), `.mcap`.
    Mcap,
    /// ROS 1 bag, `.bag`.
    Bag,
    /// ArduPilot DataFlash, `.bin`.
    DataFlash,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Csv => "CSV flight log",
            Format::Ulog => "PX4 ULog",
            Format::Mcap => "MCAP",
            Format::Bag => "ROS 1 bag",
            Format::DataFlash => "ArduPilot DataFlash",
        }
    }

    /// The format an extension names (case-insensitive), if any.
    pub fn from_extension(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "csv" => Format::Csv,
            "ulg" | "ulog" => Format::Ulog,
            "mcap" => Format::Mcap,
            "bag" => Format::Bag,
            "bin" => Format::DataFlash,
            _ => return None,
        })
    }

    /// The format the first bytes show, if any.
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        if bytes.starts_with(&ulog::MAGIC) {
            Some(Format::Ulog)
        } else if bytes.starts_with(b"\x89MCAP") {
            Some(Format::Mcap)
        } else if bytes.starts_with(b"#ROSBAG V2.0") {
            Some(Format::Bag)
        } else if bytes.len() >= 3 && bytes[0] == 0xA3 && bytes[1] == 0x95 {
            Some(Format::DataFlash)
        } else {
            None
        }
    }
}

/// Options of [`import_file`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportOptions {
    pub grid: GridOptions,
    /// Import the part before the break of a truncated or corrupt file (otherwise such a file is
    /// an error that says where it broke and how much could be read).
    pub partial: bool,
}

/// An imported log.
#[derive(Clone, Debug)]
pub struct Imported {
    pub source: String,
    pub format: Format,
    pub profile: String,
    pub rows: Vec<Row>,
    pub summary: Summary,
    pub options: ImportOptions,
    /// Where the file broke (truncated or corrupt), if it did; the rows are from before the break.
    pub broken: Option<String>,
    /// The damaged stretches skipped inside the file (with `--partial`): where, and the samples
    /// and seconds each mapped topic lost there, one line each.
    pub damaged: Vec<String>,
    /// Which source feeds each contract field, one line per channel, when the profile offers
    /// alternatives (`rates` from `vehicle_attitude` in an older PX4 log, …); empty otherwise.
    pub choices: Vec<String>,
    pub notes: Vec<String>,
}

/// Damaged stretches named in an error (the rest are counted).
const MAX_SHOWN: usize = 5;

/// Read `path` (format from its first bytes, checked against its extension), map it with
/// `profile`.
pub fn import_file(path: &Path, profile: &Profile, options: &ImportOptions) -> Result<Imported, ImportError> {
    let label = path.display().to_string();
    let bytes =
        std::fs::read(path).map_err(|e| ImportError::new(&label, ImportErrorKind::Io, format!("cannot read: {e}")))?;
    import_bytes(&label, Format::from_extension(path), &bytes, profile, options)
}

/// [`import_file`] on bytes in memory; `claimed` is the format the file name says, if any.
pub fn import_bytes(
    label: &str,
    claimed: Option<Format>,
    bytes: &[u8],
    profile: &Profile,
    options: &ImportOptions,
) -> Result<Imported, ImportError> {
    let format = match (Format::sniff(bytes), claimed) {
        (Some(f), _) => f,
        (None, Some(Format::Csv)) => Format::Csv,
        (None, None) if profile.time.is_some() => Format::Csv,
        (None, Some(f)) => {
            return Err(ImportError::new(
                label,
                ImportErrorKind::WrongFormat,
                format!(
                    "not a {} file: its first bytes ({}) are not the format's signature",
                    f.name(),
                    hex_prefix(bytes)
                ),
            ))
        }
        (None, None) => {
            return Err(ImportError::new(
                label,
                ImportErrorKind::WrongFormat,
                format!(
                    "not a file uavgen imports: its first bytes ({}) are none of PX4 ULog, MCAP, ROS 1 bag, ArduPilot DataFlash",
                    hex_prefix(bytes)
                ),
            ))
        }
    };
    if let Some(c) = claimed.filter(|c| *c != format && *c != Format::Csv) {
        return Err(ImportError::new(
            label,
            ImportErrorKind::WrongFormat,
            format!("the name says {} but the content is {}", c.name(), format.name()),
        ));
    }
    let needs = profile.needs();
    let rec = match format {
        Format::Ulog => ulog::read(label, bytes, &needs)?,
        Format::Mcap => mcap::read(label, bytes, &needs, profile.clock)?,
        Format::Bag => bag::read(label, bytes, &needs, profile.clock)?,
        Format::DataFlash => dataflash::read(label, bytes, &needs)?,
        Format::Csv if profile.time.is_none() => {
            return Err(ImportError::new(
                label,
                ImportErrorKind::WrongFormat,
                format!(
                    "a CSV: profile `{}` maps recordings of a flight stack, not CSV columns. A CSV of the contract (docs/log-format.md) is used directly; a CSV of another schema needs a profile with a `time` column and the `csv` topic: `uavgen import --print-profile csv > my.json`, edit its column names, units and frames, then `--profile my.json` (docs/import.md)",
                    profile.name
                ),
            ))
        }
        Format::Csv => table::read(label, bytes, profile)?,
    };
    // A profile with alternatives (older versions of a flight stack): one source per channel.
    let (chosen, choices) = profile.choose(label, &rec)?;
    let assembled = assemble::assemble(&rec, &chosen, options.grid);
    let damaged = rec.damage_report();
    if (rec.broken.is_some() || !damaged.is_empty()) && !options.partial {
        let mut problems = damaged.clone();
        problems.extend(rec.broken.clone());
        let read = match &assembled {
            Ok((rows, _)) if damaged.is_empty() => format!(
                "{} rows (t = {} … {} s) can be imported from before the break: pass --partial to keep them",
                rows.len(),
                rows.first().map_or(0.0, |r| r.t),
                rows.last().map_or(0.0, |r| r.t)
            ),
            Ok((rows, _)) => format!(
                "pass --partial to import the {} rows that can be read (t = {} … {} s; a channel that lost samples is held or the rows cut out as a gap)",
                rows.len(),
                rows.first().map_or(0.0, |r| r.t),
                rows.last().map_or(0.0, |r| r.t)
            ),
            Err(e) => format!("nothing usable around the damage ({})", e.message),
        };
        let shown = problems.len().min(MAX_SHOWN);
        let more = match problems.len() - shown {
            0 => String::new(),
            k => format!("; and {k} more damaged stretch(es)"),
        };
        return Err(ImportError::new(
            label,
            ImportErrorKind::Corrupt,
            format!("{}{more}; {read}", problems[..shown].join("; ")),
        ));
    }
    let (rows, summary) = assembled?;
    Ok(Imported {
        source: label.to_owned(),
        format,
        profile: profile.name.clone(),
        rows,
        summary,
        options: options.clone(),
        broken: rec.broken,
        damaged,
        choices,
        notes: rec.notes,
    })
}

fn hex_prefix(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return "the file is empty".into();
    }
    bytes
        .iter()
        .take(8)
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The CSV header: the 17 contract columns, then `battery_voltage` (if mapped), `segment`, `stale`.
pub fn header(battery: bool) -> String {
    let mut h = String::from("t");
    for c in crate::logs::STATE_COLUMNS
        .iter()
        .chain(crate::logs::INPUT_COLUMNS.iter())
    {
        h.push(',');
        h.push_str(c);
    }
    if battery {
        h.push_str(",battery_voltage");
    }
    h.push_str(",segment,stale");
    h
}

/// The pause put between the files of [`Imported::append`], s (as the simulator's segments).
pub const FILE_GAP_S: f64 = 2.0;

impl Imported {
    /// Append `next` (another file of the same flight campaign) as further segments: its segment
    /// numbers follow this log's, and its times are shifted, if needed, to start [`FILE_GAP_S`]
    /// after this log's end (each file's own clock usually starts at 0). The shift is noted.
    pub fn append(&mut self, mut next: Imported) {
        let segments = self.rows.last().map_or(0, |r| r.segment + 1);
        let end = self.rows.last().map_or(f64::NEG_INFINITY, |r| r.t);
        let start = next.rows.first().map_or(0.0, |r| r.t);
        let shift = if start < end + FILE_GAP_S {
            end + FILE_GAP_S - start
        } else {
            0.0
        };
        for r in &mut next.rows {
            r.t += shift;
            r.segment += segments;
        }
        let s = &mut self.summary;
        let n = &next.summary;
        s.rows += n.rows;
        s.segments += n.segments;
        for g in 0..4 {
            s.held[g] += n.held[g];
            s.nan_setpoints[g] += n.nan_setpoints[g];
        }
        s.stale_rows += n.stale_rows;
        s.dropped_segments += n.dropped_segments;
        s.gaps.extend(n.gaps.iter().map(|(a, b)| (a + shift, b + shift)));
        self.notes.push(format!(
            "{}: segments {segments}…{} (times shifted by {shift} s to follow the previous file)",
            next.source,
            segments + n.segments.max(1) - 1
        ));
        self.notes.extend(next.notes);
        if self.broken.is_none() {
            self.broken = next.broken.map(|b| format!("{}: {b}", next.source));
        }
        self.damaged
            .extend(next.damaged.iter().map(|d| format!("{}: {d}", next.source)));
        self.source = format!("{}, {}", self.source, next.source);
        self.rows.extend(next.rows);
    }

    /// The log as CSV of the contract: metadata comments, the header, rows. Numbers are written
    /// in Rust's shortest round-trip form (reading them back gives the same f64).
    pub fn to_csv(&self) -> String {
        let battery = self.rows.first().is_some_and(|r| r.battery_voltage.is_some());
        let mut out = String::with_capacity(self.rows.len() * 300 + 1024);
        let _ = writeln!(out, "# format: uavgen flight log v1");
        let _ = writeln!(out, "# source: uavgen import {}", env!("CARGO_PKG_VERSION"));
        let _ = writeln!(out, "# imported_from: {} ({})", self.source, self.format.name());
        let _ = writeln!(out, "# profile: {}", self.profile);
        if let Some(hz) = self.options.grid.rate_hz {
            let _ = writeln!(out, "# rate_hz: {hz}");
        }
        if let Some(b) = &self.broken {
            let _ = writeln!(out, "# broken: {b}");
        }
        for d in &self.damaged {
            let _ = writeln!(out, "# damaged: {d}");
        }
        let _ = writeln!(
            out,
            "# stale: bit 0 position, 1 velocity, 2 attitude, 3 rates held (no new sample since the previous row)"
        );
        out.push_str(&header(battery));
        out.push('\n');
        for r in &self.rows {
            let _ = write!(out, "{}", r.t);
            for v in r.x.iter().chain(r.u.iter()) {
                let _ = write!(out, ",{v}");
            }
            if let Some(b) = r.battery_voltage {
                let _ = write!(out, ",{b}");
            }
            let _ = writeln!(out, ",{},{}", r.segment, r.stale);
        }
        out
    }

    /// What the import lost or chose, for stderr: the damaged stretches (with `--partial`), where
    /// the file broke, each contract field's source when a profile offers alternatives.
    pub fn warnings(&self) -> Vec<String> {
        let mut out: Vec<String> = self.damaged.iter().map(|d| format!("{}: {d}", self.source)).collect();
        if let Some(b) = &self.broken {
            out.push(format!("{}: {b}; the rows before it are kept", self.source));
        }
        out
    }

    /// What was imported, for the terminal.
    pub fn report(&self) -> String {
        let s = &self.summary;
        let mut out = format!(
            "{} ({}, profile `{}`): {} rows in {} segment{}",
            self.source,
            self.format.name(),
            self.profile,
            s.rows,
            s.segments,
            if s.segments == 1 { "" } else { "s" }
        );
        match self.options.grid.rate_hz {
            Some(hz) => {
                let _ = write!(out, " at {hz} Hz");
            }
            None => out.push_str(" at the position topic's time stamps"),
        }
        for (what, hz) in &s.topic_rates {
            let _ = write!(out, "\n  {what}: {hz:.2} Hz");
        }
        for (g, name) in GROUPS.iter().enumerate() {
            if s.held[g] > 0 {
                let _ = write!(
                    out,
                    "\n  {name} held (no new sample) on {} of {} rows",
                    s.held[g], s.rows
                );
            }
        }
        if s.stale_rows > 0 {
            let _ = write!(
                out,
                "\n  {} rows repeat the previous row's states exactly (stale rows of the log contract)",
                s.stale_rows
            );
        }
        for (k, name) in crate::logs::INPUT_COLUMNS.iter().enumerate() {
            if s.nan_setpoints[k] > 0 {
                let _ = write!(
                    out,
                    "\n  {name}: {} NaN setpoint samples skipped (previous value held)",
                    s.nan_setpoints[k]
                );
            }
        }
        for (a, b) in &s.gaps {
            let _ = write!(out, "\n  gap t = {a} … {b} s: a new segment after it");
        }
        if s.dropped_segments > 0 {
            let _ = write!(
                out,
                "\n  {} segment(s) of fewer than two rows dropped",
                s.dropped_segments
            );
        }
        if self.broken.is_some() || !self.damaged.is_empty() {
            let _ = write!(
                out,
                "\n  the file is damaged in {} place(s){}: what was lost is on stderr and in the CSV's `# damaged:` / `# broken:` lines",
                self.damaged.len() + usize::from(self.broken.is_some()),
                if self.broken.is_some() { " (and cut off)" } else { "" }
            );
        }
        for n in self.summary.notes.iter().chain(&self.notes) {
            let _ = write!(out, "\n  note: {n}");
        }
        out
    }
}
