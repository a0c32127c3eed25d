//! The data-quality report: sampling, stale (sample-and-hold) rows, yaw unwrapping.

use super::segments::{median, SegmentStart};
use super::Segment;
use std::fmt;

/// A time step that differs from the segment's median period by more than this fraction is irregular.
pub const IRREGULAR_FRACTION: f64 = 0.10;

/// In a log of more rows than this, a metadata rate under which more than 90 % of the steps are
/// gaps is not used to find gaps (the time column's median step is): a wrong `# rate_hz` would
/// otherwise split the log into single rows. (Shorter logs keep the metadata.)
pub const RATE_TRUSTED_ROWS: usize = 20;

/// A measured rate that differs from the metadata `rate_hz` by more than this fraction is reported.
pub const RATE_MISMATCH_FRACTION: f64 = 0.01;

/// Segments listed one per line by `Display`; the rest are summarised.
const DISPLAY_SEGMENTS: usize = 8;

/// Quality figures of one segment.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentQuality {
    /// Index in [`FlightLog::segments`](super::FlightLog::segments).
    pub index: usize,
    /// Lines of the first and last data row (1-based, as in an editor).
    pub first_line: usize,
    pub last_line: usize,
    pub rows: usize,
    pub t_start: f64,
    pub t_end: f64,
    /// Why the segment starts here.
    pub start: SegmentStart,
    /// The value of the `segment` column, if the log has one.
    pub segment_value: Option<i64>,
    /// The file's nominal period (see [`QualityReport::nominal_period`]), repeated here.
    pub nominal_period: Option<f64>,
    /// The median time step of this segment (`None` for a single row).
    pub median_period: Option<f64>,
    /// max |Δt − median| / median over the segment's steps (0 for fewer than two steps).
    pub max_period_deviation: f64,
    /// Steps with |Δt − median| / median > [`IRREGULAR_FRACTION`].
    pub irregular_intervals: usize,
    /// Rows whose 12 state values all equal the previous row's (sample-and-hold of the state).
    pub stale_states: usize,
    /// The longest run of consecutive stale-state rows (a value held for `run + 1` samples).
    pub longest_stale_run: usize,
    /// Rows whose state and input values all equal the previous row's.
    pub stale_rows: usize,
    /// The 2π jumps removed from yaw (0: yaw left as read).
    pub yaw_wraps: usize,
}

impl SegmentQuality {
    /// Stale-state rows as a fraction of the segment's rows.
    pub fn stale_fraction(&self) -> f64 {
        fraction(self.stale_states, self.rows)
    }
}

/// The data-quality report of a log.
#[derive(Clone, Debug, PartialEq)]
pub struct QualityReport {
    pub source: String,
    pub rows: usize,
    /// The metadata `rate_hz`, if given.
    pub metadata_rate_hz: Option<f64>,
    /// The median time step over the file (steps within a `segment` column value).
    pub measured_period: Option<f64>,
    /// The period used to detect gaps: 1 / `rate_hz` if given, else [`measured_period`](Self::measured_period).
    pub nominal_period: Option<f64>,
    pub segments: Vec<SegmentQuality>,
}

impl QualityReport {
    /// measured rate / metadata rate − 1 (e.g. +0.111 for a "30 Hz" log sampled every 0.03 s).
    pub fn rate_mismatch(&self) -> Option<f64> {
        match (self.metadata_rate_hz, self.measured_period) {
            (Some(hz), Some(p)) if p > 0.0 => Some(1.0 / (p * hz) - 1.0),
            _ => None,
        }
    }

    /// Stale-state rows over all segments.
    pub fn stale_states(&self) -> usize {
        self.segments.iter().map(|s| s.stale_states).sum()
    }

    /// Stale-state rows as a fraction of all rows.
    pub fn stale_fraction(&self) -> f64 {
        fraction(self.stale_states(), self.rows)
    }

    /// Rows whose state and input both repeat, over all segments.
    pub fn stale_rows(&self) -> usize {
        self.segments.iter().map(|s| s.stale_rows).sum()
    }

    /// The longest stale-state run over all segments.
    pub fn longest_stale_run(&self) -> usize {
        self.segments.iter().map(|s| s.longest_stale_run).max().unwrap_or(0)
    }

    /// Irregular steps over all segments.
    pub fn irregular_intervals(&self) -> usize {
        self.segments.iter().map(|s| s.irregular_intervals).sum()
    }

    /// The largest [`SegmentQuality::max_period_deviation`].
    pub fn max_period_deviation(&self) -> f64 {
        self.segments.iter().map(|s| s.max_period_deviation).fold(0.0, f64::max)
    }

    /// Indices of the segments whose yaw was unwrapped.
    pub fn unwrapped_segments(&self) -> Vec<usize> {
        self.segments
            .iter()
            .filter(|s| s.yaw_wraps > 0)
            .map(|s| s.index)
            .collect()
    }

