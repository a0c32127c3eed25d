//! Sparse regression: STLSQ and SR3 (L0, L1) with PySINDy 2.x semantics.
//!
//! Both solve Ẏ ≈ Θ Ξ for all targets at once, exactly as `pysindy.optimizers.STLSQ` and
//! `pysindy.optimizers.SR3` do in `BaseOptimizer.fit` (PySINDy 2.1.0):
//!
//! 1. if `normalize_columns`, every column of Θ is divided by its 2-norm;
//! 2. the initial guess is the (minimum-norm) least-squares solution `lstsq(Θ, Ẏ)` (STLSQ looks
//!    only at its non-zero pattern, taken from the normal equations: [`Prepared`]);
//! 3. the optimiser's `_reduce` runs (see [`stlsq`] and [`sr3`] in the docs of [`Optimizer`]);
//! 4. the support is `|ξ| > 1e-14`; with `unbias` the support is refitted by plain least squares;
//! 5. with `normalize_columns`, the coefficients are divided by the column norms (back to the units of Θ).
//!
//! The thresholds therefore act on the coefficients of the *normalised* columns when
//! `normalize_columns` is set. See `docs/sindy.md`.

use super::accumulate::{of_matrix, LsData, CHUNK_ROWS};
use nalgebra::{DMatrix, DVector};
use serde_json::{json, Value};

/// The regulariser R of SR3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Regularizer {
    /// R(v) = ‖v‖₀; prox = hard thresholding at √(2 λ ν).
    L0,
    /// R(v) = ‖v‖₁; prox = soft thresholding at λ ν.
    L1,
}

impl Regularizer {
    pub fn name(self) -> &'static str {
        match self {
            Regularizer::L0 => "L0",
            Regularizer::L1 => "L1",
        }
    }
}

/// A sparse-regression algorithm and its settings (PySINDy 2.x parameter names).
#[derive(Clone, Debug, PartialEq)]
pub enum Optimizer {
    /// Sequentially thresholded least squares (`ps.STLSQ`): repeat { ridge regression
    /// min ‖y − Θ_S ξ‖² + α‖ξ‖² on the current support S; drop |ξ| < threshold } until the support
    /// stops changing (or nothing was dropped in the first pass), at most `max_iter` passes.
    Stlsq {
        threshold: f64,
        alpha: f64,
        max_iter: usize,
        unbias: bool,
    },
    /// Sparse relaxed regularised regression (`ps.SR3`): minimises
    /// ½‖Y − Θ W‖² + λ R(V) + (1/2ν)‖W − V‖² by alternating
    /// W ← (ΘᵀΘ + I/ν)⁻¹ (ΘᵀY + V/ν), V ← prox_{λν R}(W), from V = lstsq(Θ, Y), until
    /// ‖V_k − V_{k−1}‖_F / ν < tol or `max_iter` iterations. The result is V.
    Sr3 {
        regularizer: Regularizer,
        /// λ (`reg_weight_lam`).
        reg_weight_lam: f64,
        /// ν (`relax_coeff_nu`).
        relax_coeff_nu: f64,
        max_iter: usize,
        tol: f64,
        unbias: bool,
    },
}

impl Optimizer {
    /// `ps.STLSQ(threshold=threshold)` with PySINDy's other defaults: alpha 0.05, max_iter 20, unbias.
    pub fn stlsq(threshold: f64) -> Self {
        Optimizer::Stlsq {
            threshold,
            alpha: 0.05,
            max_iter: 20,
            unbias: true,
        }
    }

    /// `ps.SR3(reg_weight_lam=lambda, regularizer=..)` with PySINDy's defaults: ν = 1, max_iter 30,
    /// tol 1e-5, no unbiasing.
    pub fn sr3(regularizer: Regularizer, reg_weight_lam: f64) -> Self {
        Optimizer::Sr3 {
            regularizer,
            reg_weight_lam,
            relax_coeff_nu: 1.0,
            max_iter: 30,
            tol: 1e-5,
            unbias: false,
        }
    }

    /// The sparsity parameter that a sweep varies: `threshold` (STLSQ) or `reg_weight_lam` (SR3).
    pub fn sparsity(&self) -> f64 {
        match self {
            Optimizer::Stlsq { threshold, .. } => *threshold,
            Optimizer::Sr3 { reg_weight_lam, .. } => *reg_weight_lam,
        }
    }

