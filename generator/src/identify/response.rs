//! Delay-aware identification: the pure delay and first-order lag of each input channel,
//! estimated from the logs themselves (`uavgen identify --input-delay auto`, the default;
//! docs/identification.md).
//!
//! **What the model sees.** The logged commands are zero-order-hold: u_m is sent at t_m and held
//! until t_{m+1}. A channel with delay d and lag τ acts through s(t), ṡ = (u(t − d) − s)/τ (s = the
//! delayed command itself without a lag). The model file says this with `corrections.latency`
//! (d) and `corrections.actuator_lag` (τ); `evaluate`, `track` and the generated crate apply them.
//!
//! **What the regression pairs.** The targets are Savitzky-Golay derivatives at the sample
//! instants t_k: a symmetric filter, so the derivative at t_k sees the input averaged over a
//! window centred on t_k, not the input of the interval [t_k, t_{k+1}]. The regressor of channel
//! j at t_k is therefore the average of s over [t_k − Δt/2, t_k + Δt/2], which is the interval
//! average of [`interval_average`] with the delay d + Δt/2 ([`InputResponse::regressors`]). Pairing
//! ẋ_k with u_{k−n} instead (the plain shift) is off by half a sample: it finds d + Δt/2 and says
//! "n samples".
//!
//! **The estimate** ([`estimate`]), per channel j and the row it drives (u_vz → vz, u_roll →
//! roll_rate, u_pitch → pitch_rate, u_yaw_rate → yaw_rate), coordinate-wise over the channels (the
//! others at their current estimate) with a second pass; held-out folds are the logs when there are
//! 3 or more, else 5 contiguous blocks of every segment:
//!
//! 0. A channel that carries no signal ([`ScanOptions::silent`], [`super::excitation`]) is not
//!    scanned: no delay, no lag, and a note.
//! 1. *Delay*: 0 … `max_delay` in steps of `delay_step` seconds. Every candidate refits the row on
//!    the whole physics library (least squares) on all folds but one and scores the one-step squared
//!    error on the held-out fold. The least held-out error wins when its evidence over no delay,
//!    N_eff ln(SSE₀/SSE), is at least `min_evidence` (N_eff: the effective sample count of the
//!    row's residual); ±1σ: the delays with N_eff ln(SSE/SSE_min) ≤ 1. A best delay within one
//!    sample period of `max_delay` (the scan's edge) is refused: the response may lie beyond the
//!    scan, or the error surface has no minimum in it; the channel gets no delay and a note.
//! 2. *Guard*: the channel's loop — the row (with its angle for roll and pitch) as a linear model in
//!    1, the eight invariant states and the four inputs, refitted per fold — runs freely over one
//!    MPC horizon on the held-out folds, the other states from the log. A delay that makes these
//!    free runs more than `lag_gain` worse than no delay is not kept.
//! 3. *Lag*: every τ of `lags`, with the delay shortened by about τ (±1 step); kept only when its
//!    one-step evidence over the delay alone is ≥ `min_evidence` and the loop's held-out free runs
//!    improve by ≥ `lag_gain` (and the delay did not make them worse: the loop model is trusted).

use super::sindy::{eval_term, Library, LibraryKind};
use crate::model::Base;
use crate::model::{DEFAULT_INPUTS, DEFAULT_STATES};
use nalgebra::{DMatrix, DMatrixView, DVector};
use std::borrow::Cow;

/// The input channels (LOG_FORMAT.md order) and the rows they drive.
pub const INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];
/// The state row each channel drives (vz, roll_rate, pitch_rate, yaw_rate).
pub const DRIVEN_ROW: [usize; 4] = [8, 9, 10, 11];
/// State names (log order).
const STATE_NAMES: [&str; 12] = DEFAULT_STATES;
/// The angle integrated from the driven row in the loop free runs (roll, pitch), if any.
const LOOP_ANGLE: [Option<usize>; 4] = [None, Some(3), Some(4), None];
/// States in the loop regressors: vx vy vz roll pitch roll_rate pitch_rate yaw_rate.
const LOOP_STATES: [usize; 8] = [6, 7, 8, 3, 4, 9, 10, 11];
/// 1 + 8 states + 4 inputs.
const NZ: usize = 13;

/// Delay (s) and first-order lag (s, `None`: none) of each input channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InputResponse {
    pub delay: [f64; 4],
    pub lag: [Option<f64>; 4],
}

impl InputResponse {
    pub fn is_identity(&self) -> bool {
        self.delay.iter().all(|d| *d == 0.0) && self.lag.iter().all(Option::is_none)
    }

    /// The regressors of the Savitzky-Golay derivatives at the sample instants (see the module
    /// documentation): per channel the average of what the model sees over [t_k − Δt/2, t_k + Δt/2].
    pub fn regressors(&self, u: &[[f64; 4]], dt: f64) -> Vec<[f64; 4]> {
        self.transform(u, dt, 0.5)
    }

    /// What one sample of integration sees over [t_k, t_{k+1}] (interval averages).
    pub fn interval_inputs(&self, u: &[[f64; 4]], dt: f64) -> Vec<[f64; 4]> {
        self.transform(u, dt, 0.0)
    }

    fn transform(&self, u: &[[f64; 4]], dt: f64, offset: f64) -> Vec<[f64; 4]> {
        let mut out = u.to_vec();
        for j in 0..4 {
            let col: Vec<f64> = u.iter().map(|r| r[j]).collect();
            let seen = interval_average(&col, dt, self.delay[j] + offset * dt, self.lag[j]);
            for (o, v) in out.iter_mut().zip(seen) {
                o[j] = v;
            }
        }
        out
    }

    /// Samples at the start of a segment whose regressors reach before its first sample.
    pub fn warmup(&self, dt: f64) -> usize {
        let d = self.delay.iter().cloned().fold(0.0, f64::max);
        (d / dt + 0.5).ceil() as usize + 1
    }
}

/// The interval average over [t_m, t_{m+1}] of a zero-order-hold input delayed by `delay` and
/// filtered by a first-order lag τ (s_0 = the first delayed value): with d = (n + α)Δt,
/// v_m = (1 − α) u_{m−n} + α u_{m−n−1} (indices clamped at 0); with a lag, s_{m+1} = a s_m +
/// (1 − a) v_m, a = e^{−Δt/τ}, and the average v_m + (s_m − v_m)(τ/Δt)(1 − a). Exact for
/// zero-order-hold inputs.
pub fn interval_average(u: &[f64], dt: f64, delay: f64, lag: Option<f64>) -> Vec<f64> {
    crate::ir::corrections::channel_average(u, dt, delay, lag)
}

/// The scan's grid and rules (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ScanOptions {
    /// Largest delay scanned, s. A best delay within one sample period of it is at the scan's edge:
    /// refused (no delay, a note), since the response may lie beyond the scan.
    pub max_delay: f64,
    /// Delay step, s.
    pub delay_step: f64,
    /// Lag time constants scanned, s.
    pub lags: Vec<f64>,
    /// Folds when there are fewer than 3 logs (contiguous blocks of every segment).
    pub blocks: usize,
    /// Coordinate-wise passes over the channels.
    pub passes: usize,
    /// One free run (the MPC horizon) and the stride between their starts, s (converted to
    /// samples of each segment's period, at least 1).
    pub horizon: f64,
    pub stride: f64,
    /// Evidence N_eff ln(SSE₀/SSE) a channel's response must have over "no delay, no lag".
    pub min_evidence: f64,
    /// Relative improvement of the held-out loop free runs a lag must bring to be kept.
    pub lag_gain: f64,
    /// Channels without excitation ([`super::excitation`]): not scanned, no delay and no lag.
    pub silent: [bool; 4],
    /// Variables (16 states-then-inputs index) whose library terms the scan's regression leaves
    /// out (a still heading's yaw, a silent input).
    pub excluded_vars: Vec<usize>,
}

