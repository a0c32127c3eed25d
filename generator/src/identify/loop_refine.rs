//! Simulation-error refinement of the loops the commands drive (`uavgen identify
//! --refine-loops auto`, the default for SINDy; docs/identification.md "Loop refinement").
//!
//! **Why.** SINDy's rows are fitted by equation error: the one-interval slope of each state
//! against the library. For the rate rows of a real aircraft's attitude loops the slope target is
//! the difference of two noisy gyro samples (30 Hz, a third of the rows stale and interpolated),
//! and the regressors carry the same noise. The least-squares row is then biased towards a slow,
//! under-damped loop with a low gain: on the M100 runs 1–5 the roll row is ω_n 3.5 rad/s, ζ 0.36,
//! gain 0.82 (R² 0.29), while the roll angle itself, simulated from the logged commands, is
//! followed best by ω_n ≈ 7, ζ ≈ 0.7, gain 1.0 (held-out run 7: roll RMSE 0.047 against 0.014 rad).
//! An MPC predicts with the model over a whole horizon, so what matters is the free run, not the
//! one-interval slope.
//!
//! **What is refined.** Each loop is the row a command drives and the state the loop is judged
//! by ([`LOOPS`]): u_roll → roll_rate judged by roll, u_pitch → pitch_rate by pitch (the angle
//! integrates the rate: the kinematic row), u_vz → vz and u_yaw_rate → yaw_rate by themselves.
//! The row keeps the terms the sparse fit selected; only their coefficients θ move, to
//!
//! ```text
//!   min_θ  Σ_windows Σ_{k=1..H} (y_sim,k(θ) − y_log,k)²
//! ```
//!
//! where every window starts at a logged sample, runs the loop's own states freely for H samples
//! (one MPC horizon) with RK4 on the interval inputs the data set pairs with each interval (the
//! identified delays and lags included) and every other state linearly interpolated from the log.
//! Levenberg–Marquardt from the sparse fit's coefficients, with the exact Jacobian of the runs
//! (forward sensitivities carried through the RK4 steps: the rate is linear in θ).
//!
//! **When it is kept.** Cross-validated, like the input response: with 3 or more logs each log is
//! held out in turn (else 5 contiguous blocks of every segment), the row is refined on the rest
//! and scored on the held-out windows. The refinement is kept only when the held-out sum of
//! squares falls by at least [`RefineOptions::min_gain`] against the sparse fit's coefficients
//! (which have seen the held-out data: the comparison favours them). Kept, the row is refined once
//! more on all windows. On clean simulated data the equation error is unbiased and the rows rarely
//! move; on the M100 logs the attitude rows do.

use super::dataset::{Dataset, SegmentData};
use crate::model::{parse_term, Base, Coefficient, Term, DEFAULT_INPUTS, DEFAULT_STATES};
use nalgebra::{DMatrix, DVector};

/// One loop: the row a command drives and the state its free runs are judged by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Loop {
    /// The driven row (state index).
    pub row: usize,
    /// The judged state: the angle integrating the row (roll, pitch), or the row itself.
    pub output: usize,
}

impl Loop {
    pub fn row_name(&self) -> &'static str {
        DEFAULT_STATES[self.row]
    }
    pub fn output_name(&self) -> &'static str {
        DEFAULT_STATES[self.output]
    }
    fn has_angle(&self) -> bool {
        self.output != self.row
    }
}

/// u_vz → vz, u_roll → roll_rate (roll), u_pitch → pitch_rate (pitch), u_yaw_rate → yaw_rate.
pub const LOOPS: [Loop; 4] = [
    Loop { row: 8, output: 8 },
    Loop { row: 9, output: 3 },
    Loop { row: 10, output: 4 },
    Loop { row: 11, output: 11 },
];

/// The refinement's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineOptions {
    /// Samples of one free run (the MPC horizon).
    pub horizon: usize,
    /// Samples between window starts (at least; see `max_windows`).
    pub stride: usize,
    /// Windows at most: on long logs the stride grows so that there are no more, spread evenly
    /// over every segment (free runs of one horizon that start 3 samples apart are nearly the
    /// same run; the stage estimates a handful of coefficients per loop, and its cost is the
    /// windows' runs: bounded whatever the log's length). 2000 windows of the default stride
    /// 0.1 s are 200 s of run starts.
    pub max_windows: usize,
    /// Levenberg–Marquardt iterations at most.
    pub max_iter: usize,
    /// Relative fall of the held-out sum of squares a refinement must bring to be kept.
    pub min_gain: f64,
    /// Folds when there are fewer than 3 logs (contiguous blocks of every segment).
    pub blocks: usize,
}

/// One free run of the refinement, s (the MPC horizon).
pub const HORIZON_S: f64 = 1.0;
/// Time between window starts, s.
pub const STRIDE_S: f64 = 0.1;

impl RefineOptions {
    /// The default options for logs sampled every `dt` s: free runs of [`HORIZON_S`] every
    /// [`STRIDE_S`] in samples of `dt` (30 and 3 at 30 Hz, 100 and 10 at 100 Hz).
    pub fn for_period(dt: f64) -> Self {
        Self {
            horizon: super::response::samples(HORIZON_S, dt),
            stride: super::response::samples(STRIDE_S, dt),
            ..Self::default()
        }
    }
}

impl Default for RefineOptions {
    /// One 30-sample horizon every 3rd sample (at most 2000 windows), 40 iterations, kept at a 5 %
    /// held-out gain, 5 blocks: [`RefineOptions::for_period`] at 30 Hz.
    fn default() -> Self {
        Self {
            horizon: 30,
            stride: 3,
            max_windows: 2000,
            max_iter: 40,
            min_gain: 0.05,
            blocks: 5,
        }
    }
}

/// What the refinement did to one loop.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopRefinement {
    pub row: &'static str,
    pub output: &'static str,
    /// (term, sparse fit's coefficient, refined coefficient); the refined equals the sparse fit's
    /// when the refinement was not kept.
    pub terms: Vec<(String, f64, f64)>,
    /// Held-out free-run RMSE of `output`: the sparse fit's coefficients, the refined ones.
    pub held_out_rmse: (f64, f64),
    /// Windows scored (all folds).
    pub windows: usize,
    pub kept: bool,
    /// Why it was not kept or not tried.
    pub note: Option<String>,
}