    /// The problems worth a look, one sentence each (empty if none): a metadata rate that the time
    /// column contradicts, stale rows, irregular steps, time gaps, single-row segments.
    pub fn warnings(&self) -> Vec<String> {
        self.problems(true)
    }

    fn problems(&self, with_stale: bool) -> Vec<String> {
        let mut w = Vec::new();
        if let (Some(m), Some(hz), Some(p)) = (self.rate_mismatch(), self.metadata_rate_hz, self.measured_period) {
            if m.abs() > RATE_MISMATCH_FRACTION {
                w.push(format!(
                    "the metadata says rate_hz {hz} but the time column is sampled every {} ({} Hz, {:+.1} %){}",
                    secs(p),
                    hz_of(p),
                    100.0 * m,
                    if self.nominal_period == self.measured_period {
                        "; gaps and segments are found from the time column"
                    } else {
                        ""
                    }
                ));
            }
        }
        if with_stale && self.stale_states() > 0 {
            w.push(format!(
                "{} of {} rows ({:.1} %) repeat the previous row's state (longest run {})",
                self.stale_states(),
                self.rows,
                100.0 * self.stale_fraction(),
                self.longest_stale_run()
            ));
        }
        if self.irregular_intervals() > 0 {
            w.push(format!(
                "{} time steps differ from their segment's median period by more than {:.0} % (max {:.1} %)",
                self.irregular_intervals(),
                100.0 * IRREGULAR_FRACTION,
                100.0 * self.max_period_deviation()
            ));
        }
        let gaps: Vec<f64> = self
            .segments
            .iter()
            .filter_map(|s| match s.start {
                SegmentStart::Gap { gap } => Some(gap),
                _ => None,
            })
            .collect();
        if !gaps.is_empty() {
            w.push(format!(
                "{} time gap{} of more than {} nominal periods split segments (largest {})",
                gaps.len(),
                if gaps.len() == 1 { "" } else { "s" },
                super::GAP_PERIODS,
                secs(gaps.iter().copied().fold(0.0, f64::max))
            ));
        }
        let short = self.segments.iter().filter(|s| s.rows < 2).count();
        match short {
            0 => {}
            1 => w.push("1 segment has a single row".to_owned()),
            _ => w.push(format!("{short} segments have a single row")),
        }
        w
    }
}

fn fraction(n: usize, of: usize) -> f64 {
    if of == 0 {
        0.0
    } else {
        n as f64 / of as f64
    }
}

fn secs(p: f64) -> String {
    format!("{} s", trim_float(p, 6))
}

fn hz_of(p: f64) -> String {
    trim_float(1.0 / p, 2)
}

/// `v` with `digits` decimals, trailing zeros removed.
fn trim_float(v: f64, digits: usize) -> String {
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// Compute the figures of one segment; `yaw_wraps` is filled in by the caller.
pub(super) fn segment_quality(
    seg: &Segment,
    last_line: usize,
    start: SegmentStart,
    segment_value: Option<i64>,
    nominal_period: Option<f64>,
) -> SegmentQuality {
    let steps: Vec<f64> = seg.t.windows(2).map(|w| w[1] - w[0]).collect();
    let median_period = median(&steps);
    let (mut max_dev, mut irregular) = (0.0f64, 0);
    if let Some(m) = median_period.filter(|m| *m > 0.0) {
        for dt in &steps {
            let dev = (dt - m).abs() / m;
            max_dev = max_dev.max(dev);
            if dev > IRREGULAR_FRACTION {
                irregular += 1;
            }
        }
    }
    let (mut stale_states, mut stale_rows, mut run, mut longest) = (0, 0, 0, 0);
    for i in 1..seg.x.len().min(seg.u.len()) {
        if seg.x[i] == seg.x[i - 1] {
            stale_states += 1;
            run += 1;
            longest = longest.max(run);
            if seg.u[i] == seg.u[i - 1] {
                stale_rows += 1;
            }
        } else {
            run = 0;
        }
    }
    SegmentQuality {
        index: seg.index,
        first_line: seg.first_line,
        last_line,
        rows: seg.t.len(),
        t_start: seg.t.first().copied().unwrap_or(0.0),
        t_end: seg.t.last().copied().unwrap_or(0.0),
        start,
        segment_value,
        nominal_period,
        median_period,
        max_period_deviation: max_dev,
        irregular_intervals: irregular,
        stale_states,
        longest_stale_run: longest,
        stale_rows,
        yaw_wraps: 0,
    }
}

impl fmt::Display for SegmentStart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SegmentStart::First => write!(f, "start of file"),
            SegmentStart::Column { previous, value } => write!(f, "segment {previous} → {value}"),
            SegmentStart::Gap { gap } => write!(f, "time gap {}", secs(*gap)),
        }
    }
}