impl Default for ScanOptions {
    /// Delays 0 … 0.5 s in steps of 1/120 s (a quarter sample at 30 Hz); lags 0.02 … 0.8 s (14
    /// log-spaced values); 5 blocks; 2 passes; free runs of 1 s every 1/15 s; evidence 4 (two
    /// standard errors); a lag must improve the loop's held-out free runs by 2 %; every channel
    /// scanned, the whole library.
    fn default() -> Self {
        let (lo, hi, count) = (0.02f64, 0.8f64, 14);
        let r = (hi / lo).ln() / (count - 1) as f64;
        Self {
            max_delay: 0.5,
            delay_step: 1.0 / 120.0,
            lags: (0..count).map(|i| lo * (r * i as f64).exp()).collect(),
            blocks: 5,
            passes: 2,
            horizon: 1.0,
            stride: 1.0 / 15.0,
            min_evidence: 4.0,
            lag_gain: 0.02,
            silent: [false; 4],
            excluded_vars: Vec::new(),
        }
    }
}

/// One uniformly sampled segment, whole (not trimmed): states, inputs as logged, and the
/// Savitzky-Golay derivatives; `log` is the index of its log, `h` the filter's half window. The
/// series are borrowed from the logs where they can be ([`ScanSegment::interval_of`]): the scan
/// holds no copy of them.
#[derive(Clone, Debug)]
pub struct ScanSegment<'a> {
    pub log: usize,
    pub dt: f64,
    pub h: usize,
    pub x: Cow<'a, [[f64; 12]]>,
    pub u: Cow<'a, [[f64; 4]]>,
    /// The targets. Empty in the integral form of [`ScanSegment::interval_of`]: the interval's
    /// mean slope (x_{k+1} − x_k)/(t_{k+1} − t_k), computed where it is used.
    pub dx: Cow<'a, [[f64; 12]]>,
    /// Integral-form data (`dataset::Targets::Trapezoid`): x_{k+1} per sample, `dx` the interval's
    /// mean slope and `h` 0; the regressors are then the trapezoid means over [t_k, t_{k+1}] with
    /// the inputs the interval sees. Empty: Savitzky-Golay derivatives at the samples.
    pub x_next: Cow<'a, [[f64; 12]]>,
    /// With `dx` empty: the sample times (one more than the samples of `x`).
    pub t: Cow<'a, [f64]>,
}

impl<'a> ScanSegment<'a> {
    /// The integral form of one log segment (times `t`, states `x`, inputs `u`, borrowed): sample k
    /// stands for the interval [t_k, t_{k+1}] — what `dataset::build` makes of it with
    /// `Targets::Trapezoid` and no input response, without copying it. `None` with fewer than two
    /// samples.
    pub fn interval_of(log: usize, dt: f64, t: &'a [f64], x: &'a [[f64; 12]], u: &'a [[f64; 4]]) -> Option<Self> {
        let end = t.len().min(x.len()).min(u.len()).saturating_sub(1);
        if end == 0 {
            return None;
        }
        Some(Self {
            log,
            dt,
            h: 0,
            x: Cow::Borrowed(&x[..end]),
            u: Cow::Borrowed(&u[..end]),
            dx: Cow::Borrowed(&[]),
            x_next: Cow::Borrowed(&x[1..=end]),
            t: Cow::Borrowed(&t[..=end]),
        })
    }

    fn interval(&self) -> bool {
        !self.x_next.is_empty()
    }

    /// The target of state `row` at sample k.
    fn target(&self, k: usize, row: usize) -> f64 {
        if self.dx.is_empty() {
            (self.x_next[k][row] - self.x[k][row]) / (self.t[k + 1] - self.t[k])
        } else {
            self.dx[k][row]
        }
    }

    /// The input regressors of `r` paired with this segment's targets.
    #[cfg(test)]
    fn inputs(&self, r: &InputResponse) -> Vec<[f64; 4]> {
        if self.interval() {
            r.interval_inputs(&self.u, self.dt)
        } else {
            r.regressors(&self.u, self.dt)
        }
    }

    /// [`ScanSegment::inputs`] one sample at a time (the same numbers).
    fn input_stream(&self, r: &InputResponse) -> InputStream<'_> {
        let offset = if self.interval() { 0.0 } else { 0.5 };
        InputStream::new(&self.u, self.dt, r, offset)
    }

    /// The loop regressor of sample k (the trapezoid mean in the integral form; it is linear in x).
    fn loop_regressor(&self, k: usize, u: &[f64; 4]) -> [f64; NZ] {
        if self.interval() {
            let mid: [f64; 12] = core::array::from_fn(|i| 0.5 * (self.x[k][i] + self.x_next[k][i]));
            regressor(&mid, u)
        } else {
            regressor(&self.x[k], u)
        }
    }

    /// A library term at sample k (the trapezoid mean in the integral form).
    fn term(&self, t: &crate::model::Term, k: usize, u: &[f64; 4]) -> f64 {
        let mut v = [0.0; 16];
        v[..12].copy_from_slice(&self.x[k]);
        v[12..].copy_from_slice(u);
        let a = eval_term(t, &v);
        if self.interval() {
            v[..12].copy_from_slice(&self.x_next[k]);
            0.5 * (a + eval_term(t, &v))
        } else {
            a
        }
    }
}

/// What the scan found for one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelEstimate {
    pub input: &'static str,
    /// The row it drives.
    pub row: &'static str,
    pub delay: f64,
    /// Delays within Δχ² = 1 of the best (s).
    pub delay_range: (f64, f64),
    pub lag: Option<f64>,
    /// Lags within Δχ² = 1 of the best (with a lag kept).
    pub lag_range: Option<(f64, f64)>,
    /// The best candidate with a lag, kept or not: (delay, τ).
    pub best_with_lag: Option<(f64, f64)>,
    /// Held-out one-step RMSE of the row: no delay and no lag, and the chosen response.
    pub one_step_rmse: (f64, f64),
    /// Held-out free runs of the loop over one horizon, RMSE of the row: no response, the best
    /// delay without a lag, the best with a lag (when one was scanned).
    pub horizon_rmse: (f64, f64, Option<f64>),
    /// Effective sample count and the evidence N_eff ln(SSE₀/SSE) of the chosen response.
    pub n_eff: f64,
    pub evidence: f64,
    /// Why the lag or the response was not kept, if so.
    pub note: Option<String>,
    /// The channel carried no signal ([`ScanOptions::silent`]): not scanned.
    pub silent: bool,
    /// The best delay, refused because it lay at the scan's edge.
    pub refused_at_edge: Option<f64>,
}

impl ChannelEstimate {
    /// One line for the command's output.
    pub fn line(&self) -> String {
        if self.silent {
            return format!("{:<10} {SILENT_NOTE}", self.input);
        }
        let mut s = format!(
            "{:<10} delay {:.3} s (±1σ {:.3}..{:.3})",
            self.input, self.delay, self.delay_range.0, self.delay_range.1
        );
        match (self.lag, self.lag_range) {
            (Some(t), Some((a, b))) => s += &format!(", lag {t:.3} s ({a:.3}..{b:.3})"),
            _ => s += ", no lag",
        }
        s += &format!(
            "; held-out {} one-step RMSE {:.4} -> {:.4} (evidence {:.0}); loop free runs {:.4} -> {:.4}",
            self.row,
            self.one_step_rmse.0,
            self.one_step_rmse.1,
            self.evidence,
            self.horizon_rmse.0,
            if self.lag.is_some() {
                self.horizon_rmse.2.unwrap_or(self.horizon_rmse.1)
            } else {
                self.horizon_rmse.1
            }
        );
        if let Some(n) = &self.note {
            s += &format!(" [{n}]");
        }
        s
    }
}

/// The scan's result.
#[derive(Clone, Debug, PartialEq)]
pub struct ResponseEstimate {
    pub response: InputResponse,
    pub channels: Vec<ChannelEstimate>,
    /// How the data were split for the held-out scores ("logs" or "blocks") and into how many.
    pub folds: usize,
    pub fold_kind: &'static str,
}