/// `provenance.loop_refinement`: the options and, per loop, its verdict, held-out RMSE and the
/// fitted coefficients it started from under `fitted_as` (`sparse_fit` for SINDy,
/// `equation_error_fit` for PD).
pub fn record(options: &RefineOptions, loops: &[LoopRefinement], fitted_as: &str) -> serde_json::Value {
    let loops: serde_json::Map<String, serde_json::Value> = loops
        .iter()
        .map(|r| {
            let fitted: serde_json::Map<_, _> = r
                .terms
                .iter()
                .map(|(t, a, _)| (t.clone(), serde_json::json!(a)))
                .collect();
            let mut entry = serde_json::json!({
                "judged_by": r.output,
                "held_out_free_run_rmse": [r.held_out_rmse.0, r.held_out_rmse.1],
                "kept": r.kept,
            });
            entry[fitted_as] = fitted.into();
            entry["note"] = serde_json::json!(r.note);
            (r.row.to_string(), entry)
        })
        .collect();
    serde_json::json!({
        "horizon": options.horizon,
        "stride": options.stride,
        "horizon_s": HORIZON_S,
        "stride_s": STRIDE_S,
        "max_windows": options.max_windows,
        "min_gain": options.min_gain,
        "loops": loops,
    })
}

impl LoopRefinement {
    /// One line for the command's output.
    pub fn line(&self) -> String {
        let verdict = if self.kept {
            "refined".to_string()
        } else {
            format!("kept as fitted ({})", self.note.as_deref().unwrap_or("no gain"))
        };
        let coefficients: Vec<String> = self
            .terms
            .iter()
            .map(|(t, a, b)| {
                if self.kept {
                    format!("{t} {a:.4} -> {b:.4}")
                } else {
                    format!("{t} {a:.4}")
                }
            })
            .collect();
        format!(
            "{:<10} judged by {:<10} held-out free-run RMSE {:.4} -> {:.4} over {} windows: {verdict}; {}",
            self.row,
            self.output,
            self.held_out_rmse.0,
            self.held_out_rmse.1,
            self.windows,
            coefficients.join(", ")
        )
    }
}

/// One window: segment and first sample.
#[derive(Clone, Copy, Debug)]
struct Window {
    seg: usize,
    start: usize,
}

/// The loop's row as parsed terms and their coefficients, and the values of the terms that do
/// not involve the loop's own states at every sample the windows cover (see [`Row::new`]).
struct Row {
    lp: Loop,
    /// The row's terms in the refinement's order: first the `columns` that involve no loop state
    /// (tabulated), then those that do (evaluated along each free run), each group in the row's
    /// order; θ vectors of the methods below are in this order ([`Row::original`]).
    terms: Vec<Term>,
    theta0: Vec<f64>,
    /// The row's index of each term of `terms`.
    order: Vec<usize>,
    /// Whether a free term also reads a variable other than the loop's states (then the other
    /// states are interpolated along the runs).
    mixed: bool,
    /// Per segment of the data, sample k → its slot in `fixed` (`u32::MAX`: no window covers k).
    slot: Vec<Vec<u32>>,
    /// Per segment, the terms that do not involve the loop's states at the three points RK4
    /// evaluates of every covered interval (the interval's start, middle and end):
    /// `[(3 slot + point) * columns + column]`.
    fixed: Vec<Vec<f64>>,
    /// Columns of `fixed`: the first `columns` terms.
    columns: usize,
}

/// The fractions of an interval RK4 evaluates the row at (start, middle, end).
const RK4_POINTS: [f64; 3] = [0.0, 0.5, 1.0];

/// A term's value at `v` (what [`super::sindy::eval_term`] computes, bit for bit: a first power
/// is the base itself, as `powi(1)` gives it).
fn eval_term(term: &Term, v: &[f64; 16]) -> f64 {
    let mut r = 1.0;
    for &(base, power) in &term.factors {
        let b = match base {
            Base::Var(i) => v[i],
            Base::Sin(i) => v[i].sin(),
            Base::Cos(i) => v[i].cos(),
        };
        r *= if power == 1 { b } else { b.powi(power as i32) };
    }
    r
}

/// A term's value at `v` (as [`eval_term`], bit for bit) and its partial derivatives by the
/// variables `a` and `b` (product rule over the factors; `b` may equal `a`).
fn eval_term_grad(term: &Term, v: &[f64; 16], a: usize, b: usize) -> (f64, f64, f64) {
    let (mut r, mut da, mut db) = (1.0, 0.0, 0.0);
    for &(base, power) in &term.factors {
        let (i, x, dx) = match base {
            Base::Var(i) => (i, v[i], 1.0),
            Base::Sin(i) => (i, v[i].sin(), v[i].cos()),
            Base::Cos(i) => (i, v[i].cos(), -v[i].sin()),
        };
        let (g, dg) = if power == 1 {
            (x, dx)
        } else {
            (x.powi(power as i32), power as f64 * x.powi(power as i32 - 1) * dx)
        };
        // d(r g) = dr g + r dg, dg only by the factor's own variable.
        da *= g;
        db *= g;
        if i == a {
            da += r * dg;
        }
        if i == b {
            db += r * dg;
        }
        r *= g;
    }
    (r, da, db)
}

/// Whether `term` reads the variable `var`.
fn reads(term: &Term, var: usize) -> bool {
    term.factors.iter().any(|&(base, _)| match base {
        Base::Var(i) | Base::Sin(i) | Base::Cos(i) => i == var,
    })
}

/// The variables at fraction `frac` of interval k of `seg`: states linearly interpolated between
/// x_k and x_{k+1}, the interval's inputs.
fn interpolated(seg: &SegmentData, k: usize, frac: f64) -> [f64; 16] {
    let (x0, x1) = (&seg.x[k], &seg.x_next[k]);
    let mut v = [0.0; 16];
    for i in 0..12 {
        v[i] = x0[i] + frac * (x1[i] - x0[i]);
    }
    v[12..].copy_from_slice(&seg.u[k]);
    v
}

