//! Anti-aliased decimation of logs sampled far faster than identification needs
//! (docs/logs.md#resampling).
//!
//! `identify` fits continuous-time dynamics whose bandwidth is a few Hz (attitude loops of
//! 2-5 Hz, motor lags of tens of ms) and sets everything else in seconds (the Savitzky-Golay
//! window of 0.3 s, delays of 0 … 0.5 s, lags of 0.02 … 0.8 s); its cost grows with the number of
//! samples. A log at 1 kHz carries ten times the samples of the same flight at 100 Hz and
//! nothing the fit uses, so [`resample`] decimates it: each segment by the largest whole factor
//! q with q·Δt ≤ the target period (Δt its median step; q ≥ 2, else the segment is kept), after
//! a zero-phase low-pass at the new Nyquist frequency, the same filter on every column (states,
//! inputs, battery voltage), so a linear relation between them (ẋ = Ax + Bu) holds in the
//! filtered series as in the logged one and no delay is added. The result keeps the log's
//! time stamps (every q-th one), its metadata (plus a `resampled` line) and its quality report
//! (the report of the log as read, as [`FlightLog::with_stale`] keeps it).
//!
//! The filter: a Hamming-windowed sinc with cutoff 1/(2qΔt) (the new Nyquist frequency) and
//! 8q + 1 taps (± 4 output periods), normalised to unit gain at 0 Hz; at a segment's ends the
//! taps that fall outside it are dropped and the rest renormalised. Its gain is within 0.5 % of
//! 1 up to 0.6 × the new Nyquist frequency and below 0.5 % from 1.4 × it (a test measures both
//! within 1 %), so what folds back lands in the top of the new band, above the dynamics
//! identified.
//! The target is given in seconds: decimating the same flight logged at 500 Hz or at 1 kHz to
//! 10 ms gives the same series to within the filter's ripple (a test).

use super::{FlightLog, Segment};

/// `identify`'s default target: logs faster than 2 × this rate (100 Hz, a 10 ms period) are
/// decimated to between 100 and 200 Hz. Ten or more samples per period of a 10 Hz mode, a
/// Savitzky-Golay window of 31+ samples, delays resolved to 10 ms or better; the rate of the
/// fastest plant shipped (`plants/nano.json`).
pub const DEFAULT_MAX_RATE_HZ: f64 = 100.0;

/// What [`resample`] did to a log: printed on stderr and recorded in the model's provenance.
#[derive(Clone, Debug, PartialEq)]
pub struct ResampleNote {
    /// The log (as [`FlightLog::source`]).
    pub source: String,
    /// Rows before and after, over all segments.
    pub rows_before: usize,
    pub rows_after: usize,
    /// The median step of the log before and after (s).
    pub period_before: f64,
    pub period_after: f64,
    /// The decimation factor of each segment (1: kept as logged).
    pub factors: Vec<usize>,
    /// The target period asked for (s).
    pub target_period: f64,
}

impl std::fmt::Display for ResampleNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "note: {}: logged at {:.1} Hz, far faster than identification needs: resampled to {:.1} Hz \
             (anti-aliased decimation ×{}, {} → {} rows; target period {} s; docs/logs.md#resampling)",
            self.source,
            1.0 / self.period_before,
            1.0 / self.period_after,
            factors_text(&self.factors),
            self.rows_before,
            self.rows_after,
            self.target_period
        )
    }
}

impl ResampleNote {
    /// For a model's provenance.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "log": self.source,
            "rows_before": self.rows_before,
            "rows_after": self.rows_after,
            "period_before_s": self.period_before,
            "period_after_s": self.period_after,
            "factors": self.factors,
            "target_period_s": self.target_period,
            "filter": "zero-phase Hamming-windowed sinc, cutoff at the new Nyquist frequency, 8q+1 taps",
        })
    }
}

fn factors_text(factors: &[usize]) -> String {
    let mut unique: Vec<usize> = factors.to_vec();
    unique.sort_unstable();
    unique.dedup();
    unique.iter().map(|q| q.to_string()).collect::<Vec<_>>().join("/")
}

/// The decimation factor for a step `dt` and a target `period`: the largest whole q with
/// q·dt ≤ period (1 if dt or period is not a positive finite number).
pub fn factor(dt: f64, period: f64) -> usize {
    if !(dt.is_finite() && dt > 0.0 && period.is_finite() && period > 0.0) {
        return 1;
    }
    // A relative tolerance so that 1 ms into 10 ms is 10, not 9 by rounding.
    let q = (period / dt * (1.0 + 1e-9)).floor();
    if q >= 1.0 && q < usize::MAX as f64 {
        q as usize
    } else {
        1
    }
}

/// The filter's taps for factor q: 8q + 1 weights, symmetric, summing to 1.
fn taps(q: usize) -> Vec<f64> {
    let half = 4 * q;
    let fc = 0.5 / q as f64; // cycles per input sample
    let mut w: Vec<f64> = (0..=2 * half)
        .map(|i| {
            let k = i as f64 - half as f64;
            let sinc = if k == 0.0 {
                2.0 * fc
            } else {
                (2.0 * std::f64::consts::PI * fc * k).sin() / (std::f64::consts::PI * k)
            };
            let hamming = 0.54 + 0.46 * (std::f64::consts::PI * k / half as f64).cos();
            sinc * hamming
        })
        .collect();
    let sum: f64 = w.iter().sum();
    for v in &mut w {
        *v /= sum;
    }
    w
}