/// Why the scan could not run.
#[derive(Debug, thiserror::Error)]
pub enum ResponseError {
    #[error("too little data for the delay scan: {usable} usable samples (at least {needed} are needed beyond each segment's first {warmup} samples and the filter's edges); pass --input-delay none or a list")]
    TooShort {
        usable: usize,
        needed: usize,
        warmup: usize,
    },
}

struct Folded {
    /// Per segment: the rows used and the fold of each.
    rows: Vec<Vec<(usize, usize)>>,
    folds: usize,
    kind: &'static str,
}

fn fold_rows(segments: &[ScanSegment], options: &ScanOptions) -> (Folded, usize) {
    let logs = segments.iter().map(|s| s.log).max().map_or(0, |m| m + 1);
    let by_log = logs >= 3;
    let folds = if by_log { logs } else { options.blocks.max(2) };
    let mut rows = Vec::new();
    let mut warm = 0;
    for s in segments {
        let w = (options.max_delay / s.dt + 0.5).ceil() as usize + 1;
        warm = warm.max(w);
        let start = s.h.max(w);
        let end = s.x.len().saturating_sub(s.h);
        let mut r = Vec::new();
        if start < end {
            let len = end - start;
            for k in start..end {
                let f = if by_log {
                    s.log
                } else {
                    ((k - start) * folds / len).min(folds - 1)
                };
                r.push((k, f));
            }
        }
        rows.push(r);
    }
    (
        Folded {
            rows,
            folds,
            kind: if by_log { "logs" } else { "blocks" },
        },
        warm,
    )
}

fn regressor(x: &[f64; 12], u: &[f64; 4]) -> [f64; NZ] {
    let mut z = [0.0; NZ];
    z[0] = 1.0;
    for (i, &s) in LOOP_STATES.iter().enumerate() {
        z[1 + i] = x[s];
    }
    z[9..13].copy_from_slice(u);
    z
}

/// Per-fold Gram matrices of [z, y].
struct Grams {
    g: Vec<DMatrix<f64>>,
}

impl Grams {
    fn new(folds: usize) -> Self {
        Self {
            g: vec![DMatrix::zeros(NZ + 1, NZ + 1); folds],
        }
    }

    fn add(&mut self, f: usize, z: &[f64; NZ], y: f64) {
        let g = &mut self.g[f];
        let mut v = [0.0; NZ + 1];
        v[..NZ].copy_from_slice(z);
        v[NZ] = y;
        for a in 0..=NZ {
            for b in a..=NZ {
                g[(a, b)] += v[a] * v[b];
            }
        }
    }

    fn total_except(&self, skip: Option<usize>) -> DMatrix<f64> {
        let mut t = DMatrix::zeros(NZ + 1, NZ + 1);
        for (f, g) in self.g.iter().enumerate() {
            if Some(f) != skip {
                t += g;
            }
        }
        t
    }

    /// Coefficients fitted without fold `skip` (ridge 1e-9 relative, on the upper triangle).
    fn solve(&self, skip: Option<usize>) -> DVector<f64> {
        let t = self.total_except(skip);
        let mut a = DMatrix::zeros(NZ, NZ);
        let mut b = DVector::zeros(NZ);
        for i in 0..NZ {
            for j in 0..NZ {
                a[(i, j)] = if i <= j { t[(i, j)] } else { t[(j, i)] };
            }
            b[i] = t[(i, NZ)];
        }
        let scale = (0..NZ).map(|i| a[(i, i)]).fold(0.0, f64::max).max(1e-300);
        for i in 0..NZ {
            a[(i, i)] += 1e-9 * scale;
        }
        match a.clone().cholesky() {
            Some(c) => c.solve(&b),
            None => a
                .svd(true, true)
                .solve(&b, 1e-12)
                .unwrap_or_else(|_| DVector::zeros(NZ)),
        }
    }
}

/// The per-segment regressor inputs of `response` with channel j replaced by (delay, lag).
fn with_channel(r: &InputResponse, j: usize, delay: f64, lag: Option<f64>) -> InputResponse {
    let mut r = *r;
    r.delay[j] = delay;
    r.lag[j] = lag;
    r
}

struct Scanner<'a> {
    segments: &'a [ScanSegment<'a>],
    folded: Folded,
    options: &'a ScanOptions,
}

impl Scanner<'_> {
    fn usable(&self) -> usize {
        self.folded.rows.iter().map(Vec::len).sum()
    }

    fn grams(&self, r: &InputResponse, row: usize) -> Grams {
        let mut g = Grams::new(self.folded.folds);
        for (s, rows) in self.segments.iter().zip(&self.folded.rows) {
            if rows.is_empty() {
                continue;
            }
            let mut u = s.input_stream(r);
            for &(k, f) in rows {
                g.add(f, &s.loop_regressor(k, &u.at(k)), s.target(k, row));
            }
        }
        g
    }

    /// Held-out free runs of channel j's loop over one horizon: RMSE of its row.
    fn horizon_rmse(&self, r: &InputResponse, j: usize) -> f64 {
        let row = DRIVEN_ROW[j];
        let g = self.grams(r, row);
        let thetas: Vec<DVector<f64>> = (0..self.folded.folds).map(|f| g.solve(Some(f))).collect();
        let (mut sum, mut count) = (0.0, 0usize);
        for (s, rows) in self.segments.iter().zip(&self.folded.rows) {
            let h = samples(self.options.horizon, s.dt);
            let stride = samples(self.options.stride, s.dt);
            if rows.len() <= h {
                continue;
            }
            let u = r.interval_inputs(&s.u, s.dt);
            let last = rows[rows.len() - 1].0;
            for &(k0, f) in rows.iter().step_by(stride) {
                if k0 + h > last {
                    break;
                }
                let theta = &thetas[f];
                let mut x = s.x[k0];
                for i in 0..h {
                    let k = k0 + i;
                    // The loop's states (row, angle) are integrated; the others are the log's.
                    let mut other = s.x[k];
                    let deriv = |rate: f64, angle: f64, other: &mut [f64; 12]| {
                        other[row] = rate;
                        if let Some(a) = LOOP_ANGLE[j] {
                            other[a] = angle;
                        }
                        let z = regressor(other, &u[k]);
                        ((0..NZ).map(|i| z[i] * theta[i]).sum::<f64>(), rate)
                    };
                    let angle0 = LOOP_ANGLE[j].map_or(0.0, |a| x[a]);
                    let (k1r, k1a) = deriv(x[row], angle0, &mut other);
                    let dt = s.dt;
                    let (k2r, k2a) = deriv(x[row] + 0.5 * dt * k1r, angle0 + 0.5 * dt * k1a, &mut other);
                    let (k3r, k3a) = deriv(x[row] + 0.5 * dt * k2r, angle0 + 0.5 * dt * k2a, &mut other);
                    let (k4r, k4a) = deriv(x[row] + dt * k3r, angle0 + dt * k3a, &mut other);
                    x[row] += dt / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r);
                    if let Some(a) = LOOP_ANGLE[j] {
                        x[a] = angle0 + dt / 6.0 * (k1a + 2.0 * k2a + 2.0 * k3a + k4a);
                    }
                    if !x[row].is_finite() {
                        return f64::INFINITY;
                    }
                    let e = x[row] - s.x[k + 1][row];
                    sum += e * e;
                    count += 1;
                }
            }
        }
        if count == 0 {
            f64::NAN
        } else {
            (sum / count as f64).sqrt()
        }
    }
}

/// Held-out squared errors of one row regressed on the SINDy physics library.
struct LibraryScan {
    library: Library,
}

impl LibraryScan {
    fn new(excluded: &[usize]) -> Self {
        let vars: Vec<String> = DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect();
        let mut library = Library::new(LibraryKind::Physics.terms(), &vars).unwrap_or_else(|_| Library {
            names: Vec::new(),
            terms: Vec::new(),
        });
        let keep: Vec<bool> = library
            .terms
            .iter()
            .map(|t| {
                !t.factors.iter().any(|(b, _)| match b {
                    Base::Var(v) | Base::Sin(v) | Base::Cos(v) => excluded.contains(v),
                })
            })
            .collect();
        let mut k = keep.iter();
        library.names.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        library.terms.retain(|_| *k.next().unwrap_or(&true));
        Self { library }
    }