impl Row {
    /// The row of loop `lp`; the terms that involve neither the row's state nor (with an angle)
    /// the judged state are the same on every free run through a sample, so they are evaluated
    /// once per sample the `windows` (of `h` samples) cover here, instead of on every run (the
    /// refinement runs each window twice per Levenberg–Marquardt iteration).
    fn new(lp: Loop, terms: Vec<Term>, theta0: Vec<f64>, data: &Dataset, windows: &[Window], h: usize) -> Self {
        let (row, output, angle) = (lp.row, lp.output, lp.has_angle());
        let loop_var = |i: usize| i == row || (angle && i == output);
        let is_free: Vec<bool> = terms
            .iter()
            .map(|t| reads(t, row) || (angle && reads(t, output)))
            .collect();
        let order: Vec<usize> = (0..terms.len())
            .filter(|&i| !is_free[i])
            .chain((0..terms.len()).filter(|&i| is_free[i]))
            .collect();
        let columns = is_free.iter().filter(|f| !**f).count();
        let terms: Vec<Term> = order.iter().map(|&i| terms[i].clone()).collect();
        let theta0: Vec<f64> = order.iter().map(|&i| theta0[i]).collect();
        let mixed = terms[columns..].iter().any(|t| {
            t.factors.iter().any(|&(base, _)| match base {
                Base::Var(v) | Base::Sin(v) | Base::Cos(v) => !loop_var(v),
            })
        });
        let mut slot: Vec<Vec<u32>> = data.segments.iter().map(|_| Vec::new()).collect();
        for w in windows {
            let n = data.segments[w.seg].x.len();
            let s = &mut slot[w.seg];
            if s.is_empty() {
                *s = vec![u32::MAX; n];
            }
            for k in w.start..(w.start + h).min(n) {
                s[k] = 0;
            }
        }
        let fixed = data
            .segments
            .iter()
            .zip(slot.iter_mut())
            .map(|(seg, slots)| {
                // Its exact size (a growing vector would hold up to twice the table).
                let covered = slots.iter().filter(|s| **s != u32::MAX).count();
                let mut table = Vec::with_capacity(covered * RK4_POINTS.len() * columns);
                let mut next = 0u32;
                for (k, sl) in slots.iter_mut().enumerate() {
                    if *sl == u32::MAX {
                        continue;
                    }
                    *sl = next;
                    next += 1;
                    if columns == 0 {
                        continue;
                    }
                    for frac in RK4_POINTS {
                        let v = interpolated(seg, k, frac);
                        for t in &terms[..columns] {
                            table.push(eval_term(t, &v));
                        }
                    }
                }
                table
            })
            .collect();
        Self {
            lp,
            terms,
            theta0,
            order,
            mixed,
            slot,
            fixed,
            columns,
        }
    }