    /// The same optimiser with another sparsity parameter.
    pub fn with_sparsity(&self, value: f64) -> Self {
        let mut o = self.clone();
        match &mut o {
            Optimizer::Stlsq { threshold, .. } => *threshold = value,
            Optimizer::Sr3 { reg_weight_lam, .. } => *reg_weight_lam = value,
        }
        o
    }

    /// Name of the sparsity parameter (`threshold` or `reg_weight_lam`).
    pub fn sparsity_name(&self) -> &'static str {
        match self {
            Optimizer::Stlsq { .. } => "threshold",
            Optimizer::Sr3 { .. } => "reg_weight_lam",
        }
    }

    /// The settings as JSON, with PySINDy's parameter names.
    pub fn to_json(&self) -> Value {
        match self {
            Optimizer::Stlsq {
                threshold,
                alpha,
                max_iter,
                unbias,
            } => json!({
                "name": "STLSQ", "threshold": threshold, "alpha": alpha, "max_iter": max_iter, "unbias": unbias
            }),
            Optimizer::Sr3 {
                regularizer,
                reg_weight_lam,
                relax_coeff_nu,
                max_iter,
                tol,
                unbias,
            } => json!({
                "name": "SR3", "regularizer": regularizer.name(), "reg_weight_lam": reg_weight_lam,
                "relax_coeff_nu": relax_coeff_nu, "max_iter": max_iter, "tol": tol, "unbias": unbias
            }),
        }
    }

    /// Reject settings PySINDy rejects (and non-finite ones).
    pub fn validate(&self) -> Result<(), OptimizerError> {
        let bad = |m: String| Err(OptimizerError::Settings(m));
        match *self {
            Optimizer::Stlsq {
                threshold,
                alpha,
                max_iter,
                ..
            } => {
                if !(threshold.is_finite() && threshold >= 0.0) {
                    return bad(format!("STLSQ threshold must be finite and >= 0, got {threshold}"));
                }
                if !(alpha.is_finite() && alpha >= 0.0) {
                    return bad(format!("STLSQ alpha must be finite and >= 0, got {alpha}"));
                }
                if max_iter == 0 {
                    return bad("STLSQ max_iter must be positive".into());
                }
            }
            Optimizer::Sr3 {
                reg_weight_lam,
                relax_coeff_nu,
                max_iter,
                tol,
                ..
            } => {
                if !(reg_weight_lam.is_finite() && reg_weight_lam >= 0.0) {
                    return bad(format!(
                        "SR3 reg_weight_lam must be finite and >= 0, got {reg_weight_lam}"
                    ));
                }
                if !(relax_coeff_nu.is_finite() && relax_coeff_nu > 0.0) {
                    return bad(format!(
                        "SR3 relax_coeff_nu must be finite and > 0, got {relax_coeff_nu}"
                    ));
                }
                if !(tol.is_finite() && tol > 0.0) {
                    return bad(format!("SR3 tol must be finite and > 0, got {tol}"));
                }
                if max_iter == 0 {
                    return bad("SR3 max_iter must be positive".into());
                }
            }
        }
        Ok(())
    }
}

/// Why a regression could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptimizerError {
    #[error("invalid optimiser settings: {0}")]
    Settings(String),
    #[error("library and targets have different sample counts ({0} and {1})")]
    Shape(usize, usize),
    #[error("no samples")]
    Empty,
    #[error("library column {0} is all zero: it cannot be normalised")]
    ZeroColumn(usize),
    #[error("non-finite value in the library or the targets")]
    NonFinite,
}

/// Result of one regression.
#[derive(Clone, Debug)]
pub struct Regression {
    /// Ξ as PySINDy's `coef_`: one row per target, one column per library column, in the units of Θ.
    pub coef: DMatrix<f64>,
    /// Passes of STLSQ / iterations of SR3 that ran.
    pub iterations: usize,
    /// Whether the stopping rule was met before `max_iter` (PySINDy warns otherwise).
    pub converged: bool,
}

