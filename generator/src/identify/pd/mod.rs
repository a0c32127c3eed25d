//! The PD model fit: ξ1..ξ16 of MODEL_NOTES.md by bounded least squares of the Euler-Lagrange residual
//! M̄ q̈ + C̄ q̇ + Ḡ − R̄ [S1 μ − S2 q − S3 q̇ − S4 q̈ + S5] = 0 over a [`Dataset`], which is linear in ξ
//! (see [`regressors`] and `docs/pd-fit.md`).
//!
//! The translational rows (x, y, z) hold ξ1, ξ7, ξ11, ξ13 and are anchored by the known mass; the
//! rotational rows (roll, pitch, yaw) hold ξ2..ξ6, ξ8..ξ10, ξ12 and the inertias ξ14..ξ16 and are
//! homogeneous in them, so their scale is fixed by [`PdScale`]. The two groups share no parameter and
//! are solved as two independent bounded problems ([`bvls`]).

pub mod bvls;
mod checks;
pub mod refine;
pub mod regressors;

pub use checks::{FreeRun, FreeRunLimits, FREE_RUN_LIMITS, STABILITY_TOLERANCE};

use super::dataset::Dataset;
use super::loop_refine::{LoopRefinement, RefineOptions};
use super::preprocess::{try_columnwise, LowPass, PreprocessError};
use crate::model::{parse, Model, ModelError, PdFile, FORMAT};
use regressors::{mass_matrix, rotation_rows, thrust_axis, translation_rows, ROTATION_XI, TRANSLATION_XI};
use serde::Serialize;
use std::borrow::Cow;

/// Names of the six equation rows, in order.
pub const ROW_NAMES: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];

/// How the scale of the homogeneous rotational rows is fixed.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PdScale {
    /// Known inertias Ix, Iy, Iz (ξ14..ξ16, kg m²); the other rotational ξ are fitted.
    Inertia([f64; 3]),
    /// One rotational gain, stiffness or damping ξ`xi` (2, 3, 4, 5, 6, 8, 9 or 10) held at `value` (> 0);
    /// the inertias are fitted. The paper's normalisation is `Gain { xi: 2, value: 1.0 }`.
    Gain { xi: usize, value: f64 },
}

/// What the least-squares residual measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PdWeighting {
    /// The Euler-Lagrange residual itself, in N and N m (the paper's criterion). Its size scales with
    /// the vertical mass m + ξ11 b_z and with M(Ω) + ξ12 e3 e3ᵀ, so it is biased towards ξ11 → −m and
    /// ξ12 → 0.
    Force,
    /// The residual premultiplied by (M̄ + R̄ S4)⁻¹, i.e. in m/s² and rad/s²: the error of the q̈ the
    /// model predicts. The weight depends on ξ11, ξ12 and the inertias, so it is taken from the
    /// previous solution (iteratively reweighted least squares, starting from [`PdWeighting::Force`]).
    Acceleration,
}

/// Options of the PD fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PdFitOptions {
    /// m in kg (anchors the translational rows).
    pub mass: f64,
    /// g in m/s².
    pub gravity: f64,
    /// Scale fixing of the rotational rows.
    pub scale: PdScale,
    /// The paper's low-pass λ/(s+λ) (λ = 1 rad/s in the paper), applied inside the fit to states,
    /// inputs and derivatives of every segment before the rows are formed. Build the dataset
    /// without a low-pass when this is set, or the data is filtered twice.
    pub lowpass: Option<LowPass>,
    /// Which equation rows enter the fit: x, y, z, roll, pitch, yaw.
    pub rows: [bool; 6],
    /// The residual's units: force (the paper) or acceleration (default).
    pub weighting: PdWeighting,
    /// ξ held at given values (1-based index, value), besides the scale. Default: the acceleration
    /// feedbacks ξ11 = ξ12 = 0, which the data cannot separate from the vertical mass and the yaw inertia
    /// (docs/pd-fit.md). Any ξ1..ξ13 may be listed; the inertias are set by [`PdScale`].
    pub fixed: Vec<(usize, f64)>,
    /// Lower bound on the fitted inertias (kg m²) with [`PdScale::Gain`].
    pub min_inertia: f64,
    /// |ξ11| ≤ (1 − margin) m; the model file requires |ξ11| < m.
    pub xi11_margin: f64,
    /// Run the fitted model freely over every segment (a post-fit check).
    pub free_run: bool,
    /// Channels (u_vz, u_roll, u_pitch, u_yaw_rate) the logs did not excite
    /// ([`crate::identify::excitation`]): their gain (ξ1, ξ2, ξ3, ξ4) is not taken from the fit
    /// (which finds ~0 on a silent command) but set to the unit static gain, equal to the loop's
    /// stiffness or damping (ξ7, ξ5, ξ6, ξ10): the commanded quantity follows the command once
    /// settled.
    pub unit_gain: [bool; 4],
    /// The slowest rate loop a multirotor is taken to have (s): with known inertias
    /// ([`PdScale::Inertia`]) each rate damping is bounded below, ξ8 ≥ Ix/τ, ξ9 ≥ Iy/τ,
    /// ξ10 ≥ Iz/τ (the rate settles within τ without a command). A loop the logs do not excite
    /// (a still heading: the yaw rate is gyro noise) otherwise fits a damping of 0 and the model's
    /// channel is dead: its rate never decays and, at the unit static gain, the command never acts.
    /// `None`: dampings ≥ 0 only.
    pub max_rate_time_constant: Option<f64>,
}