    /// θ in the row's order (of the refinement's order, `theta`).
    fn original(&self, theta: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; theta.len()];
        for (&i, t) in self.order.iter().zip(theta) {
            out[i] = *t;
        }
        out
    }

    /// θ in the refinement's order (of the row's order, `theta`).
    #[cfg(test)]
    fn internal(&self, theta: &[f64]) -> Vec<f64> {
        self.order.iter().map(|&i| theta[i]).collect()
    }

    /// Per segment and covered interval, the fixed terms' part of the rate at RK4's three points,
    /// Σ θ_i φ_i over the tabulated terms in order: `[3 slot + point]`.
    fn fixed_sums(&self, theta: &[f64]) -> Vec<Vec<f64>> {
        let fixed_theta = &theta[..self.columns];
        self.fixed
            .iter()
            .zip(&self.slot)
            .map(|(table, slots)| {
                let points = 3 * slots.iter().filter(|s| **s != u32::MAX).count();
                (0..points)
                    .map(|q| {
                        let phi = &table[q * self.columns..(q + 1) * self.columns];
                        phi.iter().zip(fixed_theta).fold(-0.0, |acc, (p, t)| acc + t * p)
                    })
                    .collect()
            })
            .collect()
    }

    /// The free-run residuals y_sim − y_log of every window, into `out`.
    ///
    /// Every free run is one RK4 step per interval k of the loop's (output, rate), ṙ = Σ θ_i φ_i(v)
    /// at the interval's start, middle (twice) and end, v the other states linearly interpolated
    /// between x_k and x_{k+1} and the interval's inputs: the tabulated terms' sum read from
    /// [`Row::fixed_sums`], the terms that read a loop state evaluated along the run.
    fn residuals(&self, theta: &[f64], data: &Dataset, windows: &[Window], h: usize, out: &mut Vec<f64>) {
        out.clear();
        let p = self.terms.len();
        let sums = self.fixed_sums(theta);
        let angle = self.lp.has_angle();
        let (row, output) = (self.lp.row, self.lp.output);
        for w in windows {
            let seg = &data.segments[w.seg];
            let (slots, sums) = (&self.slot[w.seg], &sums[w.seg]);
            let dt = seg.dt;
            let x = &seg.x[w.start];
            let mut s = [x[output], x[row]];
            for k in w.start..w.start + h {
                let v = if self.mixed {
                    RK4_POINTS.map(|frac| interpolated(seg, k, frac))
                } else {
                    [[0.0; 16]; 3]
                };
                let q = 3 * slots[k] as usize;
                let mut slopes = [[0.0; 2]; 4];
                for (stage, point) in [0usize, 1, 1, 2].into_iter().enumerate() {
                    let at = match stage {
                        0 => s,
                        1 | 2 => [
                            s[0] + 0.5 * dt * slopes[stage - 1][0],
                            s[1] + 0.5 * dt * slopes[stage - 1][1],
                        ],
                        _ => [s[0] + dt * slopes[2][0], s[1] + dt * slopes[2][1]],
                    };
                    let mut f = sums[q + point];
                    if self.columns < p {
                        let mut vr = v[point];
                        if angle {
                            vr[output] = at[0];
                        }
                        vr[row] = at[1];
                        for (t, c) in self.terms[self.columns..].iter().zip(&theta[self.columns..]) {
                            f += c * eval_term(t, &vr);
                        }
                    }
                    slopes[stage] = if angle { [at[1], f] } else { [0.0, f] };
                }
                let [k1, k2, k3, k4] = slopes;
                s = [
                    s[0] + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
                    s[1] + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
                ];
                out.push(if angle { s[0] } else { s[1] } - seg.x_next[k][output]);
            }
        }
    }

    /// The free-run residuals at `theta` (into `r` if given, as [`Row::residuals`]; their sum of
    /// squares is returned, summed in their order, so they need not be held) and the Gauss–Newton
    /// matrices of their Jacobian J = ∂r/∂θ: (JᵀJ, Jᵀr, Σ r²).
    ///
    /// J is exact for the discrete runs: forward sensitivities S = ∂(output, rate)/∂θ carried
    /// through every RK4 stage alongside the state. The rate ṙ = Σ θ_i φ_i(v) is linear in θ, so
    /// a stage's slope sensitivity is ∂k/∂θ_j = φ_j + (∂f/∂rate) S_rate,j + (∂f/∂angle) S_angle,j
    /// (the angle's slope is the rate: its sensitivity is S_rate), ∂f/∂· = Σ θ_i ∂φ_i/∂· over the
    /// terms that read the loop's states (the tabulated ones do not). One run per call instead of
    /// the p + 1 of a forward-difference Jacobian, and without its truncation error.
    fn residuals_jacobian(
        &self,
        theta: &[f64],
        data: &Dataset,
        windows: &[Window],
        h: usize,
        mut r: Option<&mut Vec<f64>>,
    ) -> (DMatrix<f64>, DVector<f64>, f64) {
        if let Some(r) = r.as_mut() {
            r.clear();
        }
        let p = self.terms.len();
        let mut jtj = DMatrix::zeros(p, p);
        let mut jtr = DVector::zeros(p);
        let mut sse = -0.0;
        if p == 0 {
            return (jtj, jtr, sse);
        }
        let sums = self.fixed_sums(theta);
        let angle = self.lp.has_angle();
        let (row, output) = (self.lp.row, self.lp.output);
        let columns = self.columns;
        // JᵀJ's upper triangle (row-major, p × p) and Jᵀr, accumulated residual by residual.
        let mut upper = vec![0.0; p * p];
        let mut jr = vec![0.0; p];
        // Sensitivities of the state (angle, rate), at a stage, and of the four stages' slopes
        // (`[stage * p + j]`); φ of the terms evaluated along the run.
        let (mut sa, mut sr) = (vec![0.0; p], vec![0.0; p]);
        let (mut ata, mut atr) = (vec![0.0; p], vec![0.0; p]);
        let (mut ka, mut kr) = (vec![0.0; 4 * p], vec![0.0; 4 * p]);
        let mut phi_free = vec![0.0; p - columns];
        for w in windows {
            let seg = &data.segments[w.seg];
            let (slots, sums, table) = (&self.slot[w.seg], &sums[w.seg], &self.fixed[w.seg]);
            let dt = seg.dt;
            let x = &seg.x[w.start];
            let mut s = [x[output], x[row]];
            sa.fill(0.0);
            sr.fill(0.0);
            for k in w.start..w.start + h {
                let v = if self.mixed {
                    RK4_POINTS.map(|frac| interpolated(seg, k, frac))
                } else {
                    [[0.0; 16]; 3]
                };
                let q = 3 * slots[k] as usize;
                let mut slopes = [[0.0; 2]; 4];
                for (stage, point) in [0usize, 1, 1, 2].into_iter().enumerate() {
                    let c = if stage == 3 { dt } else { 0.5 * dt };
                    let at = if stage == 0 {
                        ata.copy_from_slice(&sa);
                        atr.copy_from_slice(&sr);
                        s
                    } else {
                        let sl = slopes[stage - 1];
                        let (pa, pr) = (&ka[(stage - 1) * p..stage * p], &kr[(stage - 1) * p..stage * p]);
                        for ((a, s), k) in ata.iter_mut().zip(&sa).zip(pa) {
                            *a = s + c * k;
                        }
                        for ((a, s), k) in atr.iter_mut().zip(&sr).zip(pr) {
                            *a = s + c * k;
                        }
                        [s[0] + c * sl[0], s[1] + c * sl[1]]
                    };
                    let (mut f, mut f_rate, mut f_angle) = (sums[q + point], 0.0, 0.0);
                    if columns < p {
                        let mut vr = v[point];
                        if angle {
                            vr[output] = at[0];
                        }
                        vr[row] = at[1];
                        for ((t, th), ph) in self.terms[columns..]
                            .iter()
                            .zip(&theta[columns..])
                            .zip(phi_free.iter_mut())
                        {
                            let (value, d_rate, d_angle) = eval_term_grad(t, &vr, row, output);
                            *ph = value;
                            f += th * value;
                            f_rate += th * d_rate;
                            if angle {
                                f_angle += th * d_angle;
                            }
                        }
                    }
                    slopes[stage] = if angle { [at[1], f] } else { [0.0, f] };
                    // ∂k/∂θ_j: the angle's slope is the rate; the rate's is φ_j + f_rate S_rate + f_angle S_angle.
                    let phi_fixed = &table[(q + point) * columns..(q + point + 1) * columns];
                    let phi = phi_fixed.iter().chain(phi_free.iter());
                    let nr = &mut kr[stage * p..(stage + 1) * p];
                    for (((n, ph), r), a) in nr.iter_mut().zip(phi).zip(&atr).zip(&ata) {
                        *n = ph + f_rate * r + f_angle * a;
                    }
                    let na = &mut ka[stage * p..(stage + 1) * p];
                    if angle {
                        na.copy_from_slice(&atr);
                    } else {
                        na.fill(0.0);
                    }
                }
                let [k1, k2, k3, k4] = slopes;
                s = [
                    s[0] + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
                    s[1] + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
                ];
                let (k0, rest) = ka.split_at(p);
                let (k1, rest) = rest.split_at(p);
                let (k2, k3) = rest.split_at(p);
                for ((((s, a), b), c), d) in sa.iter_mut().zip(k0).zip(k1).zip(k2).zip(k3) {
                    *s += dt / 6.0 * (a + 2.0 * b + 2.0 * c + d);
                }
                let (k0, rest) = kr.split_at(p);
                let (k1, rest) = rest.split_at(p);
                let (k2, k3) = rest.split_at(p);
                for ((((s, a), b), c), d) in sr.iter_mut().zip(k0).zip(k1).zip(k2).zip(k3) {
                    *s += dt / 6.0 * (a + 2.0 * b + 2.0 * c + d);
                }
                let jrow: &[f64] = if angle { &sa } else { &sr };
                let res = if angle { s[0] } else { s[1] } - seg.x_next[k][output];
                if let Some(r) = r.as_mut() {
                    r.push(res);
                }
                sse += res * res;
                for (i, &ji) in jrow.iter().enumerate() {
                    jr[i] += ji * res;
                    for (u, jk) in upper[i * p + i..(i + 1) * p].iter_mut().zip(&jrow[i..]) {
                        *u += ji * jk;
                    }
                }
            }
        }
        for i in 0..p {
            jtr[i] = jr[i];
            for k in i..p {
                jtj[(i, k)] = upper[i * p + k];
                jtj[(k, i)] = upper[i * p + k];
            }
        }
        (jtj, jtr, sse)
    }

    fn cost(&self, theta: &[f64], data: &Dataset, windows: &[Window], h: usize, buf: &mut Vec<f64>) -> f64 {
        self.residuals(theta, data, windows, h, buf);
        let c: f64 = buf.iter().map(|r| r * r).sum();
        if c.is_finite() {
            c
        } else {
            f64::INFINITY
        }
    }

    /// Levenberg–Marquardt on the windows from θ₀; returns the refined θ. Every point tried is
    /// run once, with its sensitivities ([`Row::residuals_jacobian`]): an accepted step's run
    /// gives the next iteration's JᵀJ and Jᵀr.
    fn refine(&self, data: &Dataset, windows: &[Window], options: &RefineOptions) -> Vec<f64> {
        let h = options.horizon;
        let p = self.theta0.len();
        let mut theta = self.theta0.clone();
        if windows.is_empty() || p == 0 {
            return theta;
        }
        // The runs' sum of squares (the residuals are not held: their number is windows × horizon).
        let finite = |c: f64| if c.is_finite() { c } else { f64::INFINITY };
        let (mut a, mut g, c0) = self.residuals_jacobian(&theta, data, windows, h, None);
        let mut cost = finite(c0);
        if !cost.is_finite() {
            return theta;
        }
        let mut lambda = 1e-3;
        for _ in 0..options.max_iter {
            if a.iter().chain(g.iter()).any(|v: &f64| !v.is_finite()) {
                break;
            }
            // Converged when even the Gauss–Newton step (λ = 0) predicts a relative fall of the
            // cost below the 1e-7 at which an accepted step ends the iterations (else the search
            // below would try ever larger λ, one free run each, for a fall it cannot find).
            if let Some(c) = a.clone().cholesky() {
                let predicted = g.dot(&c.solve(&g));
                if predicted.is_finite() && predicted < 1e-7 * cost {
                    return theta;
                }
            }
            let mut accepted = false;
            while lambda < 1e10 {
                let mut lhs = a.clone();
                for i in 0..p {
                    lhs[(i, i)] += lambda * a[(i, i)].max(1e-12);
                }
                let Some(delta) = lhs.cholesky().map(|c| c.solve(&(-&g))) else {
                    lambda *= 4.0;
                    continue;
                };
                let trial: Vec<f64> = theta.iter().zip(delta.iter()).map(|(t, d)| t + d).collect();
                let (at, gt, c) = self.residuals_jacobian(&trial, data, windows, h, None);
                let c = finite(c);
                if c < cost {
                    let fall = (cost - c) / cost;
                    theta = trial;
                    cost = c;
                    (a, g) = (at, gt);
                    lambda = (lambda / 3.0).max(1e-9);
                    accepted = true;
                    if fall < 1e-7 {
                        return theta;
                    }
                    break;
                }
                lambda *= 4.0;
            }
            if !accepted {
                break;
            }
        }
        theta
    }
}