/// Fit Ẏ ≈ Θ Ξᵀ (`theta`: samples × features, `y`: samples × targets) like PySINDy's
/// `optimizer.fit(theta, y)`.
pub fn regress(
    theta: &DMatrix<f64>,
    y: &DMatrix<f64>,
    optimizer: &Optimizer,
    normalize_columns: bool,
) -> Result<Regression, OptimizerError> {
    optimizer.validate()?;
    Prepared::new(theta, y, normalize_columns)?.regress(optimizer)
}

/// What every regression on one (Θ, Ẏ) shares, computed once: the normal equations of the
/// normalised Θ (ΘᵀΘ and ΘᵀẎ) and its column norms, the triangular factor of Θ and Qᵀ Ẏ (every
/// least-squares solve), the least-squares initial guess (its non-zero pattern for STLSQ), and the
/// unbiasing refits by support.
///
/// It is built from an [`LsData`] (the rows of [Θ | Ẏ] gathered chunk by chunk: the library is
/// never held as an N × p matrix; [`super::accumulate`]), or from matrices ([`Prepared::new`]).
/// A sparsity sweep regresses the same data with many thresholds; several thresholds give a row
/// the same support, hence the same unbiased refit, computed once. STLSQ takes its initial
/// guess's non-zero pattern from the normal equations ([`Prepared::init_pattern`], the same
/// pattern).
pub struct Prepared {
    /// Samples.
    n: usize,
    norms: DVector<f64>,
    normalize_columns: bool,
    /// The least-squares initial guess: SR3 starts from it; STLSQ only compares its non-zero
    /// pattern with the first pass's (see [`Prepared::init_pattern`]). Computed when first needed.
    init: Option<DMatrix<f64>>,
    /// STLSQ's view of the initial guess: its non-zero pattern.
    pattern: Option<DMatrix<f64>>,
    gram: DMatrix<f64>,
    xty: DMatrix<f64>,
    /// The unbiased refit of target t on a support (the normalised columns' coefficients).
    unbiased: std::collections::HashMap<(usize, Vec<usize>), Vec<f64>>,
    /// The R factor of the normalised library (p × p) and the first p rows of Qᵀ Ẏ (see
    /// [`Prepared::refit`]).
    r: DMatrix<f64>,
    qty: DMatrix<f64>,
}

impl Prepared {
    /// Check the data and compute the shared parts (see the type's documentation).
    pub fn new(theta: &DMatrix<f64>, y: &DMatrix<f64>, normalize_columns: bool) -> Result<Self, OptimizerError> {
        if theta.nrows() != y.nrows() {
            return Err(OptimizerError::Shape(theta.nrows(), y.nrows()));
        }
        let both = DMatrix::from_fn(theta.nrows(), theta.ncols() + y.ncols(), |i, j| {
            if j < theta.ncols() {
                theta[(i, j)]
            } else {
                y[(i, j - theta.ncols())]
            }
        });
        Self::from_data(&of_matrix(&both, CHUNK_ROWS), theta.ncols(), normalize_columns)
    }

    /// The shared parts of the data gathered in `data`: [Θ | Ẏ], the first `p` columns Θ.
    pub fn from_data(data: &LsData, p: usize, normalize_columns: bool) -> Result<Self, OptimizerError> {
        if data.n == 0 {
            return Err(OptimizerError::Empty);
        }
        if !data.finite {
            return Err(OptimizerError::NonFinite);
        }
        let m = data.gram.nrows();
        let t = m - p;
        let mut norms = DVector::from_element(p, 1.0);
        if normalize_columns {
            for j in 0..p {
                let n = data.gram[(j, j)].sqrt();
                if n == 0.0 || !data.nonzero[j] {
                    return Err(OptimizerError::ZeroColumn(j));
                }
                norms[j] = n;
            }
        }
        let gram = DMatrix::from_fn(p, p, |i, j| data.gram[(i, j)] / norms[i] / norms[j]);
        let xty = DMatrix::from_fn(p, t, |i, c| data.gram[(i, p + c)] / norms[i]);
        let r = DMatrix::from_fn(p, p, |i, j| data.r[(i, j)] / norms[j]);
        let qty = DMatrix::from_fn(p, t, |i, c| data.r[(i, p + c)]);
        Ok(Self {
            n: data.n,
            norms,
            normalize_columns,
            init: None,
            pattern: None,
            gram,
            xty,
            unbiased: std::collections::HashMap::new(),
            r,
            qty,
        })
    }