    fn solve(total: &DMatrix<f64>) -> DVector<f64> {
        let p = total.nrows() - 1;
        let a = total.view((0, 0), (p, p));
        let b = total.view((0, p), (p, 1));
        // Jacobi scaling, ridge 1e-9 on the unit diagonal.
        let d: Vec<f64> = (0..p).map(|i| a[(i, i)].max(0.0).sqrt()).collect();
        let mut m = DMatrix::zeros(p, p);
        let mut rhs = DVector::zeros(p);
        for i in 0..p {
            let di = if d[i] > 0.0 { 1.0 / d[i] } else { 0.0 };
            for jj in 0..p {
                let dj = if d[jj] > 0.0 { 1.0 / d[jj] } else { 0.0 };
                m[(i, jj)] = a[(i, jj)] * di * dj;
            }
            m[(i, i)] += if d[i] > 0.0 { 1e-9 } else { 1.0 };
            rhs[i] = b[(i, 0)] * di;
        }
        let x = match m.clone().cholesky() {
            Some(c) => c.solve(&rhs),
            None => m
                .svd(true, true)
                .solve(&rhs, 1e-12)
                .unwrap_or_else(|_| DVector::zeros(p)),
        };
        DVector::from_iterator(p, (0..p).map(|i| if d[i] > 0.0 { x[i] / d[i] } else { 0.0 }))
    }

    /// Σ over folds of the held-out SSE (each fold predicted by the fit on the others).
    fn cv_sse(grams: &[DMatrix<f64>]) -> f64 {
        let mut total = grams[0].clone() * 0.0;
        for g in grams {
            total += g;
        }
        let p = total.nrows() - 1;
        let mut sse = 0.0;
        for g in grams {
            let theta = Self::solve(&(&total - g));
            let a = g.view((0, 0), (p, p));
            let b = g.view((0, p), (p, 1));
            let q = g[(p, p)] - 2.0 * theta.dot(&b.column(0)) + theta.dot(&(a * &theta));
            sse += q.max(0.0);
        }
        sse
    }
}

/// Rows per chunk of the scan's passes: 1024 rows of the 68 columns [Θ, y] are 0.56 MB. A count
/// of samples, not of seconds: it changes nothing but round-off.
const SCAN_CHUNK: usize = 1024;

/// The inputs of a response one sample at a time: what [`InputResponse::transform`] gives for the
/// whole series (per channel the delayed zero-order hold, [`crate::ir::corrections::delayed`], then
/// the lag's interval average, [`crate::ir::corrections::channel_average`]), the same operations
/// in the same order, without the series.
struct InputStream<'a> {
    u: &'a [[f64; 4]],
    /// The next sample.
    k: usize,
    /// Per channel: the whole samples and fraction of the delay (`None`: no delay), the lag's
    /// a = e^{−Δt/τ} and (τ/Δt)(1 − a), and the lag state.
    shift: [Option<(usize, f64)>; 4],
    lag: [Option<(f64, f64)>; 4],
    state: [f64; 4],
    last: [f64; 4],
}

impl<'a> InputStream<'a> {
    fn new(u: &'a [[f64; 4]], dt: f64, r: &InputResponse, offset: f64) -> Self {
        let shift = core::array::from_fn(|j| {
            let delay = r.delay[j] + offset * dt;
            (delay > 0.0).then(|| {
                let samples = delay / dt;
                let n = samples.floor() as usize;
                (n, samples - n as f64)
            })
        });
        let lag = core::array::from_fn(|j| r.lag[j].map(|tau| ((-dt / tau).exp(), -(tau / dt) * (-dt / tau).exp_m1())));
        Self {
            u,
            k: 0,
            shift,
            lag,
            state: [0.0; 4],
            last: [0.0; 4],
        }
    }

    /// The inputs at sample `k` (`k` never decreasing from one call to the next).
    fn at(&mut self, k: usize) -> [f64; 4] {
        while self.k <= k {
            let m = self.k;
            for j in 0..4 {
                let v = match self.shift[j] {
                    None => self.u[m][j],
                    Some((n, alpha)) => {
                        (1.0 - alpha) * self.u[m.saturating_sub(n)][j] + alpha * self.u[m.saturating_sub(n + 1)][j]
                    }
                };
                self.last[j] = match self.lag[j] {
                    None => v,
                    Some((a, gain)) => {
                        if m == 0 {
                            self.state[j] = v;
                        }
                        let s = self.state[j];
                        self.state[j] = a * s + (1.0 - a) * v;
                        v + (s - v) * gain
                    }
                };
            }
            self.k += 1;
        }
        self.last
    }
}

/// The per-fold Gram matrices of [Θ, y] of one driven row for the input response `resp` — the
/// library's rows are streamed chunk by chunk, never held (docs/identification.md, "Memory").
///
/// The scan tries one channel's delays and lags at a time, and only the library terms of that
/// input change with them (for u_roll 11 of the 67 columns). A batch of candidates is scored in
/// one pass over the samples ([`LibraryState::pass`]): per chunk of rows the library at `resp` is
/// evaluated once, and per candidate only the changed columns (a column m(x)·u_j as m, evaluated
/// once per chunk, times the candidate's u_j) and their rows of the Gram matrices against every
/// column. Each column holds the same numbers as the whole library matrix evaluated for the
/// candidate; the Gram matrices differ from that matrix's only by the order of summation.
struct LibraryState {
    /// The target's state index.
    row: usize,
    resp: InputResponse,
    gram: Vec<DMatrix<f64>>,
    /// Per input channel: the library columns whose term uses it.
    uses: [Vec<usize>; 4],
    /// Per library column of the form m(x)·u_j (u_j to the first power, last or with one other
    /// factor, no other input): j. The term is then m·u_j, the same product [`eval_term`] forms.
    simple: Vec<Option<usize>>,
    /// Rows per chunk.
    chunk: usize,
}

/// What a pass gives each chunk: `(candidate, segment, fold, rows of [Θ, y])`.
type Visit<'v> = dyn FnMut(usize, usize, usize, DMatrixView<f64>) + 'v;

/// Residuals' autocorrelation sums c_l = Σ e_i e_{i−l}, l = 0 … 200, within each segment, pooled
/// (what [`effective_count`] sums), one residual at a time.
struct AutoCorr {
    c: Vec<f64>,
    recent: std::collections::VecDeque<f64>,
    segment: Option<usize>,
    n: usize,
}

impl AutoCorr {
    fn new() -> Self {
        Self {
            c: vec![0.0; 201],
            recent: std::collections::VecDeque::with_capacity(201),
            segment: None,
            n: 0,
        }
    }

    fn push(&mut self, segment: usize, e: f64) {
        if self.segment != Some(segment) {
            self.recent.clear();
            self.segment = Some(segment);
        }
        if self.recent.len() == 201 {
            self.recent.pop_back();
        }
        self.recent.push_front(e);
        for (l, past) in self.recent.iter().enumerate() {
            self.c[l] += e * past;
        }
        self.n += 1;
    }

    /// N / (1 + 2 Σ ρ_k) of [`effective_count`].
    fn count(&self) -> f64 {
        n_over_tau(self.n, &self.c)
    }
}

impl LibraryState {
    fn new(lib: &LibraryScan, sc: &Scanner, r: &InputResponse, row: usize) -> Self {
        Self::with_chunk(lib, sc, r, row, SCAN_CHUNK)
    }