/// Refine the loops of a SINDy model's coefficients (the 12 default states and 4 inputs) on the
/// integral-form data set; the coefficients of kept refinements are replaced in place.
pub fn refine(coefficients: &mut [Coefficient], data: &Dataset, options: &RefineOptions) -> Vec<LoopRefinement> {
    let vars: Vec<String> = DEFAULT_STATES
        .iter()
        .chain(DEFAULT_INPUTS.iter())
        .map(|s| s.to_string())
        .collect();
    let h = options.horizon.max(1);
    let starts: usize = data
        .segments
        .iter()
        .filter(|seg| seg.x_next.len() == seg.x.len() && seg.x.len() >= h)
        .map(|seg| seg.x.len() - h + 1)
        .sum();
    let stride = options.stride.max(1).max(starts.div_ceil(options.max_windows.max(1)));
    let mut windows = Vec::new();
    for (si, seg) in data.segments.iter().enumerate() {
        if seg.x_next.len() != seg.x.len() || seg.x.len() < h {
            continue;
        }
        for start in (0..=seg.x.len() - h).step_by(stride) {
            windows.push(Window { seg: si, start });
        }
    }
    let logs = data.segments.iter().map(|s| s.log).max().map_or(0, |m| m + 1);
    let folds = if logs >= 3 { logs } else { options.blocks.max(2) };
    let fold_of = |w: &Window| -> usize {
        if logs >= 3 {
            data.segments[w.seg].log
        } else {
            let n = data.segments[w.seg].x.len();
            (w.start * folds / n.max(1)).min(folds - 1)
        }
    };
    let mut out = Vec::new();
    for lp in LOOPS {
        let row_name = lp.row_name();
        let idx: Vec<usize> = (0..coefficients.len())
            .filter(|&i| coefficients[i].state == row_name && coefficients[i].coefficient != 0.0)
            .collect();
        let parsed: Option<Vec<Term>> = idx
            .iter()
            .map(|&i| parse_term(&coefficients[i].term, &vars).ok())
            .collect();
        let mut report = LoopRefinement {
            row: row_name,
            output: lp.output_name(),
            terms: idx
                .iter()
                .map(|&i| {
                    (
                        coefficients[i].term.clone(),
                        coefficients[i].coefficient,
                        coefficients[i].coefficient,
                    )
                })
                .collect(),
            held_out_rmse: (f64::NAN, f64::NAN),
            windows: windows.len(),
            kept: false,
            note: None,
        };
        let Some(terms) = parsed else {
            report.note = Some("a term of the row is not in the default variables".into());
            out.push(report);
            continue;
        };
        if idx.is_empty() || windows.is_empty() {
            report.note = Some(
                if idx.is_empty() {
                    "the row has no term"
                } else {
                    "no window of one horizon in the data"
                }
                .into(),
            );
            out.push(report);
            continue;
        }
        let row = Row::new(
            lp,
            terms,
            idx.iter().map(|&i| coefficients[i].coefficient).collect(),
            data,
            &windows,
            h,
        );
        // Cross-validation: refine on all folds but one, score the one (in parallel over folds).
        let scores: Vec<(f64, f64, usize)> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..folds)
                .map(|f| {
                    let (train, test): (Vec<Window>, Vec<Window>) = windows.iter().partition(|w| fold_of(w) != f);
                    let row = &row;
                    scope.spawn(move || {
                        if test.is_empty() || train.is_empty() {
                            return (0.0, 0.0, 0);
                        }
                        let theta = row.refine(data, &train, options);
                        let mut buf = Vec::new();
                        let before = row.cost(&row.theta0, data, &test, h, &mut buf);
                        let after = row.cost(&theta, data, &test, h, &mut buf);
                        (before, after, buf.len())
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or((f64::INFINITY, f64::INFINITY, 0)))
                .collect()
        });
        let (held_out_rmse, not_kept) = held_out_verdict(&scores, options.min_gain);
        report.held_out_rmse = held_out_rmse;
        if let Some(why) = not_kept {
            report.note = Some(why);
        } else {
            let theta = row.refine(data, &windows, options);
            if theta.iter().all(|t| t.is_finite()) {
                let theta = row.original(&theta);
                for ((&i, t), entry) in idx.iter().zip(&theta).zip(report.terms.iter_mut()) {
                    coefficients[i].coefficient = *t;
                    entry.2 = *t;
                }
                report.kept = true;
            } else {
                report.note = Some("the refinement on all windows is not finite".into());
            }
        }
        out.push(report);
    }
    out
}