    /// The least-squares refit of target `t` on the normalised columns `support` (coefficients
    /// in the support's order): what `lstsq(x_S, y_t)` solves. With Θ = Q R (gathered chunk by
    /// chunk, [`super::accumulate`]), ‖Θ_S w − y‖² = ‖R_S w − (Qᵀy)₁..ₚ‖² + a constant, so each
    /// support is solved on the p × k columns S of R instead of the N × k columns of Θ: the same
    /// problem, its rank test and fallback on the same numbers (R_S has Θ_S's singular values; the
    /// tolerance is taken at N rows as `lstsq`'s), equal up to round-off.
    fn refit(&mut self, t: usize, support: &[usize]) -> Vec<f64> {
        let p = self.r.nrows();
        let rs = self.r.select_columns(support);
        let rhs = DMatrix::from_column_slice(p, 1, self.qty.column(t).as_slice());
        lstsq_at(&rs, &rhs, self.n).column(0).iter().copied().collect()
    }

    /// The initial guess lstsq(x, y), features × targets (on R and Qᵀ Ẏ).
    fn init(&mut self) -> &DMatrix<f64> {
        let (r, qty, n) = (&self.r, &self.qty, self.n);
        self.init.get_or_insert_with(|| lstsq_at(r, qty, n))
    }

    /// What STLSQ needs of the initial guess: which entries are non-zero. `STLSQ._reduce` uses the
    /// guess only to ask whether the first pass changed the support (its history's first entry),
    /// so the pattern is taken from the least-squares solution of the normal equations already at
    /// hand (a Cholesky solve, p³/3 flops) instead of the QR factorisation of the N × p library.
    /// The two solve the same problem; an entry of a least-squares solution is exactly zero only
    /// for a target column that is exactly zero, where both give zeros. And when no entry of the
    /// guess is zero the pattern cannot change the result: the first pass either keeps every
    /// term (converged either way) or drops one (then it differs from the guess's pattern either way).
    fn init_pattern(&mut self) -> &DMatrix<f64> {
        let (gram, xty) = (&self.gram, &self.xty);
        self.pattern.get_or_insert_with(|| solve_spd(gram.clone(), xty))
    }

    /// The regression with `optimizer` (what [`regress`] returns for the same data).
    pub fn regress(&mut self, optimizer: &Optimizer) -> Result<Regression, OptimizerError> {
        optimizer.validate()?;
        let p = self.gram.ncols();
        let (mut coef, iterations, converged, unbias) = match *optimizer {
            Optimizer::Stlsq {
                threshold,
                alpha,
                max_iter,
                unbias,
            } => {
                self.init_pattern();
                let init = self.pattern.as_ref().expect("computed above");
                let (c, it, conv) = stlsq(&self.gram, &self.xty, init, threshold, alpha, max_iter);
                (c, it, conv, unbias)
            }
            Optimizer::Sr3 {
                regularizer,
                reg_weight_lam,
                relax_coeff_nu,
                max_iter,
                tol,
                unbias,
            } => {
                self.init();
                let init = self.init.as_ref().expect("computed above");
                let (c, it, conv) = sr3(
                    &self.gram,
                    &self.xty,
                    init,
                    regularizer,
                    reg_weight_lam,
                    relax_coeff_nu,
                    max_iter,
                    tol,
                );
                (c, it, conv, unbias)
            }
        };
        if unbias {
            for t in 0..coef.nrows() {
                let support: Vec<usize> = (0..p).filter(|&j| coef[(t, j)].abs() > 1e-14).collect();
                let key = (t, support);
                if !self.unbiased.contains_key(&key) {
                    let mut row = vec![0.0; p];
                    if !key.1.is_empty() {
                        let w = self.refit(t, &key.1);
                        for (k, &j) in key.1.iter().enumerate() {
                            row[j] = w[k];
                        }
                    }
                    self.unbiased.insert(key.clone(), row);
                }
                let row = &self.unbiased[&key];
                for j in 0..p {
                    coef[(t, j)] = row[j];
                }
            }
        }
        if self.normalize_columns {
            for j in 0..p {
                coef.column_mut(j).unscale_mut(self.norms[j]);
            }
        }
        Ok(Regression {
            coef,
            iterations,
            converged,
        })
    }
}