    fn with_chunk(lib: &LibraryScan, sc: &Scanner, r: &InputResponse, row: usize, chunk: usize) -> Self {
        let p = lib.library.len() + 1;
        let uses: [Vec<usize>; 4] = core::array::from_fn(|j| {
            lib.library
                .terms
                .iter()
                .enumerate()
                .filter(|(_, t)| {
                    t.factors.iter().any(|&(b, _)| match b {
                        crate::model::Base::Var(v) | crate::model::Base::Sin(v) | crate::model::Base::Cos(v) => {
                            v == 12 + j
                        }
                    })
                })
                .map(|(c, _)| c)
                .collect()
        });
        let simple = (0..lib.library.len())
            .map(|c| {
                let t = &lib.library.terms[c];
                let j = (0..4).find(|j| uses[*j].contains(&c))?;
                let at = t
                    .factors
                    .iter()
                    .position(|&(b, _)| b == crate::model::Base::Var(12 + j))?;
                let simple = t.factors[at].1 == 1
                    && (t.factors.len() <= 2 || at + 1 == t.factors.len())
                    && (0..4).filter(|i| uses[*i].contains(&c)).count() == 1;
                simple.then_some(j)
            })
            .collect();
        let mut state = Self {
            row,
            resp: *r,
            gram: vec![DMatrix::zeros(p, p); sc.folded.folds],
            uses,
            simple,
            chunk: chunk.max(1),
        };
        let all: Vec<usize> = (0..p).collect();
        let blocks = state.blocks(sc, lib, row, &[*r], &all);
        state.gram = blocks.into_iter().next().unwrap_or_default();
        state
    }

    /// The library columns that change from `self.resp` to any of `cands`.
    fn changed_columns(&self, cands: &[InputResponse]) -> Vec<usize> {
        let mut cols: Vec<usize> = (0..4)
            .filter(|&j| {
                cands
                    .iter()
                    .any(|r| r.delay[j] != self.resp.delay[j] || r.lag[j] != self.resp.lag[j])
            })
            .flat_map(|j| self.uses[j].iter().copied())
            .collect();
        cols.sort_unstable();
        cols.dedup();
        cols
    }

    /// One pass over the used rows, chunk by chunk (rows of one segment and one fold): for every
    /// candidate response of `cands`, the rows of [Θ, y] (the target that of state `row`) with the
    /// columns `cols` under the candidate's inputs and the others under `self.resp`'s, given to
    /// `visit(candidate, segment, fold, rows)`.
    fn pass(
        &self,
        sc: &Scanner,
        lib: &LibraryScan,
        row: usize,
        cands: &[InputResponse],
        cols: &[usize],
        visit: &mut Visit,
    ) {
        let p = lib.library.len() + 1;
        let mut z = DMatrix::zeros(self.chunk, p);
        let mut zc = DMatrix::zeros(self.chunk, p);
        let mut mult = vec![[0.0; 2]; self.chunk * cols.len()];
        for (si, (s, rows)) in sc.segments.iter().zip(&sc.folded.rows).enumerate() {
            if rows.is_empty() {
                continue;
            }
            let mut base = s.input_stream(&self.resp);
            let mut streams: Vec<InputStream> = cands.iter().map(|r| s.input_stream(r)).collect();
            let mut at = 0;
            while at < rows.len() {
                let f = rows[at].1;
                let mut len = 1;
                while at + len < rows.len() && len < self.chunk && rows[at + len].1 == f {
                    len += 1;
                }
                let chunk = &rows[at..at + len];
                at += len;
                for (i, &(k, _)) in chunk.iter().enumerate() {
                    let u = base.at(k);
                    for (c, t) in lib.library.terms.iter().enumerate() {
                        z[(i, c)] = s.term(t, k, &u);
                    }
                    z[(i, p - 1)] = s.target(k, row);
                    for (ci, &c) in cols.iter().enumerate() {
                        if let (Some(j), Some(t)) = (self.simple.get(c).copied().flatten(), lib.library.terms.get(c)) {
                            let mut v = [0.0; 16];
                            v[..12].copy_from_slice(&s.x[k]);
                            v[12 + j] = 1.0;
                            let m0 = eval_term(t, &v);
                            let m1 = if s.interval() {
                                v[..12].copy_from_slice(&s.x_next[k]);
                                eval_term(t, &v)
                            } else {
                                0.0
                            };
                            mult[i * cols.len() + ci] = [m0, m1];
                        }
                    }
                }
                for (cand, stream) in streams.iter_mut().enumerate() {
                    zc.rows_mut(0, len).copy_from(&z.rows(0, len));
                    for (i, &(k, _)) in chunk.iter().enumerate() {
                        let u = stream.at(k);
                        for (ci, &c) in cols.iter().enumerate() {
                            if c + 1 == p {
                                continue;
                            }
                            let t = &lib.library.terms[c];
                            zc[(i, c)] = match self.simple[c] {
                                Some(j) => {
                                    let [m0, m1] = mult[i * cols.len() + ci];
                                    let uj = u[j];
                                    if s.interval() {
                                        0.5 * (m0 * uj + m1 * uj)
                                    } else {
                                        m0 * uj
                                    }
                                }
                                None => s.term(t, k, &u),
                            };
                        }
                    }
                    visit(cand, si, f, zc.rows(0, len));
                }
            }
        }
    }

    /// Per candidate, per fold: the rows `cols` of the Gram matrix of [Θ, y] (each against every
    /// column), the columns `cols` under the candidate's inputs (see [`LibraryState::pass`]).
    fn blocks(
        &self,
        sc: &Scanner,
        lib: &LibraryScan,
        row: usize,
        cands: &[InputResponse],
        cols: &[usize],
    ) -> Vec<Vec<DMatrix<f64>>> {
        let p = lib.library.len() + 1;
        let mut out = vec![vec![DMatrix::zeros(cols.len(), p); sc.folded.folds]; cands.len()];
        self.pass(sc, lib, row, cands, cols, &mut |cand, _, f, z| {
            let sel = z.select_columns(cols);
            out[cand][f].gemm_tr(1.0, &sel, &z, 1.0);
        });
        out
    }

    /// The Gram matrices with the rows and columns `cols` replaced by `blocks` (per fold).
    fn replaced(&self, blocks: &[DMatrix<f64>], cols: &[usize]) -> Vec<DMatrix<f64>> {
        self.gram
            .iter()
            .zip(blocks)
            .map(|(g, b)| {
                let mut g = g.clone();
                for (ia, &a) in cols.iter().enumerate() {
                    for c in 0..g.ncols() {
                        g[(a, c)] = b[(ia, c)];
                        g[(c, a)] = b[(ia, c)];
                    }
                }
                g
            })
            .collect()
    }

    /// Make the state that of the target of state `row` and the response `r` (one pass over the
    /// columns that change).
    fn move_to(&mut self, sc: &Scanner, lib: &LibraryScan, row: usize, r: &InputResponse) {
        let mut cols = self.changed_columns(&[*r]);
        if row != self.row {
            cols.push(lib.library.len());
        }
        if cols.is_empty() {
            return;
        }
        let blocks = self.blocks(sc, lib, row, &[*r], &cols);
        self.gram = self.replaced(&blocks[0], &cols);
        self.row = row;
        self.resp = *r;
    }

    /// Every candidate's per-fold Gram matrices, one pass for all (candidates that differ from
    /// the state's response in the same channels: the scan's batches).
    fn candidate_grams(&self, sc: &Scanner, lib: &LibraryScan, cands: &[InputResponse]) -> Vec<Vec<DMatrix<f64>>> {
        let cols = self.changed_columns(cands);
        self.blocks(sc, lib, self.row, cands, &cols)
            .iter()
            .map(|b| self.replaced(b, &cols))
            .collect()
    }

    /// The held-out SSE of every candidate ([`LibraryScan::cv_sse`]).
    fn scores(&self, sc: &Scanner, lib: &LibraryScan, cands: &[InputResponse]) -> Vec<f64> {
        let cols = self.changed_columns(cands);
        self.blocks(sc, lib, self.row, cands, &cols)
            .iter()
            .map(|b| LibraryScan::cv_sse(&self.replaced(b, &cols)))
            .collect()
    }