/// The default [`PdFitOptions::max_rate_time_constant`] (s): every stabilised multirotor's rate
/// loops settle well within it (the bed's plants: yaw 0.05–0.2 s, roll and pitch < 0.1 s; the M100
/// logs' PD fit: yaw 0.4 s).
pub const MAX_RATE_TIME_CONSTANT: f64 = 1.0;

/// Per channel: the gain ξ and the stiffness/damping ξ that sets its static gain (1-based).
pub const CHANNEL_GAIN_XI: [(usize, usize); 4] = [(1, 7), (2, 5), (3, 6), (4, 10)];

impl Default for PdFitOptions {
    fn default() -> Self {
        Self {
            mass: 2.4,
            gravity: 9.81,
            scale: PdScale::Inertia([0.05, 0.05, 0.09]),
            lowpass: None,
            rows: [true; 6],
            weighting: PdWeighting::Acceleration,
            fixed: vec![(11, 0.0), (12, 0.0)],
            min_inertia: 1e-6,
            xi11_margin: 0.05,
            free_run: true,
            unit_gain: [false; 4],
            max_rate_time_constant: Some(MAX_RATE_TIME_CONSTANT),
        }
    }
}

impl PdFitOptions {
    /// The paper's preprocessing: the default options with the λ = 1 rad/s low-pass.
    pub fn paper() -> Self {
        Self {
            lowpass: Some(LowPass::default()),
            ..Self::default()
        }
    }
}