/// Minimum-norm least squares `numpy.linalg.lstsq(a, b, rcond=None)`: features × targets.
/// Householder QR when `a` has full column rank (the solution is then unique), SVD otherwise.
pub fn lstsq(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    lstsq_at(a, b, a.nrows())
}

/// [`lstsq`] with its rank tolerance (rcond = ε · max(rows, p)) taken at `rows` rows: for a
/// triangular factor R_S of an N-row matrix, `lstsq_at(R_S, Qᵀb, N)` decides rank as `lstsq` on
/// the N-row matrix does.
fn lstsq_at(a: &DMatrix<f64>, b: &DMatrix<f64>, rows: usize) -> DMatrix<f64> {
    let (n, p) = a.shape();
    let rcond = f64::EPSILON * rows.max(n).max(p) as f64;
    if n >= p && p > 0 {
        let qr = a.clone().qr();
        let r = qr.r();
        let dmax = (0..p).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
        // A diagonal of R far below its largest entry means (near) rank deficiency: use the SVD.
        if (0..p).all(|i| r[(i, i)].abs() > dmax * rcond * 1e3) {
            let mut qtb = b.clone();
            qr.q_tr_mul(&mut qtb);
            let rp = r.view((0, 0), (p, p)).into_owned();
            let rhs = qtb.rows(0, p).into_owned();
            if let Some(sol) = rp.solve_upper_triangular(&rhs) {
                return sol;
            }
        }
    }
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
    svd.solve(b, smax * rcond)
        .unwrap_or_else(|_| DMatrix::zeros(p, b.ncols()))
}

/// Solve the symmetric positive (semi)definite system `a w = b` like `scipy.linalg.solve(assume_a="pos")`;
/// falls back to a pseudo-inverse if the Cholesky factorisation fails.
fn solve_spd(a: DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    match a.clone().cholesky() {
        Some(ch) => ch.solve(b),
        None => {
            let svd = a.svd(true, true);
            let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
            svd.solve(b, smax * f64::EPSILON * b.nrows().max(1) as f64)
                .unwrap_or_else(|_| DMatrix::zeros(b.nrows(), b.ncols()))
        }
    }
}

/// `STLSQ._reduce` on the normal equations (`gram` = XᵀX, `xty` = XᵀY). `init`: features × targets.
/// Returns targets × features.
fn stlsq(
    gram: &DMatrix<f64>,
    xty: &DMatrix<f64>,
    init: &DMatrix<f64>,
    threshold: f64,
    alpha: f64,
    max_iter: usize,
) -> (DMatrix<f64>, usize, bool) {
    let p = gram.ncols();
    let t = xty.ncols();
    let mut ind = vec![vec![true; p]; t];
    let n_selected0 = t * p;
    // Non-zero pattern of the previous history entry (the lstsq guess first).
    let pattern = |m: &DMatrix<f64>, transposed: bool| -> Vec<bool> {
        let mut v = Vec::with_capacity(t * p);
        for i in 0..t {
            for j in 0..p {
                v.push(if transposed { m[(j, i)] } else { m[(i, j)] } != 0.0);
            }
        }
        v
    };
    let mut last_nonzero = pattern(init, true);
    let mut optvar = DMatrix::zeros(t, p);
    let mut iterations = 0;
    let mut converged = false;
    for _ in 0..max_iter {
        if ind.iter().all(|r| r.iter().all(|&b| !b)) {
            optvar = DMatrix::zeros(t, p);
            converged = true;
            break;
        }
        optvar = DMatrix::zeros(t, p);
        for i in 0..t {
            let sel: Vec<usize> = (0..p).filter(|&j| ind[i][j]).collect();
            if sel.is_empty() {
                continue;
            }
            let k = sel.len();
            let mut a = DMatrix::zeros(k, k);
            let mut b = DMatrix::zeros(k, 1);
            for (r, &jr) in sel.iter().enumerate() {
                for (c, &jc) in sel.iter().enumerate() {
                    a[(r, c)] = gram[(jr, jc)];
                }
                a[(r, r)] += alpha;
                b[(r, 0)] = xty[(jr, i)];
            }
            let w = solve_spd(a, &b);
            for (r, &j) in sel.iter().enumerate() {
                let c = w[(r, 0)];
                if c.abs() >= threshold {
                    optvar[(i, j)] = c;
                    ind[i][j] = true;
                } else {
                    ind[i][j] = false;
                }
            }
        }
        iterations += 1;
        let nonzero = pattern(&optvar, false);
        let count: usize = ind.iter().map(|r| r.iter().filter(|&&b| b).count()).sum();
        let no_change = nonzero == last_nonzero;
        last_nonzero = nonzero;
        if count == n_selected0 || no_change {
            converged = true;
            break;
        }
    }
    (optvar, iterations, converged)
}