    /// The all-data residuals' effective sample count under the response `r`.
    fn n_eff(&self, sc: &Scanner, lib: &LibraryScan, r: &InputResponse) -> f64 {
        let grams = self.candidate_grams(sc, lib, &[*r]).remove(0);
        let mut total = grams[0].clone() * 0.0;
        for g in &grams {
            total += g;
        }
        let theta = LibraryScan::solve(&total);
        let terms = theta.len();
        let cols = self.changed_columns(&[*r]);
        let mut acf = AutoCorr::new();
        self.pass(sc, lib, self.row, &[*r], &cols, &mut |_, si, _, z| {
            for i in 0..z.nrows() {
                let fit: f64 = (0..terms).map(|c| theta[c] * z[(i, c)]).sum();
                acf.push(si, z[(i, terms)] - fit);
            }
        });
        acf.count()
    }
}

/// N / (1 + 2 Σ ρ_k), ρ summed while positive up to lag 200, pooled over segments.
#[cfg(test)]
fn effective_count(residuals: &[Vec<f64>]) -> f64 {
    let n: usize = residuals.iter().map(Vec::len).sum();
    let mut c = vec![0.0; 201];
    for e in residuals {
        for (l, acc) in c.iter_mut().enumerate() {
            for i in l..e.len() {
                *acc += e[i] * e[i - l];
            }
        }
    }
    n_over_tau(n, &c)
}

/// N / (1 + 2 Σ ρ_k) of the autocorrelation sums `c` (ρ_k = c_k / c_0, summed while positive).
fn n_over_tau(n: usize, c: &[f64]) -> f64 {
    if n == 0 || c[0] <= 0.0 {
        return n as f64;
    }
    let mut tau = 1.0;
    for &v in &c[1..] {
        let rho = v / c[0];
        if rho <= 0.0 {
            break;
        }
        tau += 2.0 * rho;
    }
    n as f64 / tau
}

/// Seconds as a count of samples of period `dt` (rounded, at least 1).
pub fn samples(seconds: f64, dt: f64) -> usize {
    if dt > 0.0 && seconds.is_finite() {
        ((seconds / dt).round() as usize).max(1)
    } else {
        1
    }
}

/// Is `d` within one sample period of the scan's top `max_delay` (the edge)?
pub fn at_edge(d: f64, max_delay: f64, dt: f64) -> bool {
    d > 0.0 && d >= max_delay - dt + 1e-9
}

/// The note of a silent channel.
pub const SILENT_NOTE: &str = "no excitation: the channel carries no signal, no delay estimated";

fn silent_channel(j: usize) -> ChannelEstimate {
    ChannelEstimate {
        input: INPUTS[j],
        row: STATE_NAMES[DRIVEN_ROW[j]],
        delay: 0.0,
        delay_range: (0.0, 0.0),
        lag: None,
        lag_range: None,
        best_with_lag: None,
        one_step_rmse: (f64::NAN, f64::NAN),
        horizon_rmse: (f64::NAN, f64::NAN, None),
        n_eff: 0.0,
        evidence: 0.0,
        note: Some(SILENT_NOTE.into()),
        silent: true,
        refused_at_edge: None,
    }
}