impl fmt::Display for SegmentQuality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "segment {} (lines {}–{}, {}): {} rows, t {}..{} s",
            self.index,
            self.first_line,
            self.last_line,
            self.start,
            self.rows,
            trim_float(self.t_start, 4),
            trim_float(self.t_end, 4)
        )?;
        if let Some(p) = self.median_period {
            write!(
                f,
                ", period {} (max deviation {:.1} %, {} irregular)",
                secs(p),
                100.0 * self.max_period_deviation,
                self.irregular_intervals
            )?;
        }
        write!(
            f,
            ", {} stale ({:.1} %, longest run {})",
            self.stale_states,
            100.0 * self.stale_fraction(),
            self.longest_stale_run
        )?;
        if self.yaw_wraps > 0 {
            let s = if self.yaw_wraps == 1 { "" } else { "s" };
            write!(f, ", yaw unwrapped ({} jump{s})", self.yaw_wraps)?;
        }
        Ok(())
    }
}

/// A short human summary: totals, sampling, stale samples, unwrapped segments, then one line
/// per segment (the first few if there are many).
impl fmt::Display for QualityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.segments.len();
        write!(
            f,
            "{}: {} rows in {} segment{}",
            self.source,
            self.rows,
            n,
            if n == 1 { "" } else { "s" }
        )?;
        match (self.measured_period, self.metadata_rate_hz) {
            (Some(p), Some(hz)) => write!(
                f,
                "; sampled every {} ({} Hz), metadata rate_hz {hz}",
                secs(p),
                hz_of(p)
            )?,
            (Some(p), None) => write!(
                f,
                "; sampled every {} ({} Hz), no rate_hz in the metadata",
                secs(p),
                hz_of(p)
            )?,
            (None, _) => write!(f, "; no time steps")?,
        }
        writeln!(f)?;
        write!(
            f,
            "  stale: {} of {} rows ({:.1} %) repeat the previous state (longest run {}); {} repeat state and input",
            self.stale_states(),
            self.rows,
            100.0 * self.stale_fraction(),
            self.longest_stale_run(),
            self.stale_rows()
        )?;
        let unwrapped = self.unwrapped_segments();
        writeln!(f)?;
        if unwrapped.is_empty() {
            write!(f, "  yaw: no 2π jumps")?;
        } else {
            let list: Vec<String> = unwrapped.iter().map(|i| i.to_string()).collect();
            write!(
                f,
                "  yaw: unwrapped in segment{} {}",
                if unwrapped.len() == 1 { "" } else { "s" },
                list.join(", ")
            )?;
        }
        for w in self.problems(false) {
            write!(f, "\n  warning: {w}")?;
        }
        for s in self.segments.iter().take(DISPLAY_SEGMENTS) {
            write!(f, "\n  {s}")?;
        }
        if n > DISPLAY_SEGMENTS {
            write!(f, "\n  … and {} more segments", n - DISPLAY_SEGMENTS)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(t: &[f64], states: &[f64], inputs: &[f64]) -> Segment {
        Segment {
            index: 0,
            t: t.to_vec(),
            x: states.iter().map(|&s| [s; 12]).collect(),
            u: inputs.iter().map(|&v| [v; 4]).collect(),
            battery_voltage: None,
            first_line: 2,
        }
    }

    #[test]
    fn stale_counts_by_hand() {
        // States a a a b b c a: rows 2, 3 and 5 repeat (runs of 2 and 1); the input changes at
        // row 3 only, so rows 2 and 5 repeat both.
        let s = seg(
            &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            &[1.0, 1.0, 1.0, 2.0, 2.0, 3.0, 1.0],
            &[0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 5.0],
        );
        let q = segment_quality(&s, 8, SegmentStart::First, None, Some(0.1));
        assert_eq!(q.stale_states, 3);
        assert_eq!(q.longest_stale_run, 2);
        assert_eq!(q.stale_rows, 2);
        assert_eq!(q.rows, 7);
        assert!((q.stale_fraction() - 3.0 / 7.0).abs() < 1e-15);
    }

    #[test]
    fn irregular_steps_by_hand() {
        // Steps 0.1, 0.1, 0.1, 0.12, 0.05: median 0.1, deviations 0, 0, 0, 0.2, 0.5.
        let s = seg(&[0.0, 0.1, 0.2, 0.3, 0.42, 0.47], &[0.0; 6], &[0.0; 6]);
        let q = segment_quality(&s, 7, SegmentStart::First, None, None);
        assert!((q.median_period.unwrap() - 0.1).abs() < 1e-12);
        assert!((q.max_period_deviation - 0.5).abs() < 1e-9);
        assert_eq!(q.irregular_intervals, 2);
        let one = segment_quality(&seg(&[1.0], &[0.0], &[0.0]), 2, SegmentStart::First, None, None);
        assert_eq!(
            (one.median_period, one.irregular_intervals, one.stale_states),
            (None, 0, 0)
        );
    }

    #[test]
    fn floats_are_trimmed() {
        assert_eq!(trim_float(0.030000000001, 6), "0.03");
        assert_eq!(trim_float(30.0, 2), "30");
        assert_eq!(trim_float(1.0 / 30.0, 6), "0.033333");
    }
}