/// Why the fit failed.
#[derive(Debug, thiserror::Error)]
pub enum PdFitError {
    #[error("the dataset has no samples")]
    Empty,
    #[error("invalid PD fit option: {0}")]
    Option(String),
    #[error("log {log}, segment {segment}, sample {sample}: a state, input or derivative is not finite")]
    NonFinite { log: usize, segment: usize, sample: usize },
    #[error("low-pass: {0}")]
    LowPass(#[from] PreprocessError),
    #[error("ξ{} cannot be identified: no selected row depends on it (its regressor is zero)", .xi.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(", ξ"))]
    Unidentifiable { xi: Vec<usize> },
    #[error("the fitted model does not load: {0}")]
    Model(#[from] ModelError),
}

/// Residual of one equation row over the dataset.
#[derive(Clone, Debug, Serialize)]
pub struct RowResidual {
    pub row: &'static str,
    /// Whether the row entered the fit.
    pub used: bool,
    /// RMS of the residual (N for x, y, z; N m for roll, pitch, yaw).
    pub residual_rms: f64,
    /// RMS of the inertial side of the row, m (η̈ + g e3) or (M(Ω) + ξ12 e3 e3ᵀ) Ω̈ + C Ω̇, for scale.
    pub inertial_rms: f64,
}

/// One of the two bounded least-squares problems.
#[derive(Clone, Debug, Serialize)]
pub struct Subproblem {
    /// The fitted ξ (1-based), in column order.
    pub xi: Vec<usize>,
    pub rows: usize,
    /// Condition number of the column-equilibrated regressor matrix.
    pub condition: f64,
    /// The ξ that ended on a bound.
    pub at_bounds: Vec<usize>,
    /// Active-set iterations of the last solve.
    pub iterations: usize,
    pub converged: bool,
    /// Reweighted solves after the first ([`PdWeighting::Acceleration`]).
    pub reweightings: usize,
}

/// Post-fit checks.
#[derive(Clone, Debug, Serialize)]
pub struct PdFitDiagnostics {
    pub samples: usize,
    pub rows: Vec<RowResidual>,
    pub translation: Subproblem,
    pub rotation: Subproblem,
    /// ξ13 / (m g): 1 for a model that hovers at u = 0.
    pub hover_ratio: f64,
    /// The trim input at hover: u_vz = (m g − ξ13) / ξ1, the others 0.
    pub hover_input: [f64; 4],
    /// Eigenvalues [re, im] of ∂f/∂x at hover (x = 0, u = hover_input).
    pub eigenvalues: Vec<[f64; 2]>,
    pub max_real_eigenvalue: f64,
    /// max Re λ ≤ [`STABILITY_TOLERANCE`].
    pub stable: bool,
    pub free_runs: Vec<FreeRun>,
}

impl PdFitDiagnostics {
    /// Every free run stayed within [`FREE_RUN_LIMITS`] (true if none was run).
    pub fn free_runs_bounded(&self) -> bool {
        self.free_runs.iter().all(|r| r.bounded)
    }

    /// A human-readable report.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(s, "samples: {}", self.samples);
        for r in &self.rows {
            let _ = writeln!(
                s,
                "  row {:<5} {} residual RMS {:.4e} (inertial side RMS {:.4e})",
                r.row,
                if r.used { "fit " } else { "unused" },
                r.residual_rms,
                r.inertial_rms
            );
        }
        for (name, p) in [("translation", &self.translation), ("rotation", &self.rotation)] {
            let _ = writeln!(
                s,
                "  {name}: ξ{:?}, {} rows, condition {:.3e}, at bounds {:?}, {} iterations, {} reweightings{}",
                p.xi,
                p.rows,
                p.condition,
                p.at_bounds,
                p.iterations,
                p.reweightings,
                if p.converged { "" } else { " (NOT converged)" }
            );
        }
        let _ = writeln!(
            s,
            "hover ratio ξ13/(m g) = {:.4}; trim u_vz = {:.4} m/s",
            self.hover_ratio, self.hover_input[0]
        );
        let _ = writeln!(
            s,
            "linearisation at hover: max Re λ = {:.3e} ({})",
            self.max_real_eigenvalue,
            if self.stable { "stable" } else { "UNSTABLE" }
        );
        for r in &self.free_runs {
            let _ = writeln!(
                s,
                "free run log {} segment {}: {}/{} steps, {} substeps, {}; RMSE vx vy vz {:.3} {:.3} {:.3} m/s, roll pitch {:.4} {:.4} rad",
                r.log,
                r.segment,
                r.steps,
                r.samples.saturating_sub(1),
                r.substeps,
                if r.bounded { "bounded".to_string() } else { format!("UNBOUNDED: {}", r.failure.as_deref().unwrap_or("")) },
                r.rmse[6],
                r.rmse[7],
                r.rmse[8],
                r.rmse[3],
                r.rmse[4]
            );
        }
        s
    }
}

/// The fitted model: the file (ready to write), the validated model, and the checks.
#[derive(Clone, Debug)]
pub struct PdFit {
    pub file: PdFile,
    pub model: Model,
    pub xi: [f64; 16],
    pub diagnostics: PdFitDiagnostics,
}

impl PdFit {
    /// The model file as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(&self.file).expect("a PdFile serialises");
        s.push('\n');
        s
    }
}