/// `SR3._reduce` (no trimming) on the normal equations (`gram` = XᵀX, `xty` = XᵀY). `init`: features × targets. Returns targets × features.
#[allow(clippy::too_many_arguments)]
fn sr3(
    gram: &DMatrix<f64>,
    xty: &DMatrix<f64>,
    init: &DMatrix<f64>,
    regularizer: Regularizer,
    lam: f64,
    nu: f64,
    max_iter: usize,
    tol: f64,
) -> (DMatrix<f64>, usize, bool) {
    let p = gram.ncols();
    let mut a = gram.clone();
    for j in 0..p {
        a[(j, j)] += 1.0 / nu;
    }
    let chol = a.clone().cholesky();
    let weight = lam * nu;
    let prox = |v: f64| -> f64 {
        match regularizer {
            Regularizer::L0 => {
                if v.abs() > (2.0 * weight).sqrt() {
                    v
                } else {
                    0.0
                }
            }
            Regularizer::L1 => v.signum() * (v.abs() - weight).max(0.0),
        }
    };
    let mut sparse = init.clone();
    let mut iterations = 0;
    let mut converged = false;
    for _ in 0..max_iter {
        let rhs = xty + &sparse / nu;
        let full = match &chol {
            Some(c) => c.solve(&rhs),
            None => solve_spd(a.clone(), &rhs),
        };
        let next = full.map(prox);
        iterations += 1;
        let err = (&next - &sparse).norm() / nu;
        sparse = next;
        if err < tol {
            converged = true;
            break;
        }
    }
    (sparse.transpose(), iterations, converged)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Θ with unit-norm columns.
    fn normalised(theta: &DMatrix<f64>) -> DMatrix<f64> {
        let mut x = theta.clone();
        for mut c in x.column_iter_mut() {
            let n = c.norm();
            c.unscale_mut(n);
        }
        x
    }

    /// The unbiased refits on one QR of the library are `lstsq` on the support's columns up to
    /// round-off, also where the support is rank deficient (a repeated column: the minimum-norm
    /// solution by the SVD fallback on both ways).
    #[test]
    fn refits_on_one_qr_are_lstsq_on_the_support() {
        let n = 300;
        let theta = DMatrix::from_fn(n, 7, |k, j| {
            let t = k as f64 * 0.03;
            match j {
                0 => 1.0,
                1 => t.sin(),
                2 => (1.7 * t).cos(),
                3 => t.sin() * (0.4 * t).cos(),
                4 => t.sin(),
                5 => (0.2 * t).sin() + 0.02 * (k % 7) as f64,
                _ => t.cos().powi(3),
            }
        });
        let y = DMatrix::from_fn(n, 2, |k, c| {
            let t = k as f64 * 0.03;
            let noise = 0.01 * (((k * 7919 + c * 31) % 97) as f64 / 97.0 - 0.5);
            (1.0 + c as f64) * t.sin() - 0.5 * (1.7 * t).cos() + 0.2 * (0.2 * t).sin() + noise
        });
        let mut prepared = Prepared::new(&theta, &y, true).unwrap();
        let x = normalised(&theta);
        for support in [vec![1], vec![1, 2], vec![0, 2, 5, 6], vec![1, 3, 4], (0..7).collect()] {
            for t in 0..2 {
                let xs = x.select_columns(&support);
                let ys = DMatrix::from_column_slice(n, 1, y.column(t).as_slice());
                let want = lstsq(&xs, &ys);
                let got = prepared.refit(t, &support);
                let scale = want.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
                for (k, g) in got.iter().enumerate() {
                    assert!(
                        (g - want[(k, 0)]).abs() < 1e-9 * scale,
                        "{support:?} {t}: {got:?} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn lstsq_matches_normal_equations() {
        let a = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0, 1.0, 3.0]);
        let b = DMatrix::from_row_slice(4, 1, &[1.0, 3.0, 5.0, 7.0]);
        let w = lstsq(&a, &b);
        assert!((w[(0, 0)] - 1.0).abs() < 1e-12 && (w[(1, 0)] - 2.0).abs() < 1e-12);
    }

    /// A sweep on one `Prepared` (shared normal equations, cached unbiased refits) gives every
    /// value the regression a fresh `regress` gives, bit for bit; STLSQ and SR3.
    #[test]
    fn a_prepared_sweep_is_fresh_regressions() {
        let n = 200;
        let theta = DMatrix::from_fn(n, 6, |k, j| {
            let t = k as f64 * 0.05;
            match j {
                0 => 1.0,
                1 => t.sin(),
                2 => (2.0 * t).cos(),
                3 => t.sin() * t.cos(),
                4 => (0.3 * t).sin() + 0.01 * (k % 5) as f64,
                _ => t.sin().powi(3),
            }
        });
        let y = DMatrix::from_fn(n, 2, |k, c| {
            let noise = 0.01 * (((k * 7919 + c * 31) % 97) as f64 / 97.0 - 0.5);
            if c == 0 {
                2.0 * theta[(k, 1)] - 0.5 * theta[(k, 2)] + noise
            } else {
                0.3 * theta[(k, 0)] + 1.5 * theta[(k, 3)] + 0.05 * theta[(k, 4)] + noise
            }
        });
        let mut prepared = Prepared::new(&theta, &y, true).unwrap();
        for opt in [Optimizer::stlsq(0.1), Optimizer::sr3(Regularizer::L0, 0.1)] {
            for value in [0.0, 0.01, 0.05, 0.1, 0.5, 1.0, 0.05] {
                let o = opt.with_sparsity(value);
                let a = prepared.regress(&o).unwrap();
                let b = regress(&theta, &y, &o, true).unwrap();
                assert!(a
                    .coef
                    .iter()
                    .zip(b.coef.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
                assert_eq!((a.iterations, a.converged), (b.iterations, b.converged));
            }
        }
        // STLSQ from the QR least-squares guess (PySINDy's) and from the normal equations' pattern
        // reaches the same coefficients in the same passes.
        let qr_guess = lstsq(&normalised(&theta), &y);
        let pattern = prepared.init_pattern().clone();
        for threshold in [0.0, 0.01, 0.05, 0.1, 0.5, 1.0, 5.0] {
            let a = stlsq(&prepared.gram, &prepared.xty, &qr_guess, threshold, 1e-3, 20);
            let b = stlsq(&prepared.gram, &prepared.xty, &pattern, threshold, 1e-3, 20);
            assert!(a.0.iter().zip(b.0.iter()).all(|(x, y)| x.to_bits() == y.to_bits()));
            assert_eq!((a.1, a.2), (b.1, b.2));
        }
        // STLSQ finds the first row's two terms.
        let r = prepared.regress(&Optimizer::stlsq(0.5)).unwrap();
        assert!(
            (r.coef[(0, 1)] - 2.0).abs() < 0.01 && (r.coef[(0, 2)] + 0.5).abs() < 0.01,
            "{}",
            r.coef
        );
    }

    #[test]
    fn prox_signs() {
        // L1 soft thresholding shrinks toward zero; np.sign(0) = 0.
        let x = DMatrix::from_row_slice(3, 1, &[1.0, 0.0, 0.0]);
        let y = DMatrix::from_row_slice(3, 1, &[2.0, 0.0, 0.0]);
        let r = regress(
            &x.columns(0, 1).into_owned(),
            &y,
            &Optimizer::sr3(Regularizer::L1, 0.5),
            false,
        )
        .unwrap();
        assert!(r.coef[(0, 0)] > 0.0 && r.coef[(0, 0)] < 2.0);
    }
}
