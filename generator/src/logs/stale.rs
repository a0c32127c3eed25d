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
        out.apply_stale(policy);
        out
    }

    /// [`Segment::with_stale`] in place: no copy of the rows.
    pub fn apply_stale(&mut self, policy: StalePolicy) {
        if policy == StalePolicy::Interpolate {
            destale_in_place(&self.t, &mut self.x);
        }
    }
}

impl FlightLog {
    /// The log under `policy` (every segment, see [`Segment::with_stale`]); the quality report is
    /// the one of the log as read.
    pub fn with_stale(&self, policy: StalePolicy) -> FlightLog {
        self.clone().into_stale(policy)
    }

    /// [`FlightLog::with_stale`] of an owned log, in place (no copy of its rows).
    pub fn into_stale(mut self, policy: StalePolicy) -> FlightLog {
        for s in &mut self.segments {
            s.apply_stale(policy);
        }
        self
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
        interpolate_run(t, &mut out, i, j);
        i = j;
    }
    out
}

/// [`destale`] of the rows [`stale_flags`] finds, in place: each run of stale rows is found on the
/// rows as logged (the rows after it are not yet touched) and then interpolated between the fresh
/// rows around it, which are never changed — the same values as [`destale`].
pub fn destale_in_place(t: &[f64], x: &mut [[f64; 12]]) {
    let n = x.len();
    let mut i = 1;
    while i < n {
        if x[i] != x[i - 1] {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < n && x[j] == x[j - 1] {
            j += 1;
        }
        interpolate_run(t, x, i, j);
        // Row j ended the run (fresh: compared with row j − 1 as logged); the next run can start
        // at j + 1 at the earliest, compared with row j, which is never changed.
        i = j + 1;
    }
}

/// Rows i..j (stale, i ≥ 1) linearly interpolated in time between rows i − 1 and j (fresh); a run
/// that ends the segment (j = n) keeps its held value.
fn interpolate_run(t: &[f64], x: &mut [[f64; 12]], i: usize, j: usize) {
    if j >= x.len() {
        return;
    }
    let (a, b) = (i - 1, j);
    let (xa, xb) = (x[a], x[b]);
    for k in i..j {
        let w = (t[k] - t[a]) / (t[b] - t[a]);
        for s in 0..12 {
            x[k][s] = xa[s] + w * (xb[s] - xa[s]);
        }
    }
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
        let mut y = x;
        destale_in_place(&t, &mut y);
        assert_eq!(y.to_vec(), d);
    }

    /// In place and by copy give the same rows, bit for bit, on random logs with stale runs
    /// anywhere (the start, the end, runs of one, adjacent runs of different held values).
    #[test]
    fn in_place_equals_the_copy() {
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as f64 / (1u64 << 31) as f64
        };
        for _ in 0..50 {
            let n = 1 + (next() * 40.0) as usize;
            let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01 + 0.003 * next()).collect();
            let mut x = vec![[0.0; 12]; n];
            for k in 0..n {
                x[k] = if k > 0 && next() < 0.5 {
                    x[k - 1]
                } else {
                    std::array::from_fn(|_| next())
                };
            }
            let copy = destale(&t, &x, &stale_flags(&x));
            destale_in_place(&t, &mut x);
            assert_eq!(x, copy);
        }
    }
}