fn validate(o: &PdFitOptions) -> Result<(), PdFitError> {
    let bad = |m: String| Err(PdFitError::Option(m));
    if !(o.mass.is_finite() && o.mass > 0.0) {
        return bad(format!("mass must be finite and positive, got {}", o.mass));
    }
    if !o.gravity.is_finite() {
        return bad(format!("gravity must be finite, got {}", o.gravity));
    }
    match &o.scale {
        PdScale::Inertia(i) => {
            if i.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return bad(format!("inertias must be finite and positive, got {i:?}"));
            }
        }
        PdScale::Gain { xi, value } => {
            if ![2, 3, 4, 5, 6, 8, 9, 10].contains(xi) {
                return bad(format!(
                    "the scale can be fixed by ξ2, ξ3, ξ4, ξ5, ξ6, ξ8, ξ9 or ξ10, not ξ{xi}"
                ));
            }
            if !(value.is_finite() && *value > 0.0) {
                return bad(format!("the fixed ξ{xi} must be finite and positive, got {value}"));
            }
        }
    }
    for (i, &(k, v)) in o.fixed.iter().enumerate() {
        if !(1..=13).contains(&k) {
            return bad(format!(
                "fixed: ξ{k} cannot be held (ξ1..ξ13 can; the inertias are set by the scale)"
            ));
        }
        if o.fixed[..i].iter().any(|&(j, _)| j == k) {
            return bad(format!("fixed: ξ{k} is listed twice"));
        }
        if matches!(o.scale, PdScale::Gain { xi, .. } if xi == k) {
            return bad(format!("fixed: ξ{k} is already the scale"));
        }
        let ok = match k {
            11 => v.abs() < o.mass,
            _ => v >= 0.0,
        };
        if !(v.is_finite() && ok) {
            return bad(format!("fixed: ξ{k} = {v} is outside its bounds (docs/pd-fit.md)"));
        }
    }
    if !(o.min_inertia.is_finite() && o.min_inertia > 0.0) {
        return bad(format!(
            "min_inertia must be finite and positive, got {}",
            o.min_inertia
        ));
    }
    if let Some(tau) = o.max_rate_time_constant {
        if !(tau.is_finite() && tau > 0.0) {
            return bad(format!("max_rate_time_constant must be finite and positive, got {tau}"));
        }
    }
    if !(o.xi11_margin > 0.0 && o.xi11_margin < 1.0) {
        return bad(format!("xi11_margin must be in (0, 1), got {}", o.xi11_margin));
    }
    if let Some(lp) = &o.lowpass {
        lp.validate()?;
    }
    Ok(())
}

/// One segment's samples as the fit sees them: the dataset's own series (borrowed, not copied),
/// or with a low-pass the filtered copies.
struct Samples<'a> {
    x: Cow<'a, [[f64; 12]]>,
    /// Integral-form data (dataset::Targets::Trapezoid): the interval ends; the fit's state is the
    /// interval's midpoint ½(x + x_next) (the midpoint rule), formed as the samples are read.
    x_next: Option<&'a [[f64; 12]]>,
    u: Cow<'a, [[f64; 4]]>,
    dx: Cow<'a, [[f64; 12]]>,
}

impl Samples<'_> {
    fn len(&self) -> usize {
        self.x.len()
    }
}

/// ½(a + b), element by element.
fn midpoint(a: &[f64; 12], b: &[f64; 12]) -> [f64; 12] {
    std::array::from_fn(|i| 0.5 * (a[i] + b[i]))
}

/// Every sample (x, u, ẋ) of `data`, in order.
fn samples<'s>(data: &'s [Samples<'_>]) -> impl Iterator<Item = ([f64; 12], &'s [f64; 4], &'s [f64; 12])> + 's {
    data.iter().flat_map(|s| {
        s.x.iter()
            .zip(s.u.iter())
            .zip(s.dx.iter())
            .enumerate()
            .map(move |(k, ((x, u), dx))| {
                let x = match s.x_next {
                    Some(ends) => midpoint(x, &ends[k]),
                    None => *x,
                };
                (x, u, dx)
            })
    })
}

fn prepare<'a>(dataset: &'a Dataset, options: &PdFitOptions) -> Result<Vec<Samples<'a>>, PdFitError> {
    let mut out = Vec::new();
    for seg in &dataset.segments {
        for (k, ((x, u), dx)) in seg.x.iter().zip(&seg.u).zip(&seg.dx).enumerate() {
            if x.iter().chain(u).chain(dx).any(|v| !v.is_finite()) {
                return Err(PdFitError::NonFinite {
                    log: seg.log,
                    segment: seg.segment,
                    sample: k,
                });
            }
        }
        let n = seg.x.len().min(seg.u.len()).min(seg.dx.len());
        let x_next = (seg.x_next.len() == seg.x.len()).then(|| &seg.x_next[..n]);
        let samples = match &options.lowpass {
            None => Samples {
                x: Cow::Borrowed(&seg.x[..n]),
                x_next,
                u: Cow::Borrowed(&seg.u[..n]),
                dx: Cow::Borrowed(&seg.dx[..n]),
            },
            Some(lp) => {
                // The low-pass runs over whole series: filtered copies (the midpoints first).
                let x: Vec<[f64; 12]> = match x_next {
                    Some(ends) => seg.x[..n].iter().zip(ends).map(|(a, b)| midpoint(a, b)).collect(),
                    None => seg.x[..n].to_vec(),
                };
                Samples {
                    x: Cow::Owned(try_columnwise(&x, |y| lp.try_apply(y, seg.dt))?),
                    x_next: None,
                    u: Cow::Owned(try_columnwise(&seg.u[..n], |y| lp.try_apply(y, seg.dt))?),
                    dx: Cow::Owned(try_columnwise(&seg.dx[..n], |y| lp.try_apply(y, seg.dt))?),
                }
            }
        };
        out.push(samples);
    }
    Ok(out)
}

