//! Stale rows: rows whose 12 states repeat the previous row's exactly (sample-and-hold
//! telemetry; the reader's `stale_states`, logs/quality.rs). One policy for every command
//! (identify, evaluate, diagnose; docs/logs.md, [`StalePolicy`]): by default such rows are treated
//! as missing — their states are replaced by linear interpolation in
//! time between the last fresh row before and the next fresh row after, and the derivative targets
//! are recomputed from the interpolated states. A stale run at the end of a segment keeps its held
//! value (nothing after it to interpolate to). The inputs are left as logged.

use super::{FlightLog, Segment};

/// What a command does with stale rows (`--stale`). The same in `identify`, `evaluate` and
/// `diagnose`, so a figure one of them reports is reproduced by the others on the same log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StalePolicy {
    /// Stale rows are missing samples: their states are interpolated (the default).
    #[default]
    Interpolate,
    /// The log as recorded: stale rows keep their held states.
    Keep,
}

impl StalePolicy {
    pub fn name(self) -> &'static str {
        match self {
            StalePolicy::Interpolate => "interpolate",
            StalePolicy::Keep => "keep",
        }
    }
}

impl Segment {
    /// Row flags: true where the row's states repeat the previous row's.
    pub fn stale_flags(&self) -> Vec<bool> {
        stale_flags(&self.x)
    }

    /// The segment under `policy`: with [`StalePolicy::Interpolate`], stale rows' states are
    /// interpolated in time (inputs, time stamps and the battery column unchanged).
    pub fn with_stale(&self, policy: StalePolicy) -> Segment {
        let mut out = self.clone();
        if policy == StalePolicy::Interpolate {
            let flags = self.stale_flags();
            if flags.iter().any(|f| *f) {
                out.x = destale(&self.t, &self.x, &flags);
            }
        }
        out
    }
}

impl FlightLog {
    /// The log under `policy` (every segment, see [`Segment::with_stale`]); the quality report is
    /// the one of the log as read.
    pub fn with_stale(&self, policy: StalePolicy) -> FlightLog {
        FlightLog {
            segments: self.segments.iter().map(|s| s.with_stale(policy)).collect(),
            ..self.clone()
        }
    }
}

/// Row i (i ≥ 1) is stale when its states equal row i − 1's; row 0 never is.
pub fn stale_flags(x: &[[f64; 12]]) -> Vec<bool> {
    let mut out = vec![false; x.len()];
    for i in 1..x.len() {
        out[i] = x[i] == x[i - 1];
    }
    out
}

/// The states with stale rows interpolated (see the module documentation).
pub fn destale(t: &[f64], x: &[[f64; 12]], stale: &[bool]) -> Vec<[f64; 12]> {
    let mut out = x.to_vec();
    let n = x.len();
    let mut i = 0;
    while i < n {
        if !stale[i] {
            i += 1;
            continue;
        }
        // A run i..j of stale rows; row i − 1 is fresh (row 0 is never stale).
        let mut j = i;
        while j < n && stale[j] {
            j += 1;
        }
        if j < n {
            let (a, b) = (i - 1, j);
            for k in i..j {
                let w = (t[k] - t[a]) / (t[b] - t[a]);
                for s in 0..12 {
                    out[k][s] = x[a][s] + w * (x[b][s] - x[a][s]);
                }
            }
        }
        i = j;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_rows_are_interpolated() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let mut x = [[0.0; 12]; 6];
        for (k, v) in [0.0, 1.0, 1.0, 1.0, 4.0, 4.0].iter().enumerate() {
            x[k][6] = *v;
        }
        let st = stale_flags(&x);
        assert_eq!(st, vec![false, false, true, true, false, true]);
        let d = destale(&t, &x, &st);
        let v: Vec<f64> = d.iter().map(|r| r[6]).collect();
        assert_eq!(v, vec![0.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
    }
}