/// Estimate every channel's delay and lag (see the module documentation).
pub fn estimate(segments: &[ScanSegment], options: &ScanOptions) -> Result<ResponseEstimate, ResponseError> {
    let (folded, warmup) = fold_rows(segments, options);
    let sc = Scanner {
        segments,
        folded,
        options,
    };
    let lib = LibraryScan::new(&options.excluded_vars);
    let needed = 4 * (lib.library.len() + 1);
    if sc.usable() < needed || lib.library.is_empty() {
        return Err(ResponseError::TooShort {
            usable: sc.usable(),
            needed,
            warmup,
        });
    }
    let dt = {
        let mut d: Vec<f64> = segments.iter().map(|s| s.dt).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let step = options.delay_step.max(1e-6);
    let steps = (options.max_delay / step).round() as usize;
    let delays: Vec<f64> = (0..=steps).map(|i| i as f64 * step).collect();
    let n_rows = sc.usable() as f64;

    let mut cur = InputResponse::default();
    let mut channels: Vec<Option<ChannelEstimate>> = vec![None; 4];
    let mut state = LibraryState::new(&lib, &sc, &cur, DRIVEN_ROW[0]);
    for _pass in 0..options.passes.max(1) {
        for j in 0..4 {
            let row = DRIVEN_ROW[j];
            if options.silent[j] {
                channels[j] = Some(silent_channel(j));
                continue;
            }
            state.move_to(&sc, &lib, row, &cur);
            // Candidates are scored in batches, one pass over the samples each.
            let scores = |cands: &[(f64, Option<f64>)]| -> Vec<f64> {
                let r: Vec<InputResponse> = cands.iter().map(|&(d, l)| with_channel(&cur, j, d, l)).collect();
                state.scores(&sc, &lib, &r)
            };
            // Delays without a lag.
            let no_lag: Vec<(f64, Option<f64>)> = delays.iter().map(|&d| (d, None)).collect();
            let curve: Vec<(f64, f64)> = delays.iter().copied().zip(scores(&no_lag)).collect();
            let sse0 = curve[0].1;
            let (d_best, sse_best) = curve
                .iter()
                .copied()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((0.0, sse0));
            let n_eff = state.n_eff(&sc, &lib, &with_channel(&cur, j, d_best, None));
            let evidence = n_eff * (sse0 / sse_best).ln();
            let mut note = None;
            let mut refused = None;
            let (mut delay, mut sse_chosen) = (d_best, sse_best);
            if evidence < options.min_evidence {
                note = Some(format!(
                    "no delay supported: evidence {evidence:.1} < {:.1}",
                    options.min_evidence
                ));
                delay = 0.0;
                sse_chosen = sse0;
            } else if at_edge(d_best, options.max_delay, dt) {
                note = Some(format!(
                    "delay {d_best:.3} s at the edge of the 0..{:.3} s scan: refused, no delay",
                    options.max_delay
                ));
                refused = Some(d_best);
                delay = 0.0;
                sse_chosen = sse0;
            }
            let within: Vec<f64> = curve
                .iter()
                .filter(|c| n_eff * (c.1 / sse_chosen).ln() <= 1.0)
                .map(|c| c.0)
                .collect();
            let mut delay_range = (
                within.iter().cloned().fold(delay, f64::min),
                within.iter().cloned().fold(delay, f64::max),
            );
            // A lag: its response time τ is taken from the delay (d' ≈ d − τ, ±1 step).
            let mut lag_cands: Vec<(f64, Option<f64>)> = Vec::new();
            for &tau in &options.lags {
                let centre = ((delay - tau) / step).round();
                for k in [centre - 1.0, centre, centre + 1.0] {
                    if k < 0.0 {
                        continue;
                    }
                    lag_cands.push((k * step, Some(tau)));
                }
            }
            let mut lag_best: Option<(f64, f64, f64)> = None;
            for (&(d, tau), v) in lag_cands.iter().zip(scores(&lag_cands)) {
                let tau = tau.unwrap_or(0.0);
                if lag_best.map_or(true, |b| v < b.2) {
                    lag_best = Some((d, tau, v));
                }
            }
            let h_none = sc.horizon_rmse(&with_channel(&cur, j, 0.0, None), j);
            let mut h_delay = sc.horizon_rmse(&with_channel(&cur, j, delay, None), j);
            // Guard: a delay that makes the loop's held-out free runs worse is not kept.
            if delay > 0.0 && h_delay > (1.0 + options.lag_gain) * h_none {
                note = Some(format!(
                    "delay {delay:.3} s left out: loop free runs {h_delay:.4} against {h_none:.4} without it"
                ));
                delay = 0.0;
                sse_chosen = sse0;
                h_delay = h_none;
                delay_range = (0.0, 0.0);
            }
            let mut lag = None;
            let mut lag_range = None;
            let mut h_lag = None;
            if let Some((d, tau, v)) = lag_best {
                let ev = n_eff * (sse_chosen / v).ln();
                let h = sc.horizon_rmse(&with_channel(&cur, j, d, Some(tau)), j);
                h_lag = Some(h);
                // Kept only when the one-step evidence is there and the loop's held-out free runs
                // improve (the loop model is trusted for this only where the delay improved them).
                let trusted = delay == 0.0 || h_delay <= h_none;
                if ev >= options.min_evidence && trusted && h < (1.0 - options.lag_gain) * h_delay {
                    lag = Some(tau);
                    delay = d;
                    sse_chosen = v;
                    // The lags near the best and the delays near its delay, in one batch.
                    let ds: Vec<f64> = (-3..=3).map(|k| d + k as f64 * step).filter(|&x| x >= 0.0).collect();
                    let batch: Vec<(f64, Option<f64>)> = options
                        .lags
                        .iter()
                        .map(|&t| (d, Some(t)))
                        .chain(ds.iter().map(|&x| (x, Some(tau))))
                        .collect();
                    let sse = scores(&batch);
                    let (sse_lags, sse_ds) = sse.split_at(options.lags.len());
                    let near: Vec<f64> = options
                        .lags
                        .iter()
                        .zip(sse_lags)
                        .filter(|(_, &e)| n_eff * (e / v).ln() <= 1.0)
                        .map(|(&t, _)| t)
                        .collect();
                    lag_range = Some((
                        near.iter().cloned().fold(tau, f64::min),
                        near.iter().cloned().fold(tau, f64::max),
                    ));
                    let ds: Vec<f64> = ds
                        .iter()
                        .zip(sse_ds)
                        .filter(|(_, &e)| n_eff * (e / v).ln() <= 1.0)
                        .map(|(&x, _)| x)
                        .collect();
                    delay_range = (
                        ds.iter().cloned().fold(d, f64::min),
                        ds.iter().cloned().fold(d, f64::max),
                    );
                } else if note.is_none() {
                    note = Some(format!(
                        "lag {tau:.3} s (delay {d:.3} s) left out: one-step evidence {ev:.1}, loop free runs {h:.4} against {h_delay:.4}"
                    ));
                }
            }
            cur.delay[j] = delay;
            cur.lag[j] = lag;
            channels[j] = Some(ChannelEstimate {
                input: INPUTS[j],
                row: STATE_NAMES[row],
                delay,
                delay_range,
                lag,
                lag_range,
                best_with_lag: lag_best.map(|b| (b.0, b.1)),
                one_step_rmse: ((sse0 / n_rows).sqrt(), (sse_chosen / n_rows).sqrt()),
                horizon_rmse: (h_none, h_delay, h_lag),
                n_eff,
                evidence: n_eff * (sse0 / sse_chosen).ln(),
                note,
                silent: false,
                refused_at_edge: refused,
            });
        }
    }
    Ok(ResponseEstimate {
        response: cur,
        channels: channels.into_iter().flatten().collect(),
        folds: sc.folded.folds,
        fold_kind: sc.folded.kind,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interval_average_of_a_step() {
        let u = [0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        assert_eq!(interval_average(&u, 0.1, 0.0, None), u.to_vec());
        assert_eq!(interval_average(&u, 0.1, 0.1, None), vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let d = interval_average(&u, 0.1, 0.125, None);
        assert!((d[3] - 0.75).abs() < 1e-12 && d[2] == 0.0 && d[4] == 1.0);
        // A lag: the average over the first interval after the step is 1 − (τ/Δt)(1 − e^{−Δt/τ}).
        let l = interval_average(&u, 0.1, 0.0, Some(0.1));
        let k = 1.0 - (1.0 - (-1.0f64).exp());
        assert!((l[2] - k).abs() < 1e-12, "{l:?}");
        assert!(l[3] > l[2] && l[5] < 1.0);
    }

    #[test]
    fn regressors_are_centred_on_the_sample_instants() {
        // No delay, no lag: the derivative at t_k sees half of u_{k−1} and half of u_k.
        let u: Vec<[f64; 4]> = (0..4).map(|k| [k as f64; 4]).collect();
        let r = InputResponse::default().regressors(&u, 0.1);
        assert_eq!(r[2], [1.5; 4]);
        assert_eq!(InputResponse::default().interval_inputs(&u, 0.1), u);
    }

    /// A vehicle of first- and second-order loops, simulated finely with zero-order-hold commands
    /// delayed by `delay` per channel, logged at 30 Hz, differentiated like the dataset does.
    fn synthetic(delay: [f64; 4], seconds: f64, seed: u64) -> ScanSegment<'static> {
        use crate::identify::preprocess::{columnwise, SavGol};
        use rand::{Rng, SeedableRng};
        let dt = 1.0 / 30.0;
        let n = (seconds / dt) as usize;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        // Random steps held 0.2–1 s.
        let mut u = vec![[0.0; 4]; n];
        let mut hold = [0usize; 4];
        let mut cur = [0.0; 4];
        let bounds = [2.0, 0.3, 0.3, 1.0];
        for row in u.iter_mut() {
            for j in 0..4 {
                if hold[j] == 0 {
                    cur[j] = rng.gen_range(-bounds[j]..=bounds[j]);
                    hold[j] = rng.gen_range(6..30);
                }
                hold[j] -= 1;
                row[j] = cur[j];
            }
        }
        let sub = 40;
        let h = dt / sub as f64;
        let mut x = [0.0f64; 12];
        let mut xs = Vec::with_capacity(n);
        for k in 0..n {
            xs.push(x);
            for i in 0..sub {
                let t = k as f64 * dt + (i as f64 + 0.5) * h;
                let uu: [f64; 4] = std::array::from_fn(|j| {
                    let m = ((t - delay[j]) / dt).floor();
                    if m < 0.0 {
                        0.0
                    } else {
                        u[m as usize][j]
                    }
                });
                let mut d = [0.0; 12];
                d[8] = -3.0 * (x[8] - uu[0]);
                d[9] = -100.0 * (x[3] - uu[1]) - 16.0 * x[9];
                d[10] = -100.0 * (x[4] - uu[2]) - 16.0 * x[10];
                d[11] = -4.0 * (x[11] - uu[3]);
                d[..6].copy_from_slice(&x[6..12]);
                d[6] = 9.81 * x[4];
                d[7] = -9.81 * x[3];
                for s in 0..12 {
                    x[s] += h * d[s];
                }
            }
        }
        let sg = SavGol::new(9, 3).unwrap();
        let dx = columnwise(&xs, |y| sg.derivative(y, dt));
        ScanSegment {
            log: 0,
            dt,
            h: 4,
            x: xs.into(),
            u: u.into(),
            dx: dx.into(),
            x_next: Vec::new().into(),
            t: Vec::new().into(),
        }
    }

    /// The same segment in the integral form (what `identify` scans by default).
    fn interval_form(s: ScanSegment<'static>) -> ScanSegment<'static> {
        let n = s.x.len() - 1;
        let dx: Vec<[f64; 12]> = (0..n)
            .map(|k| std::array::from_fn(|i| (s.x[k + 1][i] - s.x[k][i]) / s.dt))
            .collect();
        ScanSegment {
            h: 0,
            x_next: s.x[1..].to_vec().into(),
            x: s.x[..n].to_vec().into(),
            u: s.u[..n].to_vec().into(),
            dx: dx.into(),
            ..s
        }
    }

    #[test]
    fn the_integral_form_finds_every_channels_delay_within_a_quarter_sample() {
        let dt = 1.0 / 30.0;
        let truth = [0.13, 0.076, 0.09, 0.17];
        let est = estimate(&[interval_form(synthetic(truth, 90.0, 5))], &ScanOptions::default()).unwrap();
        for (c, d) in est.channels.iter().zip(truth) {
            assert!(
                (c.delay + c.lag.unwrap_or(0.0) - d).abs() <= 0.25 * dt + 1e-9,
                "{} (truth {d})",
                c.line()
            );
        }
    }

    #[test]
    fn a_known_delay_on_one_channel_is_found_within_a_quarter_sample() {
        let dt = 1.0 / 30.0;
        let truth = [0.1, 0.0, 0.0, 0.0];
        let est = estimate(&[synthetic(truth, 60.0, 7)], &ScanOptions::default()).unwrap();
        let c = &est.channels;
        assert_eq!(c.len(), 4);
        assert!(
            (c[0].delay + c[0].lag.unwrap_or(0.0) - 0.1).abs() <= 0.25 * dt + 1e-9,
            "{}",
            c[0].line()
        );
        assert!(c[0].delay_range.0 <= c[0].delay && c[0].delay <= c[0].delay_range.1);
        for ch in &c[1..] {
            assert!(ch.delay <= 0.25 * dt + 1e-9, "{}", ch.line());
        }
        // Delaying a second channel moves that one only.
        let est = estimate(&[synthetic([0.1, 0.0, 0.0, 0.2], 60.0, 8)], &ScanOptions::default()).unwrap();
        let y = &est.channels[3];
        assert!(
            (y.delay + y.lag.unwrap_or(0.0) - 0.2).abs() <= 0.25 * dt + 1e-9,
            "{}",
            y.line()
        );
        assert!(est.channels[1].delay <= 0.25 * dt + 1e-9, "{}", est.channels[1].line());
    }

    /// A delay beyond the scan puts the best candidate at its edge: refused (no delay, a note);
    /// a silent channel is not scanned at all.
    #[test]
    fn an_estimate_at_the_scans_edge_is_refused_and_a_silent_channel_is_not_scanned() {
        let dt = 1.0 / 30.0;
        let options = ScanOptions {
            max_delay: 0.2,
            silent: [false, false, false, true],
            ..ScanOptions::default()
        };
        let est = estimate(&[synthetic([0.3, 0.0, 0.0, 0.15], 60.0, 7)], &options).unwrap();
        let c = &est.channels[0];
        assert!(c.refused_at_edge.is_some_and(|d| d >= 0.2 - dt), "{}", c.line());
        assert!(c.delay < dt, "{}", c.line());
        assert!(c.note.as_deref().unwrap_or("").contains("edge"), "{}", c.line());
        let y = &est.channels[3];
        assert!(y.silent && y.delay == 0.0 && y.lag.is_none(), "{}", y.line());
        assert_eq!(est.response.delay[3], 0.0);
        assert!(y.line().contains("no excitation"));
        assert_eq!(samples(1.0, 0.01), 100);
        assert_eq!(samples(1.0 / 15.0, 1.0 / 30.0), 2);
        assert_eq!(samples(0.0, 0.01), 1);
    }

    /// The per-fold Gram matrices of [Θ, y] built directly: the whole library matrix of each fold
    /// (its rows in segment order) for the response `r`, then ZᵀZ.
    fn direct_grams(sc: &Scanner, lib: &LibraryScan, r: &InputResponse, row: usize) -> Vec<DMatrix<f64>> {
        let p = lib.library.len() + 1;
        let mut rows: Vec<Vec<Vec<f64>>> = vec![Vec::new(); sc.folded.folds];
        for (s, used) in sc.segments.iter().zip(&sc.folded.rows) {
            let u = s.inputs(r);
            for &(k, f) in used {
                let mut z: Vec<f64> = lib.library.terms.iter().map(|t| s.term(t, k, &u[k])).collect();
                z.push(s.target(k, row));
                rows[f].push(z);
            }
        }
        rows.iter()
            .map(|rs| {
                let z = DMatrix::from_fn(rs.len(), p, |i, c| rs[i][c]);
                z.tr_mul(&z)
            })
            .collect()
    }

    fn assert_grams_near(a: &[DMatrix<f64>], b: &[DMatrix<f64>], what: &str) {
        for (x, y) in a.iter().zip(b) {
            for i in 0..x.nrows() {
                for j in 0..x.ncols() {
                    let scale = (y[(i, i)] * y[(j, j)]).sqrt().max(y[(i, j)].abs()).max(1e-300);
                    assert!(
                        (x[(i, j)] - y[(i, j)]).abs() <= 1e-12 * scale,
                        "{what} ({i},{j}): {} against {}",
                        x[(i, j)],
                        y[(i, j)]
                    );
                }
            }
        }
    }

    /// The scan's streamed Gram matrices (chunks of 1, 7 and more rows than the data; the state
    /// moved channel by channel, candidates in batches) are the ones of the whole library matrix
    /// built directly, to round-off; derivative and integral form, with delays and lags.
    #[test]
    fn streamed_library_grams_are_the_direct_ones() {
        for seg in [
            synthetic([0.1, 0.05, 0.0, 0.2], 8.0, 3),
            interval_form(synthetic([0.1, 0.05, 0.0, 0.2], 8.0, 4)),
        ] {
            let n = seg.x.len();
            let segments = [seg];
            let options = ScanOptions::default();
            let (folded, _) = fold_rows(&segments, &options);
            let sc = Scanner {
                segments: &segments,
                folded,
                options: &options,
            };
            let lib = LibraryScan::new(&[]);
            for chunk in [1, 7, n + 1] {
                let mut state = LibraryState::with_chunk(&lib, &sc, &InputResponse::default(), 9, chunk);
                assert_grams_near(
                    &state.gram,
                    &direct_grams(&sc, &lib, &InputResponse::default(), 9),
                    "initial",
                );
                let steps = [
                    (1, 0.05, None),
                    (1, 0.0625, Some(0.04)),
                    (3, 0.2, None),
                    (0, 0.1, Some(0.1)),
                ];
                let mut r = InputResponse::default();
                for (j, d, l) in steps {
                    // A batch of candidates of channel j, then the state moved to the first.
                    let cands: Vec<InputResponse> = [(d, l), (d + 0.02, None), (0.0, Some(0.3))]
                        .iter()
                        .map(|&(d, l)| with_channel(&r, j, d, l))
                        .collect();
                    let grams = state.candidate_grams(&sc, &lib, &cands);
                    for (c, g) in cands.iter().zip(&grams) {
                        assert_grams_near(g, &direct_grams(&sc, &lib, c, state.row), "candidate");
                    }
                    r = cands[0];
                    for row in [9, 8] {
                        state.move_to(&sc, &lib, row, &r);
                        assert_grams_near(&state.gram, &direct_grams(&sc, &lib, &r, row), "moved");
                    }
                }
            }
        }
    }

    /// The inputs one sample at a time are the whole-series transform's, bit for bit; the
    /// streamed autocorrelation sums give [`effective_count`]'s count, bit for bit.
    #[test]
    fn streamed_inputs_and_autocorrelation_are_the_whole_series_ones() {
        let seg = synthetic([0.0; 4], 4.0, 9);
        for r in [
            InputResponse::default(),
            InputResponse {
                delay: [0.1, 0.0, 0.05, 0.21],
                lag: [None, Some(0.07), Some(0.3), None],
            },
        ] {
            for offset in [0.0, 0.5] {
                let whole = r.transform(&seg.u, seg.dt, offset);
                let mut stream = InputStream::new(&seg.u, seg.dt, &r, offset);
                for (k, w) in whole.iter().enumerate().skip(3) {
                    let got = stream.at(k);
                    assert!(got.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()), "{k}");
                }
            }
        }
        let e: Vec<Vec<f64>> = vec![
            (0..500)
                .map(|i| ((i as f64) * 0.1).sin() + 0.01 * (i % 7) as f64)
                .collect(),
            (0..50).map(|i| ((i as f64) * 0.3).cos()).collect(),
        ];
        let mut acf = AutoCorr::new();
        for (s, series) in e.iter().enumerate() {
            for &v in series {
                acf.push(s, v);
            }
        }
        assert_eq!(acf.count().to_bits(), effective_count(&e).to_bits());
    }

    #[test]
    fn too_little_data_is_an_error_not_a_panic() {
        let seg = synthetic([0.0; 4], 2.0, 1);
        let e = estimate(&[seg], &ScanOptions::default()).unwrap_err();
        assert!(e.to_string().contains("too little data"), "{e}");
    }
}