fn rms(sum_sq: f64, n: usize) -> f64 {
    if n == 0 {
        0.0
    } else {
        (sum_sq / n as f64).sqrt()
    }
}

/// The bounds of ξk (1-based) in the bounded least squares (and in the loop refinement):
/// |ξ11| ≤ (1 − margin) m, inertias ≥ `min_inertia`, a rate damping ≥ I/τ with known inertias
/// ([`PdFitOptions::max_rate_time_constant`]), every other ξ ≥ 0.
pub fn bounds(options: &PdFitOptions, k: usize) -> (f64, f64) {
    let inf = f64::INFINITY;
    let min_damping = match (&options.scale, options.max_rate_time_constant) {
        (PdScale::Inertia(i), Some(tau)) if (8..=10).contains(&k) => i[k - 8] / tau,
        _ => 0.0,
    };
    match k {
        11 => {
            let xi11_max = (1.0 - options.xi11_margin) * options.mass;
            (-xi11_max, xi11_max)
        }
        14..=16 => (options.min_inertia, inf),
        _ => (min_damping, inf),
    }
}

/// Solve one group from its rows folded into `reduction`; `columns` are the ξ of its columns.
fn solve_group(
    reduction: bvls::Reduction,
    columns: &[usize],
    bounds: &impl Fn(usize) -> (f64, f64),
) -> Result<(Vec<f64>, Subproblem), PdFitError> {
    let zero: Vec<usize> = (0..columns.len())
        .filter(|&j| reduction.column_norm(j) == 0.0)
        .map(|j| columns[j])
        .collect();
    if !zero.is_empty() {
        return Err(PdFitError::Unidentifiable { xi: zero });
    }
    let (lo, hi): (Vec<f64>, Vec<f64>) = columns.iter().map(|&k| bounds(k)).unzip();
    let rows = reduction.rows();
    let s = bvls::solve_reduced(reduction, &lo, &hi);
    let report = Subproblem {
        xi: columns.to_vec(),
        rows,
        condition: s.condition,
        at_bounds: (0..columns.len())
            .filter(|&j| s.at_bound[j])
            .map(|j| columns[j])
            .collect(),
        iterations: s.iterations,
        converged: s.converged,
        reweightings: 0,
    };
    Ok((s.theta, report))
}

/// Reweighting stops when the weight parameters (ξ11; ξ12 and the inertias) change by less than this,
/// relative to m or to Ix + Iy + Iz.
const IRLS_TOLERANCE: f64 = 1e-10;
/// Cap on the reweightings of [`PdWeighting::Acceleration`].
const MAX_REWEIGHTINGS: usize = 100;

/// (m I + ξ11 b e3ᵀ)⁻¹ = (I − ξ11 b e3ᵀ / (m + ξ11 b_z)) / m  (Sherman-Morrison).
fn translation_weight(m: f64, xi11: f64, b: &[f64; 3]) -> [[f64; 3]; 3] {
    let c = xi11 / (m + xi11 * b[2]);
    let mut w = [[0.0; 3]; 3];
    for i in 0..3 {
        w[i][i] = 1.0 / m;
        w[i][2] -= c * b[i] / m;
    }
    w
}