/// The filtered value of `col` at sample `i` (the taps centred there; renormalised at the ends).
fn filtered<F: Fn(usize) -> f64>(col: F, n: usize, i: usize, w: &[f64]) -> f64 {
    let half = w.len() / 2;
    let lo = i.saturating_sub(half);
    let hi = (i + half).min(n - 1);
    let (mut acc, mut sum) = (0.0, 0.0);
    for j in lo..=hi {
        let wj = w[j + half - i];
        acc += wj * col(j);
        sum += wj;
    }
    acc / sum
}

/// One segment decimated by `q` (`q` ≥ 2).
fn decimate(seg: &Segment, q: usize) -> Segment {
    let n = seg.len();
    let w = taps(q);
    let picks: Vec<usize> = (0..n).step_by(q).collect();
    let x = picks
        .iter()
        .map(|&i| std::array::from_fn(|c| filtered(|j| seg.x[j][c], n, i, &w)))
        .collect();
    let u = picks
        .iter()
        .map(|&i| std::array::from_fn(|c| filtered(|j| seg.u[j][c], n, i, &w)))
        .collect();
    let battery_voltage = seg
        .battery_voltage
        .as_ref()
        .filter(|b| b.len() == n)
        .map(|b| picks.iter().map(|&i| filtered(|j| b[j], n, i, &w)).collect());
    Segment {
        index: seg.index,
        t: picks.iter().map(|&i| seg.t[i]).collect(),
        x,
        u,
        battery_voltage,
        first_line: seg.first_line,
    }
}

fn median_step(segments: &[Segment]) -> Option<f64> {
    let steps: Vec<f64> = segments
        .iter()
        .flat_map(|s| s.t.windows(2).map(|w| w[1] - w[0]))
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    super::median(&steps)
}

/// The log decimated so that no segment is sampled faster than one sample per `period` seconds
/// needs, with what was done; `None` (nothing to do) when no segment is at least twice as fast
/// as `1 / period`. See the module documentation.
pub fn resample(log: &FlightLog, period: f64) -> Option<(FlightLog, ResampleNote)> {
    let factors: Vec<usize> = log
        .segments
        .iter()
        .map(|s| median_step(std::slice::from_ref(s)).map_or(1, |dt| factor(dt, period)))
        .collect();
    if factors.iter().all(|&q| q < 2) {
        return None;
    }
    let segments: Vec<Segment> = log
        .segments
        .iter()
        .zip(&factors)
        .map(|(s, &q)| if q >= 2 { decimate(s, q) } else { s.clone() })
        .collect();
    let note = ResampleNote {
        source: log.source.clone(),
        rows_before: log.rows(),
        rows_after: segments.iter().map(Segment::len).sum(),
        period_before: median_step(&log.segments).unwrap_or(f64::NAN),
        period_after: median_step(&segments).unwrap_or(f64::NAN),
        factors,
        target_period: period,
    };
    let mut metadata = log.metadata.clone();
    metadata.push((
        "resampled".to_owned(),
        format!(
            "from {:.1} Hz to {:.1} Hz (anti-aliased decimation ×{}, uavgen)",
            1.0 / note.period_before,
            1.0 / note.period_after,
            factors_text(&note.factors)
        ),
    ));
    let resampled = FlightLog {
        source: log.source.clone(),
        metadata,
        segments,
        report: log.report.clone(),
    };
    Some((resampled, note))
}