/// The kept rule over the folds' held-out scores `(SSE before, SSE after, samples)`: the held-out
/// RMSE before and after the refinement, and why it is not kept (`None`: kept — its free runs are
/// finite and at least `min_gain` better on data it was not fitted on).
pub(crate) fn held_out_verdict(scores: &[(f64, f64, usize)], min_gain: f64) -> ((f64, f64), Option<String>) {
    let (before, after, n) = scores
        .iter()
        .fold((0.0, 0.0, 0usize), |(a, b, n), s| (a + s.0, b + s.1, n + s.2));
    let rms = |sse: f64| if n > 0 { (sse / n as f64).sqrt() } else { f64::NAN };
    let why = if !(before.is_finite() && after.is_finite()) || n == 0 {
        Some("the held-out free runs are not finite".into())
    } else if after > (1.0 - min_gain) * before {
        Some(format!(
            "held-out gain {:.1} % < {:.0} %",
            100.0 * (1.0 - after / before),
            100.0 * min_gain
        ))
    } else {
        None
    };
    ((rms(before), rms(after)), why)
}

/// Test data shared by the SINDy and PD loop refinements' tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::super::dataset::{Dataset, SegmentData};

    /// Integral-form data of a known roll loop, ṙ = −ω²(φ − K u) − 2ζω r (pitch and heading still),
    /// 30 Hz, `logs` segments of 300 samples with u_roll stepping every 2/3 s, from an Euler
    /// integration of `substeps` steps per sample; the logged roll and roll rate with uniform noise
    /// of ±`noise`/2 and ±5 `noise` (a fixed LCG from `seed`).
    pub(crate) fn roll_loop_data(
        wn: f64,
        zeta: f64,
        gain: f64,
        noise: f64,
        logs: usize,
        seed: u64,
        substeps: usize,
    ) -> Dataset {
        let dt = 1.0 / 30.0;
        let mut seed = seed;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let segments = (0..logs)
            .map(|log| {
                let n = 300;
                let mut x = vec![[0.0; 12]; n + 1];
                let mut u = vec![[0.0; 4]; n];
                let (mut phi, mut r) = (0.0, 0.0);
                for k in 0..n {
                    u[k][1] = 0.3 * (((k / 20 + log) % 3) as f64 - 1.0);
                    x[k][3] = phi;
                    x[k][9] = r;
                    for _ in 0..substeps {
                        let h = dt / substeps as f64;
                        let acc = -wn * wn * (phi - gain * u[k][1]) - 2.0 * zeta * wn * r;
                        phi += h * r;
                        r += h * acc;
                    }
                }
                x[n][3] = phi;
                x[n][9] = r;
                for s in x.iter_mut() {
                    s[3] += noise * rnd();
                    s[9] += 10.0 * noise * rnd();
                }
                SegmentData {
                    log,
                    segment: 0,
                    dt,
                    t: (0..n).map(|k| k as f64 * dt).collect(),
                    x: x[..n].to_vec(),
                    u,
                    dx: vec![[0.0; 12]; n],
                    x_next: x[1..].to_vec(),
                }
            })
            .collect();
        Dataset { segments }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A data set from a known roll loop ([`fixtures::roll_loop_data`]; 20 Euler substeps: the
    /// refinement's single RK4 step per sample is within 2 % of its coefficients).
    fn roll_data(wn: f64, zeta: f64, gain: f64, noise: f64, logs: usize) -> Dataset {
        super::fixtures::roll_loop_data(wn, zeta, gain, noise, logs, 7, 20)
    }

    /// Every coefficient within `tol` (relative) of `want`'s.
    fn assert_near(coefficients: &[Coefficient], want: &[Coefficient], tol: f64) {
        for (c, w) in coefficients.iter().zip(want) {
            assert!(
                (c.coefficient - w.coefficient).abs() < tol * w.coefficient.abs(),
                "{c:?} vs {w:?}"
            );
        }
    }

    fn roll_row(wn: f64, zeta: f64, gain: f64) -> Vec<Coefficient> {
        let c = |term: &str, coefficient: f64| Coefficient {
            state: "roll_rate".into(),
            term: term.into(),
            coefficient,
        };
        vec![
            c("roll", -wn * wn),
            c("roll_rate", -2.0 * zeta * wn),
            c("u_roll", gain * wn * wn),
        ]
    }

    /// The free runs with the fixed terms tabulated per covered sample and summed once per θ
    /// are the plain evaluation: every term by `sindy::eval_term` on the interpolated variables
    /// at every RK4 stage, summed in order (a row with fixed, loop-state-only and mixed terms,
    /// powers and trigonometric factors; equal to round-off, the sums' order differs).
    #[test]
    fn tabulated_runs_are_the_plain_runs() {
        let mut data = roll_data(6.0, 0.5, 0.9, 0.01, 2);
        for seg in data.segments.iter_mut() {
            for (k, x) in seg.x.iter_mut().chain(seg.x_next.iter_mut()).enumerate() {
                x[4] = 0.1 * (k as f64 * 0.05).sin();
                x[10] = 0.3 * (k as f64 * 0.07).cos();
            }
        }
        let vars: Vec<String> = DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect();
        let names = [
            "roll",
            "roll_rate",
            "u_roll",
            "pitch^2",
            "roll_rate*pitch_rate",
            "sin(roll)*cos(pitch)",
            "u_roll*cos(pitch)",
            "1",
        ];
        let terms: Vec<Term> = names.iter().map(|t| parse_term(t, &vars).unwrap()).collect();
        let theta0 = vec![-36.0, -8.4, 32.0, 0.5, 0.2, -1.5, 2.0, 0.1];
        let lp = LOOPS[1];
        let h = 30;
        let windows: Vec<Window> = (0..2)
            .flat_map(|seg| (0..250).step_by(7).map(move |start| Window { seg, start }))
            .collect();
        let row = Row::new(lp, terms.clone(), theta0.clone(), &data, &windows, h);
        assert_eq!(row.columns, 4);
        let plain = |theta: &[f64]| -> Vec<f64> {
            let mut out = Vec::new();
            for w in &windows {
                let seg = &data.segments[w.seg];
                let mut s = [seg.x[w.start][3], seg.x[w.start][9]];
                for k in w.start..w.start + h {
                    let f = |frac: f64, s: [f64; 2]| -> [f64; 2] {
                        let mut v = [0.0; 16];
                        for i in 0..12 {
                            v[i] = seg.x[k][i] + frac * (seg.x_next[k][i] - seg.x[k][i]);
                        }
                        v[12..].copy_from_slice(&seg.u[k]);
                        v[3] = s[0];
                        v[9] = s[1];
                        let rate: f64 = terms
                            .iter()
                            .zip(theta)
                            .map(|(t, c)| c * crate::identify::sindy::eval_term(t, &v))
                            .sum();
                        [s[1], rate]
                    };
                    let dt = seg.dt;
                    let k1 = f(0.0, s);
                    let k2 = f(0.5, [s[0] + 0.5 * dt * k1[0], s[1] + 0.5 * dt * k1[1]]);
                    let k3 = f(0.5, [s[0] + 0.5 * dt * k2[0], s[1] + 0.5 * dt * k2[1]]);
                    let k4 = f(1.0, [s[0] + dt * k3[0], s[1] + dt * k3[1]]);
                    s = [
                        s[0] + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
                        s[1] + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
                    ];
                    out.push(s[0] - seg.x_next[k][3]);
                }
            }
            out
        };
        let other: Vec<f64> = theta0
            .iter()
            .enumerate()
            .map(|(i, t)| t * (1.0 + 0.01 * i as f64))
            .collect();
        for theta in [&theta0, &other] {
            let mut got = Vec::new();
            row.residuals(&row.internal(theta), &data, &windows, h, &mut got);
            let want = plain(theta);
            assert_eq!(got.len(), want.len());
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 1e-3);
            assert!(got.iter().zip(&want).all(|(a, b)| (a - b).abs() <= 1e-12 * scale));
        }
    }

    /// The forward-sensitivity Jacobian is the derivative of the free runs: its residuals are
    /// [`Row::residuals`]' bit for bit, and JᵀJ, Jᵀr match central differences of the runs
    /// (a row with fixed, loop-state-only and mixed terms, powers and trigonometric factors; an
    /// angle loop and a rate-only loop).
    #[test]
    fn the_sensitivity_jacobian_is_the_runs_derivative() {
        let mut data = roll_data(6.0, 0.5, 0.9, 0.01, 2);
        for seg in data.segments.iter_mut() {
            for (k, x) in seg.x.iter_mut().chain(seg.x_next.iter_mut()).enumerate() {
                x[4] = 0.1 * (k as f64 * 0.05).sin();
                x[10] = 0.3 * (k as f64 * 0.07).cos();
                x[11] = 0.2 * (k as f64 * 0.03).sin();
            }
        }
        let vars: Vec<String> = DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect();
        let cases: [(Loop, &[&str], Vec<f64>); 2] = [
            (
                LOOPS[1],
                &[
                    "roll",
                    "roll_rate",
                    "u_roll",
                    "pitch^2",
                    "roll_rate*pitch_rate",
                    "sin(roll)*cos(pitch)",
                    "roll^2*roll_rate",
                    "roll*cos(roll)",
                    "u_roll*cos(pitch)",
                    "1",
                ],
                vec![-36.0, -8.4, 32.0, 0.5, 0.2, -1.5, -3.0, 0.7, 2.0, 0.1],
            ),
            (
                LOOPS[3],
                &["yaw_rate", "yaw_rate^3", "sin(yaw_rate)*pitch", "u_roll", "1"],
                vec![-5.0, -0.4, 0.3, 0.8, 0.05],
            ),
        ];
        for (lp, names, theta) in cases {
            let terms: Vec<Term> = names.iter().map(|t| parse_term(t, &vars).unwrap()).collect();
            let h = 30;
            let windows: Vec<Window> = (0..2)
                .flat_map(|seg| (0..250).step_by(11).map(move |start| Window { seg, start }))
                .collect();
            let row = Row::new(lp, terms, theta.clone(), &data, &windows, h);
            let theta = row.internal(&theta);
            let p = theta.len();
            let mut r = Vec::new();
            let (jtj, jtr, sse) = row.residuals_jacobian(&theta, &data, &windows, h, Some(&mut r));
            assert_eq!(sse.to_bits(), r.iter().map(|v| v * v).sum::<f64>().to_bits());
            let mut plain = Vec::new();
            row.residuals(&theta, &data, &windows, h, &mut plain);
            assert_eq!(r.len(), plain.len());
            assert!(r.iter().zip(&plain).all(|(a, b)| a.to_bits() == b.to_bits()));
            // Central differences, column by column.
            let mut jac = DMatrix::zeros(r.len(), p);
            for i in 0..p {
                let step = 1e-5 * theta[i].abs().max(1.0);
                let (mut up, mut down) = (theta.clone(), theta.clone());
                up[i] += step;
                down[i] -= step;
                let (mut ru, mut rd) = (Vec::new(), Vec::new());
                row.residuals(&up, &data, &windows, h, &mut ru);
                row.residuals(&down, &data, &windows, h, &mut rd);
                for (m, (a, b)) in ru.iter().zip(&rd).enumerate() {
                    jac[(m, i)] = (a - b) / (2.0 * step);
                }
            }
            let want_jtj = jac.tr_mul(&jac);
            let want_jtr = jac.tr_mul(&DVector::from_column_slice(&r));
            for i in 0..p {
                let scale = (want_jtj[(i, i)]).sqrt();
                assert!(scale > 0.0, "{lp:?}: column {i} has no effect");
                let jr = (jtr[i] - want_jtr[i]).abs();
                assert!(
                    jr <= 1e-6 * scale * (r.iter().map(|v| v * v).sum::<f64>()).sqrt(),
                    "{lp:?} Jᵀr[{i}]: {} vs {}",
                    jtr[i],
                    want_jtr[i]
                );
                for j in 0..p {
                    let tol = 1e-6 * scale * want_jtj[(j, j)].sqrt();
                    assert!(
                        (jtj[(i, j)] - want_jtj[(i, j)]).abs() <= tol,
                        "{lp:?} JᵀJ[{i},{j}]: {} vs {}",
                        jtj[(i, j)],
                        want_jtj[(i, j)]
                    );
                }
            }
        }
    }

    #[test]
    fn a_biased_roll_row_is_moved_to_the_loop_that_made_the_data() {
        let data = roll_data(8.0, 0.7, 1.0, 0.0, 3);
        let mut coefficients = roll_row(3.5, 0.36, 0.82);
        let report = refine(&mut coefficients, &data, &RefineOptions::default());
        let roll = report.iter().find(|r| r.row == "roll_rate").unwrap();
        assert!(roll.kept, "{}", roll.line());
        assert!(roll.held_out_rmse.1 < 0.1 * roll.held_out_rmse.0, "{}", roll.line());
        let want = roll_row(8.0, 0.7, 1.0);
        assert_near(&coefficients, &want, 0.02);
        // The rows without terms are reported, not refined.
        assert!(report.iter().filter(|r| r.row != "roll_rate").all(|r| !r.kept));
    }

    /// With noisy window starts the free runs can still gain a little (RK4 at the log's rate,
    /// the noise of each window's initial rate), but the loop barely moves.
    #[test]
    fn a_row_that_already_fits_barely_moves() {
        let data = roll_data(8.0, 0.7, 1.0, 0.002, 3);
        let mut coefficients = roll_row(8.0, 0.7, 1.0);
        let report = refine(&mut coefficients, &data, &RefineOptions::default());
        let roll = report.iter().find(|r| r.row == "roll_rate").unwrap();
        assert!(roll.held_out_rmse.0 < 0.002, "{}", roll.line());
        assert_near(&coefficients, &roll_row(8.0, 0.7, 1.0), 0.01);
    }

    /// On long data the stride grows so that no more than `max_windows` free runs are scored.
    #[test]
    fn the_windows_are_capped() {
        let data = roll_data(6.0, 0.5, 0.9, 0.0, 3);
        let options = RefineOptions {
            max_windows: 100,
            ..RefineOptions::default()
        };
        let mut coefficients = roll_row(3.0, 0.3, 0.6);
        let report = refine(&mut coefficients, &data, &options);
        let roll = report.iter().find(|r| r.row == "roll_rate").unwrap();
        assert!(roll.windows <= 100 && roll.windows >= 90, "{}", roll.line());
        let all = refine(&mut roll_row(3.0, 0.3, 0.6), &data, &RefineOptions::default());
        assert_eq!(all[1].windows, 3 * 271_usize.div_ceil(3), "{}", all[1].line());
    }

    #[test]
    fn one_log_is_cross_validated_in_blocks() {
        let data = roll_data(6.0, 0.5, 0.9, 0.0, 1);
        let mut coefficients = roll_row(3.0, 0.3, 0.6);
        let report = refine(&mut coefficients, &data, &RefineOptions::default());
        let roll = report.iter().find(|r| r.row == "roll_rate").unwrap();
        assert!(roll.kept, "{}", roll.line());
        let want = roll_row(6.0, 0.5, 0.9);
        assert_near(&coefficients, &want, 0.02);
    }
}