/// (M(Ω) + ξ12 e3 e3ᵀ)⁻¹.
fn rotation_weight(omega: &[f64; 3], inertia: &[f64; 3], xi12: f64) -> [[f64; 3]; 3] {
    let mut a = mass_matrix(omega, inertia);
    a[2][2] += xi12;
    let m = nalgebra::Matrix3::from_fn(|i, j| a[i][j]);
    match m.try_inverse() {
        Some(inv) => [0, 1, 2].map(|i| [0, 1, 2].map(|j| inv[(i, j)])),
        None => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// One of the two independent problems: its ξ, the rows it uses, the ξ held fixed.
struct Group<'a, const N: usize> {
    selected: &'a [bool],
    xi: &'a [usize; N],
    fixed: &'a [(usize, f64)],
    reweight: bool,
}

impl<const N: usize> Group<'_, N> {
    /// Bounded least squares over the free ξ of the group, reweighted until `converged` (or once).
    /// The rows are formed from the samples for every solve and folded into R and Qᵀ y as they
    /// come ([`bvls::Reduction`]): neither the design matrix nor per-sample rows are held.
    /// Returns all 16 ξ (only this group's are set) and the report.
    fn solve(
        &self,
        data: &[Samples],
        rows: impl Fn(&[f64; 12], &[f64; 4], &[f64; 12]) -> ([[f64; N]; 3], [f64; 3]),
        bounds: impl Fn(usize) -> (f64, f64),
        weight: impl Fn(&[f64; 12], &[f64; 16]) -> [[f64; 3]; 3],
        converged: impl Fn(&[f64; 16], &[f64; 16]) -> bool,
    ) -> Result<([f64; 16], Subproblem), PdFitError> {
        let fixed_value = |k: usize| self.fixed.iter().find(|(f, _)| *f == k).map(|&(_, v)| v);
        let fixed_column: [Option<f64>; N] = std::array::from_fn(|j| fixed_value(self.xi[j]));
        let free: Vec<usize> = (0..N).filter(|&j| fixed_column[j].is_none()).collect();
        let free_xi: Vec<usize> = free.iter().map(|&j| self.xi[j]).collect();
        let mut current: Option<[f64; 16]> = None;
        let mut reweightings = 0;
        let mut row = vec![0.0; free.len()];
        loop {
            let mut reduction = bvls::Reduction::new(free.len());
            for (x, u, dx) in samples(data) {
                let (ab, yb) = rows(&x, u, dx);
                // Fixed ξ move to the right-hand side.
                let mut rhs = yb;
                for r in 0..3 {
                    for j in 0..N {
                        if let Some(v) = fixed_column[j] {
                            rhs[r] -= ab[r][j] * v;
                        }
                    }
                }
                let w = current.as_ref().map(|c| weight(&x, c));
                for r in 0..3 {
                    if !self.selected[r] {
                        continue;
                    }
                    let y = match &w {
                        None => {
                            for (c, &j) in free.iter().enumerate() {
                                row[c] = ab[r][j];
                            }
                            rhs[r]
                        }
                        Some(w) => {
                            for (c, &j) in free.iter().enumerate() {
                                row[c] = (0..3).map(|k| w[r][k] * ab[k][j]).sum();
                            }
                            (0..3).map(|k| w[r][k] * rhs[k]).sum()
                        }
                    };
                    reduction.push(&row, y);
                }
            }
            let (theta, mut report) = solve_group(reduction, &free_xi, &bounds)?;
            let mut next = [0.0; 16];
            for (&k, v) in free_xi.iter().zip(&theta) {
                next[k - 1] = *v;
            }
            for &k in self.xi {
                if let Some(v) = fixed_value(k) {
                    next[k - 1] = v;
                }
            }
            let done = !self.reweight
                || current.as_ref().is_some_and(|prev| converged(prev, &next))
                || reweightings == MAX_REWEIGHTINGS;
            if done {
                report.reweightings = reweightings;
                return Ok((next, report));
            }
            current = Some(next);
            reweightings += 1;
        }
    }
}

/// Fit ξ1..ξ16 to `dataset`. `name` becomes the model name; `provenance` (e.g. the data files) is
/// kept under `provenance.data` of the file, beside the options and the fit's figures.
pub fn fit(
    dataset: &Dataset,
    options: &PdFitOptions,
    name: &str,
    provenance: serde_json::Value,
) -> Result<PdFit, PdFitError> {
    fit_refined(dataset, options, None, name, provenance).map(|(fit, _)| fit)
}

/// What the loop refinement did ([`fit_refined`]).
#[derive(Clone, Debug)]
pub struct PdRefinement {
    pub options: RefineOptions,
    /// One report per loop of [`refine::PD_LOOPS`] (terms: ("xiK", fitted, refined)).
    pub loops: Vec<LoopRefinement>,
    /// The equation-error fit's model, to fall back on should the refined model fail a later check
    /// (`provenance.loop_refinement.reverted` says so); `None` when no loop was refined.
    pub unrefined: Option<Box<PdFit>>,
}