/// What `identify` does with a log it has read: the log under the stale-row policy (stale rows
/// are found on the samples as logged, so before any filtering), then [`resample`]d to
/// `max_rate_hz` ([`DEFAULT_MAX_RATE_HZ`] by default) if it is at least twice that fast.
/// The log is taken by value: the stale rows are interpolated in place, and a resampled log
/// replaces it (no second copy of the rows is held).
pub fn for_identification(
    log: FlightLog,
    stale: super::StalePolicy,
    max_rate_hz: f64,
) -> (FlightLog, Option<ResampleNote>) {
    let log = log.into_stale(stale);
    match resample(&log, 1.0 / max_rate_hz) {
        Some((resampled, note)) => (resampled, Some(note)),
        None => (log, None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::logs::parse_log;
    use std::f64::consts::PI;

    /// A one-segment log at `hz` for `seconds`, every column a function of time.
    fn log_at(hz: f64, seconds: f64, f: impl Fn(f64) -> f64) -> FlightLog {
        let header = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate";
        let mut csv = format!("# rate_hz: {hz}\n{header}\n");
        let n = (seconds * hz).round() as usize;
        for k in 0..n {
            let t = k as f64 / hz;
            let v = f(t);
            let row: Vec<String> = std::iter::once(format!("{t}"))
                .chain((0..16).map(|c| format!("{:e}", if c == 2 { 5.0 + v } else { v })))
                .collect();
            csv.push_str(&row.join(","));
            csv.push('\n');
        }
        parse_log(&csv, "test.csv").unwrap()
    }

    /// The gain of the decimation on a sine of `f` Hz: the amplitude of a least-squares fit of
    /// a·sin + b·cos at `f` to the output's middle half (the input's amplitude is 1).
    fn gain(hz: f64, period: f64, f: f64) -> f64 {
        let log = log_at(hz, 6.0, |t| (2.0 * PI * f * t).sin());
        let (out, _) = resample(&log, period).unwrap();
        let s = &out.segments[0];
        let n = s.len();
        let (mut ss, mut sc, mut cc, mut ys, mut yc) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for k in n / 4..3 * n / 4 {
            let (sn, cs) = (2.0 * PI * f * s.t[k]).sin_cos();
            let y = s.x[k][0];
            ss += sn * sn;
            sc += sn * cs;
            cc += cs * cs;
            ys += y * sn;
            yc += y * cs;
        }
        let det = ss * cc - sc * sc;
        let a = (ys * cc - yc * sc) / det;
        let b = (yc * ss - ys * sc) / det;
        a.hypot(b)
    }

    #[test]
    fn factors_are_whole_and_rate_independent() {
        assert_eq!(factor(0.001, 0.01), 10);
        assert_eq!(factor(0.002, 0.01), 5);
        assert_eq!(factor(0.004, 0.01), 2);
        assert_eq!(factor(0.006, 0.01), 1);
        assert_eq!(factor(1.0 / 30.0, 0.01), 1);
        assert_eq!(factor(0.0, 0.01), 1);
        assert_eq!(factor(f64::NAN, 0.01), 1);
    }

    #[test]
    fn taps_are_symmetric_with_unit_gain() {
        for q in [2, 3, 10] {
            let w = taps(q);
            assert_eq!(w.len(), 8 * q + 1);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            for i in 0..w.len() {
                assert_eq!(w[i], w[w.len() - 1 - i]);
            }
        }
    }

    #[test]
    fn slow_logs_are_kept() {
        let log = log_at(100.0, 2.0, |t| t);
        assert!(resample(&log, 0.01).is_none());
        let (same, note) = for_identification(log.clone(), crate::logs::StalePolicy::Keep, DEFAULT_MAX_RATE_HZ);
        assert!(note.is_none());
        assert_eq!(same, log);
    }

    #[test]
    fn a_fast_log_is_decimated_with_its_time_stamps_and_a_note() {
        let log = log_at(1000.0, 2.0, |t| 0.3 * t);
        let (out, note) = resample(&log, 0.01).unwrap();
        assert_eq!(note.factors, vec![10]);
        assert_eq!(note.rows_before, 2000);
        assert_eq!(note.rows_after, 200);
        assert!((note.period_after - 0.01).abs() < 1e-12);
        let s = &out.segments[0];
        for (k, t) in s.t.iter().enumerate() {
            assert_eq!(*t, log.segments[0].t[10 * k]);
        }
        // A ramp is kept exactly away from the ends (symmetric taps of unit sum).
        for k in 5..195 {
            assert!((s.x[k][0] - 0.3 * s.t[k]).abs() < 1e-12, "{k}");
        }
        assert_eq!(
            out.meta("resampled"),
            Some("from 1000.0 Hz to 100.0 Hz (anti-aliased decimation ×10, uavgen)")
        );
        assert!(note.to_string().contains("resampled to 100.0 Hz"));
    }

    #[test]
    fn the_band_identify_uses_passes_and_what_would_alias_is_stopped() {
        // Decimating 1 kHz to 100 Hz (Nyquist 50 Hz).
        for f in [1.0, 5.0, 20.0, 30.0] {
            let g = gain(1000.0, 0.01, f);
            assert!((g - 1.0).abs() < 0.01, "{f} Hz: gain {g}");
        }
        for f in [70.0, 90.0, 130.0, 240.0] {
            let g = gain(1000.0, 0.01, f);
            assert!(g < 0.01, "{f} Hz: gain {g}");
        }
    }

    #[test]
    fn the_result_does_not_depend_on_the_logged_rate() {
        let signal = |t: f64| (2.0 * PI * 1.3 * t).sin() + 0.2 * (2.0 * PI * 7.0 * t).cos();
        let (a, _) = resample(&log_at(1000.0, 4.0, signal), 0.01).unwrap();
        let (b, _) = resample(&log_at(500.0, 4.0, signal), 0.01).unwrap();
        let (a, b) = (&a.segments[0], &b.segments[0]);
        assert_eq!(a.len(), b.len());
        for k in 8..a.len() - 8 {
            assert_eq!(a.t[k], b.t[k]);
            assert!(
                (a.x[k][0] - b.x[k][0]).abs() < 2e-3,
                "{k}: {} vs {}",
                a.x[k][0],
                b.x[k][0]
            );
            assert!((a.x[k][0] - signal(a.t[k])).abs() < 1e-2, "{k}");
        }
    }
}