impl PdRefinement {
    /// `provenance.loop_refinement`: SINDy's record ([`crate::identify::loop_refine`]), the
    /// equation-error fit's ξ of each loop under `equation_error_fit`.
    pub fn record(&self) -> serde_json::Value {
        crate::identify::loop_refine::record(&self.options, &self.loops, "equation_error_fit")
    }
}

/// [`fit`], then, with `refinement` = (integral-form data, options), the attitude loops refined
/// by simulation error ([`refine`]; docs/identification.md "Loop refinement"): the model, its
/// checks and its provenance (`loop_refinement`) are those of the refined ξ.
pub fn fit_refined(
    dataset: &Dataset,
    options: &PdFitOptions,
    refinement: Option<(&Dataset, &RefineOptions)>,
    name: &str,
    provenance: serde_json::Value,
) -> Result<(PdFit, Option<PdRefinement>), PdFitError> {
    validate(options)?;
    if dataset.is_empty() {
        return Err(PdFitError::Empty);
    }
    let data = prepare(dataset, options)?;
    let (m, g) = (options.mass, options.gravity);
    let rows = options.rows;

    let mut fixed: Vec<(usize, f64)> = options.fixed.clone();
    match &options.scale {
        PdScale::Inertia(i) => fixed.extend([(14, i[0]), (15, i[1]), (16, i[2])]),
        PdScale::Gain { xi, value } => fixed.push((*xi, *value)),
    }
    let bounds = |k: usize| bounds(options, k);
    let reweight = options.weighting == PdWeighting::Acceleration;
    let translation_group = Group {
        selected: &rows[..3],
        xi: &TRANSLATION_XI,
        fixed: &fixed,
        reweight,
    };
    let (xt, translation) = translation_group.solve(
        &data,
        |x, u, dx| {
            let t = translation_rows(x, u, dx, m, g);
            (t.map(|(a, _)| a), t.map(|(_, y)| y))
        },
        bounds,
        |x, xi| translation_weight(m, xi[10], &thrust_axis(x[3], x[4], x[5])),
        |prev, next| (prev[10] - next[10]).abs() <= IRLS_TOLERANCE * m,
    )?;
    let rotation_group = Group {
        selected: &rows[3..],
        xi: &ROTATION_XI,
        fixed: &fixed,
        reweight,
    };
    let (xr, rotation) = rotation_group.solve(
        &data,
        |x, u, dx| (rotation_rows(x, u, dx), [0.0; 3]),
        bounds,
        |x, xi| rotation_weight(&[x[3], x[4], x[5]], &[xi[13], xi[14], xi[15]], xi[11]),
        |prev, next| {
            let scale: f64 = next[13..16].iter().sum();
            (11..16).all(|j| (prev[j] - next[j]).abs() <= IRLS_TOLERANCE * scale)
        },
    )?;
    let mut xi = [0.0; 16];
    for k in TRANSLATION_XI {
        xi[k - 1] = xt[k - 1];
    }
    for k in ROTATION_XI {
        xi[k - 1] = xr[k - 1];
    }
    for (j, (gain, by)) in CHANNEL_GAIN_XI.iter().enumerate() {
        if options.unit_gain[j] {
            xi[gain - 1] = xi[by - 1];
        }
    }

    let build = |xi: [f64; 16], record: Option<serde_json::Value>| -> Result<PdFit, PdFitError> {
        assemble(
            dataset,
            &data,
            options,
            xi,
            (translation.clone(), rotation.clone()),
            name,
            provenance.clone(),
            record,
        )
    };
    let Some((interval, refine_options)) = refinement else {
        return Ok((build(xi, None)?, None));
    };
    let fitted = xi;
    let lower: [f64; 16] = std::array::from_fn(|i| bounds(i + 1).0);
    let skip = [1, 2].map(|j| options.unit_gain[j].then_some("the command channel was not excited (unit static gain)"));
    let loops = refine::refine(&mut xi, &lower, interval, skip, refine_options);
    let mut r = PdRefinement {
        options: refine_options.clone(),
        loops,
        unrefined: None,
    };
    let record = r.record();
    if r.loops.iter().any(|l| l.kept) {
        let mut reverted = record.clone();
        reverted["reverted"] = "the refined model failed a later check: the equation-error fit's xi".into();
        r.unrefined = Some(Box::new(build(fitted, Some(reverted))?));
    }
    Ok((build(xi, Some(record))?, Some(r)))
}

/// The model file, the model and its checks at ξ (`loop_refinement`: the refinement's record for
/// the provenance).
#[allow(clippy::too_many_arguments)]
fn assemble(
    dataset: &Dataset,
    data: &[Samples],
    options: &PdFitOptions,
    xi: [f64; 16],
    (translation, rotation): (Subproblem, Subproblem),
    name: &str,
    provenance: serde_json::Value,
    loop_refinement: Option<serde_json::Value>,
) -> Result<PdFit, PdFitError> {
    let samples: usize = data.iter().map(Samples::len).sum();
    let (m, g) = (options.mass, options.gravity);
    let row_stats = residuals(data, options, &xi);
    let mut file = PdFile {
        format: FORMAT.to_string(),
        kind: "pd".to_string(),
        name: name.to_string(),
        states: None,
        inputs: None,
        provenance: serde_json::Value::Null,
        mass: m,
        gravity: g,
        xi: serde_json::Value::from(xi.to_vec()),
    };
    let text = serde_json::to_string(&file).expect("a PdFile serialises");
    let model = parse(&text, name)?;

    let c = checks::run(&model, dataset, options, &xi);
    let diagnostics = PdFitDiagnostics {
        samples,
        rows: row_stats,
        translation,
        rotation,
        hover_ratio: c.hover_ratio,
        hover_input: c.hover_input,
        eigenvalues: c.eigenvalues,
        max_real_eigenvalue: c.max_real_eigenvalue,
        stable: c.stable,
        free_runs: c.free_runs,
    };

    file.provenance = serde_json::json!({
        "method": "uavgen PD fit: bounded least squares of the Euler-Lagrange residual, linear in xi (docs/pd-fit.md)",
        "data": provenance,
        "options": options,
        "samples": samples,
        "residual_rms": diagnostics.rows.iter().map(|r| (r.row.to_string(), serde_json::json!(r.residual_rms))).collect::<serde_json::Map<_, _>>(),
        "inertial_rms": diagnostics.rows.iter().map(|r| (r.row.to_string(), serde_json::json!(r.inertial_rms))).collect::<serde_json::Map<_, _>>(),
        "condition": { "translation": diagnostics.translation.condition, "rotation": diagnostics.rotation.condition },
        "at_bounds": diagnostics.translation.at_bounds.iter().chain(&diagnostics.rotation.at_bounds).map(|k| format!("xi{k}")).collect::<Vec<_>>(),
        "hover_ratio": diagnostics.hover_ratio,
        "max_real_eigenvalue_at_hover": diagnostics.max_real_eigenvalue,
        "stable_at_hover": diagnostics.stable,
        "free_runs_bounded": diagnostics.free_runs_bounded(),
    });
    if let Some(record) = loop_refinement {
        file.provenance["loop_refinement"] = record;
    }
    let mut model = model;
    model.provenance = file.provenance.clone();
    Ok(PdFit {
        file,
        model,
        xi,
        diagnostics,
    })
}

/// Residual and inertial-side RMS of each row at ξ.
fn residuals(data: &[Samples], options: &PdFitOptions, xi: &[f64; 16]) -> Vec<RowResidual> {
    let mut sum = [0.0; 6];
    let mut inertial = [0.0; 6];
    let mut n = 0;
    let t_xi = TRANSLATION_XI.map(|k| xi[k - 1]);
    let r_xi = ROTATION_XI.map(|k| xi[k - 1]);
    for (x, u, dx) in samples(data) {
        n += 1;
        for (r, (a, y)) in translation_rows(&x, u, dx, options.mass, options.gravity)
            .iter()
            .enumerate()
        {
            let pred: f64 = a.iter().zip(&t_xi).map(|(a, t)| a * t).sum();
            sum[r] += (y - pred).powi(2);
            inertial[r] += y * y;
        }
        for (r, a) in rotation_rows(&x, u, dx).iter().enumerate() {
            let total: f64 = a.iter().zip(&r_xi).map(|(a, t)| a * t).sum();
            // Columns 8..12 (ξ12, inertias) carry minus the inertial side.
            let lhs: f64 = -(8..12).map(|j| a[j] * r_xi[j]).sum::<f64>();
            sum[3 + r] += total * total;
            inertial[3 + r] += lhs * lhs;
        }
    }
    (0..6)
        .map(|r| RowResidual {
            row: ROW_NAMES[r],
            used: options.rows[r],
            residual_rms: rms(sum[r], n),
            inertial_rms: rms(inertial[r], n),
        })
        .collect()
}
