//! Stage-wise box QP of one RTI step by a primal-dual interior-point method (Mehrotra
//! predictor-corrector) whose Newton systems are solved by a Riccati recursion over the N stages:
//!
//!   min  ½ Σₖ₌₀ᴺ (eₖ + xₖ)ᵀ Wₖ (eₖ + xₖ) + ½ Σₖ₌₀ᴺ⁻¹ [(ūₖ + vₖ)ᵀ R (ūₖ + vₖ) + δ ‖vₖ‖² + dₖᵀ Sₖ dₖ]
//!   s.t. x₀ = z₀,  xₖ₊₁ = Aₖ xₖ + Bₖ vₖ + cₖ,  loₖ ≤ vₖ ≤ hiₖ,
//!
//! with x = δx the state step, v the input step, eₖ = x̄ₖ − rₖ, Wₖ = diag(Q) (k < N), W_N =
//! diag(Q_N), δ = `REGULARISATION` (the condensed solver's δI), and the input-rate term: dₖ = Δ̄ₖ +
//! vₖ − wₖ the rate uₖ − uₖ₋₁ of the new plan (Δ̄ₖ = ūₖ − ūₖ₋₁ of the guess, ū₋₁ = u₋₁ fixed), wₖ
//! = Eₖ₋₁ vₖ₋₁ the previous stage's input step (w₀ = 0). An input sent already (k below its lead,
//! docs/mpc.md "Input delays") is held: its column of Bₖ is zero (the caller's), its rate weight
//! in Sₖ = diag(S · [k ≥ lead]) is 0 and Eₖ = diag([k ≥ lead]) does not carry its step to the next
//! stage, so its v is decoupled from everything (and discarded by the caller). Only the inputs are
//! bounded.
//!
//! The rate term makes the previous input step part of the state, x̃ₖ = (xₖ, wₖ), with the trivial
//! dynamics wₖ₊₁ = Eₖ vₖ; the augmented stage has Ã = blkdiag(Aₖ, 0), B̃ = (Bₖ; Eₖ), state weight
//! blkdiag(Wₖ, Sₖ) and the cross weight −Sₖ between wₖ and vₖ. Its structure is used throughout: the
//! value function's Hessian P̃ = (Pxx Pxw; Pwx Pww) is local to the factorisation, only the gain
//! on x is stored (Kₖ, as without the rate term), and the gain on w is Ĥₖ⁻¹ Sₖ, applied through the
//! stored factor of Ĥₖ.
//!
//! Slacks t_l = v − lo, t_u = hi − v ≥ 0 with multipliers λ_l, λ_u ≥ 0. The iterate's states are
//! always the rollout of its inputs (the dynamics hold exactly), so a Newton step is the LQ problem
//! with stage Hessians (blkdiag(Wₖ, Sₖ), R + δI + Sₖ + Σₖ), Σ = λ_l/t_l + λ_u/t_u, zero defects, and
//! linear terms
//!
//!   qₖ = (Wₖ (eₖ + xₖ), −Sₖ dₖ),
//!   ρₖ = (R + δI) vₖ + R ūₖ + Sₖ dₖ + (λ_l r_l + c_l − σμ)/t_l − (λ_u r_u + c_u − σμ)/t_u,
//!
//! (r_l = v − lo − t_l, r_u = hi − v − t_u, c the corrector's second-order term). The Riccati
//! factorisation, backwards from Pxx = W_N, Pxw = 0, Pww = 0,
//!
//!   Ĥₖ = R + δI + Sₖ + Σₖ + Bₖᵀ Pxx Bₖ + Bₖᵀ Pxw Eₖ + Eₖ Pwx Bₖ + Eₖ Pww Eₖ = Lₖ Lₖᵀ,
//!   Gₖ = (Bₖᵀ Pxx + Eₖ Pwx) Aₖ,  Kₖ = −Ĥₖ⁻¹ Gₖ,
//!   Pxx ← Wₖ + Aₖᵀ Pxx Aₖ + Gₖᵀ Kₖ,  Pxw ← −Kₖᵀ Sₖ,  Pww ← Sₖ − Sₖ Ĥₖ⁻¹ Sₖ,
//!
//! costs O(N (NX³ + NX² NU)) and is shared by the predictor and the corrector; each of those is a
//! backward pass ĝₖ = ρₖ + Bₖᵀ p + Eₖ p_w, κₖ = −Ĥₖ⁻¹ ĝₖ, p ← qₖ + Aₖᵀ p + Kₖᵀ ĝₖ, p_w ← −Sₖ (dₖ +
//! κₖ) (p_N = q_N, p_w = 0) and a forward pass dvₖ = Kₖ dxₖ + Ĥₖ⁻¹ Sₖ dwₖ + κₖ, dxₖ₊₁ = Aₖ dxₖ +
//! Bₖ dvₖ, dwₖ₊₁ = Eₖ dvₖ (dx₀ = 0, dw₀ = 0), O(N NX²). The rate term's extra work is confined to
//! the inputs with Sᵣ ≠ 0. The work of a solve is at most `MAX_IPM_ITERATIONS` such iterations
//! whatever the data: bounded by construction.

use crate::math::sqrt;
use crate::{Real, N, NU, NX, Q, Q_TERMINAL, R, REGULARISATION};

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IpmStatus {
    /// Residuals and complementarity below the tolerance.
    Optimal,
    /// `MAX_IPM_ITERATIONS` reached; the last iterate is returned (its inputs within the box).
    IterationCap,
    /// A pivot of Ĥₖ was not positive and was raised: the step solved a regularised system.
    Regularised,
    /// A non-finite number appeared; the iterate before it is returned.
    NumericalFailure,
}

/// Result of [`RiccatiIpm::solve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IpmResult {
    pub status: IpmStatus,
    pub iterations: usize,
}

/// The data of one QP: Jacobians, defects, tracking offsets, inputs of the guess and the box.
pub struct StageQp<'a> {
    pub a: &'a [[[Real; NX]; NX]; N],
    pub b: &'a [[[Real; NU]; NX]; N],
    pub c: &'a [[Real; NX]; N],
    /// eₖ = x̄ₖ − rₖ
    pub e: &'a [[Real; NX]; N + 1],
    /// ūₖ
    pub us: &'a [[Real; NU]; N],
    /// u₋₁: the input applied before stage 0 (where the first rate starts).
    pub u_prev: &'a [Real; NU],
    /// diag(S), the input-rate weight.
    pub s: &'a [Real; NU],
    /// Each input's lead: input i is held at the stages k < `lead[i]` (docs/mpc.md "Input delays").
    pub lead: &'a [usize; NU],
    pub lo: &'a [[Real; NU]; N],
    pub hi: &'a [[Real; NU]; N],
}

impl StageQp<'_> {
    /// Whether input i at stage k is a decision (not held): the diagonal of Eₖ.
    #[inline]
    fn free(&self, k: usize, i: usize) -> bool {
        k >= self.lead[i]
    }

    /// (Sₖ)ᵢ: the rate weight of input i at stage k, 0 for a held input (its rate is a constant).
    #[inline]
    fn rate_weight(&self, k: usize, i: usize) -> Real {
        if self.free(k, i) {
            self.s[i]
        } else {
            0.0
        }
    }

    /// Whether any input has a rate weight (the rate term's work is skipped otherwise).
    #[inline]
    fn has_rate(&self) -> bool {
        self.s.iter().any(|&s| s != 0.0)
    }

    /// dₖ,ᵢ = Δ̄ₖ,ᵢ + vₖ,ᵢ − wₖ,ᵢ: the rate of input i at stage k for the input steps v.
    #[inline]
    fn rate(&self, v: &[[Real; NU]; N], k: usize, i: usize) -> Real {
        let (before, w) = if k == 0 {
            (self.u_prev[i], 0.0)
        } else if self.free(k - 1, i) {
            (self.us[k - 1][i], v[k - 1][i])
        } else {
            (self.us[k - 1][i], 0.0)
        };
        self.us[k][i] - before + v[k][i] - w
    }
}

/// Fraction of the distance to the boundary a step may go.
const STEP_TO_BOUNDARY: Real = 0.995;
/// Initial slack at least this fraction of the box width (an interior start).
const INITIAL_SLACK: Real = 0.1;

/// Workspace of the interior-point method (no allocation, sizes fixed at compile time).
#[derive(Clone, Debug)]
pub struct RiccatiIpm {
    /// Lₖ, lower Cholesky factor of Ĥₖ.
    l: [[[Real; NU]; NU]; N],
    /// Kₖ = −Ĥₖ⁻¹ Gₖ
    k: [[[Real; NX]; NU]; N],
    /// κₖ of the last backward pass.
    kappa: [[Real; NU]; N],
    /// Iterate: input step v, its states x (rollout), slacks and multipliers.
    pub v: [[Real; NU]; N],
    pub x: [[Real; NX]; N + 1],
    t_l: [[Real; NU]; N],
    t_u: [[Real; NU]; N],
    lam_l: [[Real; NU]; N],
    lam_u: [[Real; NU]; N],
    /// Newton direction.
    dv: [[Real; NU]; N],
    dx: [[Real; NX]; N + 1],
    /// Affine-scaling slack and multiplier steps (the corrector's c = dt·dλ).
    corr_l: [[Real; NU]; N],
    corr_u: [[Real; NU]; N],
    /// The step's dt_l, dt_u, dλ_l, dλ_u (`slack_steps`): here rather than on the stack (3.8 KB
    /// for the M100 crates), so that prepare + feedback fit a small thread (docs/c-api.md, "Stack").
    steps: SlackSteps,
    /// True when `l`/`k` hold the factorisation for the current iterate's Σ.
    factored: bool,
    regularised: bool,
}

impl Default for RiccatiIpm {
    fn default() -> Self {
        Self::new()
    }
}

/// Stage weights Wₖ (diagonal).
#[inline]
fn weights(k: usize) -> &'static [Real; NX] {
    if k < N {
        &Q
    } else {
        &Q_TERMINAL
    }
}

/// Largest α ∈ (0, 1] with s + α ds ≥ 0 for every component.
#[inline]
fn max_step(s: &[[Real; NU]; N], ds: &[[Real; NU]; N], alpha: Real) -> Real {
    let mut alpha = alpha;
    for k in 0..N {
        for i in 0..NU {
            if ds[k][i] < 0.0 {
                let a = -s[k][i] / ds[k][i];
                if a < alpha {
                    alpha = a;
                }
            }
        }
    }
    alpha
}

impl RiccatiIpm {
    pub const fn new() -> Self {
        Self {
            l: [[[0.0; NU]; NU]; N],
            k: [[[0.0; NX]; NU]; N],
            kappa: [[0.0; NU]; N],
            v: [[0.0; NU]; N],
            x: [[0.0; NX]; N + 1],
            t_l: [[0.0; NU]; N],
            t_u: [[0.0; NU]; N],
            lam_l: [[0.0; NU]; N],
            lam_u: [[0.0; NU]; N],
            dv: [[0.0; NU]; N],
            dx: [[0.0; NX]; N + 1],
            corr_l: [[0.0; NU]; N],
            corr_u: [[0.0; NU]; N],
            steps: [[[0.0; NU]; N]; 4],
            factored: false,
            regularised: false,
        }
    }

    /// The start point that does not depend on x₀ (v = 0, slacks at least `INITIAL_SLACK` of the
    /// box width, λ = 1) and the Riccati factorisation for it: the part of the first iteration
    /// that can run in `prepare` (it reads Aₖ, Bₖ, S, the leads and the box of `qp`). False if a
    /// number is not finite.
    pub fn prepare(&mut self, qp: &StageQp) -> bool {
        self.regularised = false;
        let (lo, hi) = (qp.lo, qp.hi);
        for k in 0..N {
            for i in 0..NU {
                let floor = INITIAL_SLACK * (hi[k][i] - lo[k][i]).max(Real::EPSILON);
                self.v[k][i] = 0.0;
                self.t_l[k][i] = (-lo[k][i]).max(floor);
                self.t_u[k][i] = hi[k][i].max(floor);
                self.lam_l[k][i] = 1.0;
                self.lam_u[k][i] = 1.0;
            }
        }
        self.factored = self.factorize(qp);
        self.factored
    }

    /// Riccati factorisation for Σ of the current iterate (the module docs' recursion).
    /// False if a number is not finite; a non-positive pivot of Ĥₖ is raised (`regularised`).
    fn factorize(&mut self, qp: &StageQp) -> bool {
        let mut p = [[0.0; NX]; NX];
        for i in 0..NX {
            p[i][i] = Q_TERMINAL[i];
        }
        // The rate term's blocks of the value function's Hessian: Pxw (column r non-zero only where
        // the next stage's rate weight is) and Pww; zero at N.
        let mut pxw = [[0.0; NU]; NX];
        let mut pww = [[0.0; NU]; NU];
        // Columns r of Pxw / rows of Pww that may be non-zero (Sₖ₊₁ ≠ 0 there).
        let mut rate_next = [false; NU];
        let has_rate = qp.has_rate();
        let mut finite = true;
        for k in (0..N).rev() {
            let (ak, bk) = (&qp.a[k], &qp.b[k]);
            // PA = P Aₖ, PB = P Bₖ (row r: Σₘ P[r][m] A[m], axpys of contiguous rows)
            let mut pa = [[0.0; NX]; NX];
            let mut pb = [[0.0; NU]; NX];
            for r in 0..NX {
                for m in 0..NX {
                    let prm = p[r][m];
                    for c in 0..NX {
                        pa[r][c] += prm * ak[m][c];
                    }
                    for c in 0..NU {
                        pb[r][c] += prm * bk[m][c];
                    }
                }
            }
            // With the rate term, M = P B + Pxw E (the carried inputs' columns of Pxw added to
            // P B) gives Ĥ = Bᵀ M + E Pwx B + E Pww E and G = Mᵀ A = (Bᵀ P + E Pwx) A at the cost
            // of the plain recursion's Bᵀ (P B) and Bᵀ (P A), plus E Pwx B: O(NX NU) per
            // rate-weighted input. Rows r of Pwx are non-zero only where Sₖ₊₁,rr is.
            let mut mb = pb;
            let mut hh = [[0.0; NU]; NU];
            if has_rate {
                for r in 0..NU {
                    if !(rate_next[r] && qp.free(k, r)) {
                        continue;
                    }
                    for m in 0..NX {
                        let w = pxw[m][r];
                        mb[m][r] += w;
                        // (E Pwx B)[r]
                        for c in 0..NU {
                            hh[r][c] += w * bk[m][c];
                        }
                    }
                    for c in 0..NU {
                        if rate_next[c] && qp.free(k, c) {
                            hh[r][c] += pww[r][c];
                        }
                    }
                }
            }
            // Ĥ += R + δI + S + Σ + Bᵀ M, G = Mᵀ A (without the rate term M = P B: Bᵀ P A)
            let mut g = [[0.0; NX]; NU];
            for m in 0..NX {
                for r in 0..NU {
                    let bmr = bk[m][r];
                    for c in 0..NU {
                        hh[r][c] += bmr * mb[m][c];
                    }
                    let mmr = mb[m][r];
                    for c in 0..NX {
                        g[r][c] += mmr * ak[m][c];
                    }
                }
            }
            for i in 0..NU {
                hh[i][i] += R[i]
                    + REGULARISATION
                    + qp.rate_weight(k, i)
                    + self.lam_l[k][i] / self.t_l[k][i]
                    + self.lam_u[k][i] / self.t_u[k][i];
            }
            // Ĥ = L Lᵀ
            let mut l = [[0.0; NU]; NU];
            for i in 0..NU {
                for j in 0..=i {
                    let mut s = hh[i][j];
                    for m in 0..j {
                        s -= l[i][m] * l[j][m];
                    }
                    if i == j {
                        let floor = 1e3 * Real::EPSILON * hh[i][i].abs().max(1.0);
                        if !(s > floor) {
                            finite &= s.is_finite();
                            self.regularised = true;
                            s = floor;
                        }
                        l[i][i] = sqrt(s);
                    } else {
                        l[i][j] = s / l[j][j];
                    }
                }
            }
            // K = −Ĥ⁻¹ G, column by column of G.
            let mut kk = [[0.0; NX]; NU];
            for c in 0..NX {
                let mut y = [0.0; NU];
                for i in 0..NU {
                    y[i] = g[i][c];
                }
                solve_cholesky(&l, &mut y);
                for i in 0..NU {
                    kk[i][c] = -y[i];
                }
            }
            self.l[k] = l;
            self.k[k] = kk;
            if k > 0 {
                // P ← W + Aᵀ (P A) + Gᵀ K (symmetric: upper triangle, mirrored)
                let w = weights(k);
                let mut next = [[0.0; NX]; NX];
                for r in 0..NX {
                    for c in r..NX {
                        let mut s = 0.0;
                        for m in 0..NX {
                            s += ak[m][r] * pa[m][c];
                        }
                        for m in 0..NU {
                            s += g[m][r] * kk[m][c];
                        }
                        next[r][c] = s;
                        next[c][r] = s;
                    }
                    next[r][r] += w[r];
                }
                p = next;
                if has_rate {
                    // Pxw ← −Kᵀ S, Pww ← S − S Ĥ⁻¹ S (columns r with Sₖ,rr ≠ 0)
                    pww = [[0.0; NU]; NU];
                    for r in 0..NU {
                        let s = qp.rate_weight(k, r);
                        rate_next[r] = s != 0.0;
                        for m in 0..NX {
                            pxw[m][r] = -kk[r][m] * s;
                        }
                        if s != 0.0 {
                            let mut y = [0.0; NU];
                            y[r] = s;
                            solve_cholesky(&l, &mut y);
                            for i in 0..NU {
                                pww[i][r] = -qp.rate_weight(k, i) * y[i];
                            }
                            pww[r][r] += s;
                        }
                    }
                    finite &= pxw.iter().all(|row| row.iter().all(|v| v.is_finite()))
                        && pww.iter().all(|row| row.iter().all(|v| v.is_finite()));
                }
            }
            finite &= p.iter().all(|row| row.iter().all(|v| v.is_finite()));
        }
        finite
    }

    /// Backward pass for the linear terms (qₖ from the iterate's states and rates, ρₖ from `rho`),
    /// then the forward pass: the Newton direction in `dv`, `dx`.
    fn direction(&mut self, qp: &StageQp, rho: &[[Real; NU]; N]) {
        let has_rate = qp.has_rate();
        // p_N = q_N = W_N (e_N + x_N), p_w = 0
        let mut p = [0.0; NX];
        for i in 0..NX {
            p[i] = Q_TERMINAL[i] * (qp.e[N][i] + self.x[N][i]);
        }
        let mut pw = [0.0; NU];
        for k in (0..N).rev() {
            let (ak, bk) = (&qp.a[k], &qp.b[k]);
            // ĝ = ρ + Bᵀ p + E p_w
            let mut gh = rho[k];
            for m in 0..NX {
                for r in 0..NU {
                    gh[r] += bk[m][r] * p[m];
                }
            }
            if has_rate {
                for r in 0..NU {
                    if qp.free(k, r) {
                        gh[r] += pw[r];
                    }
                }
            }
            // κ = −Ĥ⁻¹ ĝ
            let mut kappa = gh;
            solve_cholesky(&self.l[k], &mut kappa);
            for r in 0..NU {
                kappa[r] = -kappa[r];
            }
            self.kappa[k] = kappa;
            if k > 0 {
                // p ← W (e + x) + Aᵀ p + Kᵀ ĝ
                let w = &Q;
                let kk = &self.k[k];
                let mut next = [0.0; NX];
                for c in 0..NX {
                    next[c] = w[c] * (qp.e[k][c] + self.x[k][c]);
                }
                for m in 0..NX {
                    let pm = p[m];
                    for (nc, amc) in next.iter_mut().zip(&ak[m]) {
                        *nc += amc * pm;
                    }
                }
                for m in 0..NU {
                    let gm = gh[m];
                    for (nc, kmc) in next.iter_mut().zip(&kk[m]) {
                        *nc += kmc * gm;
                    }
                }
                p = next;
                // p_w ← −S (d + κ)
                if has_rate {
                    for r in 0..NU {
                        pw[r] = -qp.rate_weight(k, r) * (qp.rate(&self.v, k, r) + kappa[r]);
                    }
                }
            }
        }
        // dv = K dx + Ĥ⁻¹ S dw + κ, dx⁺ = A dx + B dv, dw⁺ = E dv; dx₀ = 0, dw₀ = 0
        let mut dx = [0.0; NX];
        let mut dw = [0.0; NU];
        self.dx[0] = dx;
        for k in 0..N {
            let (ak, bk, kk) = (&qp.a[k], &qp.b[k], &self.k[k]);
            let mut dv = self.kappa[k];
            for r in 0..NU {
                for c in 0..NX {
                    dv[r] += kk[r][c] * dx[c];
                }
            }
            if has_rate && k > 0 {
                let mut y = [0.0; NU];
                let mut any = false;
                for r in 0..NU {
                    y[r] = qp.rate_weight(k, r) * dw[r];
                    any |= y[r] != 0.0;
                }
                if any {
                    solve_cholesky(&self.l[k], &mut y);
                    for r in 0..NU {
                        dv[r] += y[r];
                    }
                }
            }
            let mut next = [0.0; NX];
            for r in 0..NX {
                let mut s = 0.0;
                for c in 0..NX {
                    s += ak[r][c] * dx[c];
                }
                for c in 0..NU {
                    s += bk[r][c] * dv[c];
                }
                next[r] = s;
            }
            for r in 0..NU {
                dw[r] = if qp.free(k, r) { dv[r] } else { 0.0 };
            }
            self.dv[k] = dv;
            dx = next;
            self.dx[k + 1] = dx;
        }
    }

    /// ‖∇ᵥ L‖∞ = max |(R + δI) v + R ū + S d − Eₖ Sₖ₊₁ dₖ₊₁ + Bᵀ p − λ_l + λ_u| with the adjoint p of
    /// the iterate's states: the stationarity residual (the dynamics hold exactly at every iterate).
    fn stationarity(&self, qp: &StageQp) -> Real {
        let has_rate = qp.has_rate();
        let mut p = [0.0; NX];
        for i in 0..NX {
            p[i] = Q_TERMINAL[i] * (qp.e[N][i] + self.x[N][i]);
        }
        // p_w of stage k + 1: −Sₖ₊₁ dₖ₊₁ (0 at N)
        let mut pw = [0.0; NU];
        let mut worst: Real = 0.0;
        for k in (0..N).rev() {
            let (ak, bk) = (&qp.a[k], &qp.b[k]);
            for r in 0..NU {
                let mut s =
                    (R[r] + REGULARISATION) * self.v[k][r] + R[r] * qp.us[k][r] - self.lam_l[k][r] + self.lam_u[k][r];
                for m in 0..NX {
                    s += bk[m][r] * p[m];
                }
                if has_rate {
                    let d = qp.rate_weight(k, r) * qp.rate(&self.v, k, r);
                    if qp.free(k, r) {
                        s += pw[r];
                    }
                    s += d;
                    pw[r] = -d;
                }
                // NaN-propagating maximum
                worst = if s.abs() > worst || s.is_nan() { s.abs() } else { worst };
            }
            if k > 0 {
                let mut next = [0.0; NX];
                for c in 0..NX {
                    next[c] = Q[c] * (qp.e[k][c] + self.x[k][c]);
                }
                for m in 0..NX {
                    let pm = p[m];
                    for (nc, amc) in next.iter_mut().zip(&ak[m]) {
                        *nc += amc * pm;
                    }
                }
                p = next;
            }
        }
        worst
    }

    /// Solve from the start point of [`Self::prepare`] (which must have been called for the same
    /// Aₖ, Bₖ and box); x₀ enters through `z0` = x₀ − x̄₀. On return `v`, `x` hold the solution
    /// or the last iterate (v within the box up to the slack residual; callers clamp).
    pub fn solve(&mut self, qp: &StageQp, z0: &[Real; NX], max_iterations: usize) -> IpmResult {
        // States of v = 0: the free response x₀ = z₀, xₖ₊₁ = Aₖ xₖ + cₖ.
        self.x[0] = *z0;
        for k in 0..N {
            let mut next = qp.c[k];
            for r in 0..NX {
                for c in 0..NX {
                    next[r] += qp.a[k][r][c] * self.x[k][c];
                }
            }
            self.x[k + 1] = next;
        }
        let nv = (N * NU) as Real;
        let stationarity0 = self.stationarity(qp);
        let scale = stationarity0.max(1.0);
        // Residuals to 1e3 ε and complementarity to 1e2 ε relative to the start's stationarity
        // residual: the plans then agree with an exact solution to ≈ 1e-7 (f64), the accuracy the
        // generic comparison needs (1e-6).
        let tolerance = 1e3 * Real::EPSILON * scale;
        let mu_tolerance = Real::EPSILON * scale;
        let mut rho = [[0.0; NU]; N];
        let (mut r_l, mut r_u) = ([[0.0; NU]; N], [[0.0; NU]; N]);
        let mut iterations = 0;
        loop {
            // Residuals and the termination test.
            let mut mu = 0.0;
            let mut primal: Real = 0.0;
            for k in 0..N {
                for i in 0..NU {
                    r_l[k][i] = self.v[k][i] - qp.lo[k][i] - self.t_l[k][i];
                    r_u[k][i] = qp.hi[k][i] - self.v[k][i] - self.t_u[k][i];
                    primal = primal.max(r_l[k][i].abs()).max(r_u[k][i].abs());
                    mu += self.t_l[k][i] * self.lam_l[k][i] + self.t_u[k][i] * self.lam_u[k][i];
                }
            }
            mu /= 2.0 * nv;
            let dual = self.stationarity(qp);
            if !(mu.is_finite() && dual.is_finite() && primal.is_finite()) {
                return IpmResult {
                    status: IpmStatus::NumericalFailure,
                    iterations,
                };
            }
            if mu <= mu_tolerance && dual <= tolerance && primal <= tolerance {
                // Bounds identified as active (λ > t, and t within rounding of 0) hold exactly.
                for k in 0..N {
                    for i in 0..NU {
                        let tiny = tolerance * (qp.hi[k][i] - qp.lo[k][i]);
                        if self.lam_l[k][i] > self.t_l[k][i] && self.t_l[k][i] <= tiny {
                            self.v[k][i] = qp.lo[k][i];
                        } else if self.lam_u[k][i] > self.t_u[k][i] && self.t_u[k][i] <= tiny {
                            self.v[k][i] = qp.hi[k][i];
                        }
                    }
                }
                let status = if self.regularised {
                    IpmStatus::Regularised
                } else {
                    IpmStatus::Optimal
                };
                return IpmResult { status, iterations };
            }
            if iterations >= max_iterations {
                return IpmResult {
                    status: IpmStatus::IterationCap,
                    iterations,
                };
            }
            iterations += 1;
            if !self.factored && !self.factorize(qp) {
                return IpmResult {
                    status: IpmStatus::NumericalFailure,
                    iterations,
                };
            }
            self.factored = false;

            // Predictor (affine scaling): σ = 0, c = 0.
            self.linear_terms(qp, &r_l, &r_u, 0.0, false, &mut rho);
            self.direction(qp, &rho);
            self.slack_steps(&r_l, &r_u, 0.0, false);
            let [dt_l, dt_u, dl_l, dl_u] = &self.steps;
            let alpha = max_step(&self.t_l, dt_l, 1.0);
            let alpha = max_step(&self.t_u, dt_u, alpha);
            let alpha = max_step(&self.lam_l, dl_l, alpha);
            let alpha = max_step(&self.lam_u, dl_u, alpha);
            let mut mu_aff = 0.0;
            for k in 0..N {
                for i in 0..NU {
                    mu_aff += (self.t_l[k][i] + alpha * dt_l[k][i]) * (self.lam_l[k][i] + alpha * dl_l[k][i])
                        + (self.t_u[k][i] + alpha * dt_u[k][i]) * (self.lam_u[k][i] + alpha * dl_u[k][i]);
                    self.corr_l[k][i] = dt_l[k][i] * dl_l[k][i];
                    self.corr_u[k][i] = dt_u[k][i] * dl_u[k][i];
                }
            }
            mu_aff /= 2.0 * nv;
            let ratio = (mu_aff / mu).clamp(0.0, 1.0);
            let sigma_mu = ratio * ratio * ratio * mu;

            // Corrector: target σμ, second-order term c = dt_aff · dλ_aff.
            self.linear_terms(qp, &r_l, &r_u, sigma_mu, true, &mut rho);
            self.direction(qp, &rho);
            self.slack_steps(&r_l, &r_u, sigma_mu, true);
            let [dt_l, dt_u, dl_l, dl_u] = &self.steps;
            let alpha = max_step(&self.t_l, dt_l, 1.0 / STEP_TO_BOUNDARY);
            let alpha = max_step(&self.t_u, dt_u, alpha);
            let alpha = max_step(&self.lam_l, dl_l, alpha);
            let alpha = STEP_TO_BOUNDARY * max_step(&self.lam_u, dl_u, alpha);
            for k in 0..N {
                for i in 0..NU {
                    self.v[k][i] += alpha * self.dv[k][i];
                    self.t_l[k][i] += alpha * dt_l[k][i];
                    self.t_u[k][i] += alpha * dt_u[k][i];
                    self.lam_l[k][i] += alpha * dl_l[k][i];
                    self.lam_u[k][i] += alpha * dl_u[k][i];
                }
            }
            for k in 0..=N {
                for i in 0..NX {
                    self.x[k][i] += alpha * self.dx[k][i];
                }
            }
        }
    }

    /// ρₖ of the module docs for the current iterate; `corrected` adds c (the affine step's dt·dλ).
    fn linear_terms(
        &self,
        qp: &StageQp,
        r_l: &[[Real; NU]; N],
        r_u: &[[Real; NU]; N],
        sigma_mu: Real,
        corrected: bool,
        rho: &mut [[Real; NU]; N],
    ) {
        for k in 0..N {
            for i in 0..NU {
                let (c_l, c_u) = if corrected {
                    (self.corr_l[k][i], self.corr_u[k][i])
                } else {
                    (0.0, 0.0)
                };
                rho[k][i] = (R[i] + REGULARISATION) * self.v[k][i]
                    + R[i] * qp.us[k][i]
                    + qp.rate_weight(k, i) * qp.rate(&self.v, k, i)
                    + (self.lam_l[k][i] * r_l[k][i] + c_l - sigma_mu) / self.t_l[k][i]
                    - (self.lam_u[k][i] * r_u[k][i] + c_u - sigma_mu) / self.t_u[k][i];
            }
        }
    }

    /// dt_l = dv + r_l, dt_u = −dv + r_u, dλ = (σμ − c − λ dt)/t − λ.
    fn slack_steps(&mut self, r_l: &[[Real; NU]; N], r_u: &[[Real; NU]; N], sigma_mu: Real, corrected: bool) {
        let [dt_l, dt_u, dl_l, dl_u] = &mut self.steps;
        for k in 0..N {
            for i in 0..NU {
                let (c_l, c_u) = if corrected {
                    (self.corr_l[k][i], self.corr_u[k][i])
                } else {
                    (0.0, 0.0)
                };
                dt_l[k][i] = self.dv[k][i] + r_l[k][i];
                dt_u[k][i] = -self.dv[k][i] + r_u[k][i];
                dl_l[k][i] = (sigma_mu - c_l - self.lam_l[k][i] * dt_l[k][i]) / self.t_l[k][i] - self.lam_l[k][i];
                dl_u[k][i] = (sigma_mu - c_u - self.lam_u[k][i] * dt_u[k][i]) / self.t_u[k][i] - self.lam_u[k][i];
            }
        }
    }
}

/// dt_l, dt_u, dλ_l, dλ_u of an interior-point step (`slack_steps`).
type SlackSteps = [[[Real; NU]; N]; 4];

/// y ← (L Lᵀ)⁻¹ y for a lower-triangular L (forward, then backward substitution).
#[inline]
fn solve_cholesky(l: &[[Real; NU]; NU], y: &mut [Real; NU]) {
    for i in 0..NU {
        let mut s = y[i];
        for m in 0..i {
            s -= l[i][m] * y[m];
        }
        y[i] = s / l[i][i];
    }
    for i in (0..NU).rev() {
        let mut s = y[i];
        for m in i + 1..NU {
            s -= l[m][i] * y[m];
        }
        y[i] = s / l[i][i];
    }
}

#[cfg(test)]
#[allow(clippy::modulo_one)] // NU = 1 in the template's example model
mod tests {
    use super::*;
    use crate::qp::{BoxQp, QpStatus};
    use crate::NV;

    /// Deterministic pseudo-random numbers in [−1, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> Real {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        }
    }

    struct Data {
        a: [[[Real; NX]; NX]; N],
        b: [[[Real; NU]; NX]; N],
        c: [[Real; NX]; N],
        e: [[Real; NX]; N + 1],
        us: [[Real; NU]; N],
        lo: [[Real; NU]; N],
        hi: [[Real; NU]; N],
        z0: [Real; NX],
        u_prev: [Real; NU],
        s: [Real; NU],
        lead: [usize; NU],
    }

    impl Data {
        fn qp(&self) -> StageQp<'_> {
            StageQp {
                a: &self.a,
                b: &self.b,
                c: &self.c,
                e: &self.e,
                us: &self.us,
                u_prev: &self.u_prev,
                s: &self.s,
                lead: &self.lead,
                lo: &self.lo,
                hi: &self.hi,
            }
        }

        fn solve(&self, ipm: &mut RiccatiIpm) -> IpmResult {
            assert!(ipm.prepare(&self.qp()));
            ipm.solve(&self.qp(), &self.z0, 50)
        }

        /// Input i held at stages k < `lead`: its column of Bₖ zeroed, as `hold_sent_inputs` does.
        fn hold(&mut self, i: usize, lead: usize) {
            self.lead[i] = lead;
            for k in 0..lead {
                for row in self.b[k].iter_mut() {
                    row[i] = 0.0;
                }
            }
        }
    }

    /// A stable random LQ problem around the example model's sizes with a box that binds.
    fn random_data(rng: &mut Lcg, width: Real) -> Data {
        let mut d = Data {
            a: [[[0.0; NX]; NX]; N],
            b: [[[0.0; NU]; NX]; N],
            c: [[0.0; NX]; N],
            e: [[0.0; NX]; N + 1],
            us: [[0.0; NU]; N],
            lo: [[0.0; NU]; N],
            hi: [[0.0; NU]; N],
            z0: [0.0; NX],
            u_prev: [0.0; NU],
            s: [0.0; NU],
            lead: [0; NU],
        };
        for k in 0..N {
            for r in 0..NX {
                for c in 0..NX {
                    d.a[k][r][c] = if r == c { 1.0 } else { 0.0 } + 0.2 * rng.next();
                }
                for c in 0..NU {
                    d.b[k][r][c] = 0.5 * rng.next();
                }
                d.c[k][r] = 0.05 * rng.next();
            }
            for i in 0..NU {
                d.us[k][i] = rng.next();
                let centre = 0.3 * rng.next();
                d.lo[k][i] = centre - width * (0.2 + rng.next().abs());
                d.hi[k][i] = centre + width * (0.2 + rng.next().abs());
            }
        }
        for k in 0..=N {
            for i in 0..NX {
                d.e[k][i] = 3.0 * rng.next();
            }
        }
        for i in 0..NX {
            d.z0[i] = rng.next();
        }
        for i in 0..NU {
            d.u_prev[i] = rng.next();
        }
        d
    }

    /// The same QP condensed (Γ the prediction matrix) and solved by the active-set solver:
    /// H = Γᵀ W Γ + diag(R + δ), g = Γᵀ W (e + z) + R ū with z the free response.
    fn condensed_solution(d: &Data) -> [Real; NV] {
        let mut gamma = [[[0.0; NV]; NX]; N + 1];
        let mut z = [[0.0; NX]; N + 1];
        z[0] = d.z0;
        for k in 0..N {
            for i in 0..NX {
                z[k + 1][i] = d.c[k][i];
                for j in 0..NX {
                    z[k + 1][i] += d.a[k][i][j] * z[k][j];
                }
                for col in 0..NV {
                    let mut s = 0.0;
                    for j in 0..NX {
                        s += d.a[k][i][j] * gamma[k][j][col];
                    }
                    if col / NU == k {
                        s += d.b[k][i][col % NU];
                    }
                    gamma[k + 1][i][col] = s;
                }
            }
        }
        let mut h = [[0.0; NV]; NV];
        let mut g = [0.0; NV];
        for r in 0..NV {
            g[r] = R[r % NU] * d.us[r / NU][r % NU];
            for k in 1..=N {
                let w = weights(k);
                for i in 0..NX {
                    g[r] += gamma[k][i][r] * w[i] * (d.e[k][i] + z[k][i]);
                }
            }
            for c in 0..NV {
                let mut s = 0.0;
                for k in 1..=N {
                    let w = weights(k);
                    for i in 0..NX {
                        s += gamma[k][i][r] * w[i] * gamma[k][i][c];
                    }
                }
                if r == c {
                    s += R[r % NU] + REGULARISATION;
                }
                h[r][c] = s;
            }
        }
        // The rate term ½ Σ Sᵢ (uₖ,ᵢ − uₖ₋₁,ᵢ)² (u₋₁ fixed) as the condensed solver adds it, and the
        // held inputs decoupled (H entry 1, gradient 0: their step is 0).
        let held = |k: usize, i: usize| k < d.lead[i];
        let rate = |k: usize, i: usize| d.us[k][i] - if k == 0 { d.u_prev[i] } else { d.us[k - 1][i] };
        for k in 0..N {
            for i in 0..NU {
                let r = k * NU + i;
                if held(k, i) {
                    h[r] = [0.0; NV];
                    for row in h.iter_mut() {
                        row[r] = 0.0;
                    }
                    h[r][r] = 1.0;
                    g[r] = 0.0;
                    continue;
                }
                let s = d.s[i];
                let later = k + 1 < N;
                h[r][r] += if later { 2.0 * s } else { s };
                if k > 0 && !held(k - 1, i) {
                    h[r][r - NU] -= s;
                    h[r - NU][r] -= s;
                }
                g[r] += s * (rate(k, i) - if later { rate(k + 1, i) } else { 0.0 });
            }
        }
        let lo: [Real; NV] = core::array::from_fn(|i| d.lo[i / NU][i % NU]);
        let hi: [Real; NV] = core::array::from_fn(|i| d.hi[i / NU][i % NU]);
        let mut qp = BoxQp::<NV>::new();
        qp.factorize(&h).unwrap();
        let mut v = [0.0; NV];
        let r = qp.solve(&h, &g, &lo, &hi, &mut v, 1000, usize::MAX);
        assert_eq!(r.status, QpStatus::Optimal);
        v
    }

    #[test]
    fn decoupled_stages_by_hand() {
        // A = 0, B = 0: each stage is min ½ (R + δ) v² + R ū v on [lo, hi], so
        // v* = clamp(−R ū / (R + δ), lo, hi).
        let mut rng = Lcg(5);
        let mut d = random_data(&mut rng, 1.0);
        d.a = [[[0.0; NX]; NX]; N];
        d.b = [[[0.0; NU]; NX]; N];
        let mut ipm = RiccatiIpm::new();
        let r = d.solve(&mut ipm);
        assert_eq!(r.status, IpmStatus::Optimal);
        let mut active = 0;
        for k in 0..N {
            for i in 0..NU {
                let unconstrained = -R[i] * d.us[k][i] / (R[i] + REGULARISATION);
                let expect = unconstrained.max(d.lo[k][i]).min(d.hi[k][i]);
                active += usize::from(expect != unconstrained);
                assert!(
                    (ipm.v[k][i] - expect).abs() < 1e-8,
                    "stage {k}: {} vs {expect}",
                    ipm.v[k][i]
                );
            }
        }
        assert!(active > 0 && active < N * NU, "{active} active bounds");
    }

    #[test]
    fn scalar_integrator_by_hand() {
        // x⁺ = x + v (NX = 2: the second state is inert), e = 0, z₀ = (1, 0), W = diag(Q):
        // with one stage's inputs free of the box the optimum balances tracking and effort;
        // with the box [−0.1, 0.1] and a far start every input sits at its lower bound.
        let mut d = random_data(&mut Lcg(1), 1.0);
        for k in 0..N {
            d.a[k] = [[0.0; NX]; NX];
            d.a[k][0][0] = 1.0;
            d.a[k][1][1] = 1.0;
            d.b[k] = [[0.0; NU]; NX];
            d.b[k][0][0] = 1.0;
            d.c[k] = [0.0; NX];
            d.us[k] = [0.0; NU];
            d.lo[k] = [-0.1; NU];
            d.hi[k] = [0.1; NU];
        }
        d.e = [[0.0; NX]; N + 1];
        d.z0 = [100.0, 0.0];
        let mut ipm = RiccatiIpm::new();
        assert_eq!(d.solve(&mut ipm).status, IpmStatus::Optimal);
        for k in 0..N {
            assert!((ipm.v[k][0] + 0.1).abs() < 1e-9, "stage {k}: {}", ipm.v[k][0]);
            assert!((ipm.x[k + 1][0] - (100.0 - 0.1 * (k + 1) as Real)).abs() < 1e-7);
        }
    }

    #[test]
    fn random_problems_match_the_condensed_active_set_solver() {
        let mut rng = Lcg(42);
        let mut worst: Real = 0.0;
        for width in [0.05, 0.3, 1.0, 100.0] {
            for _ in 0..25 {
                let d = random_data(&mut rng, width);
                let mut ipm = RiccatiIpm::new();
                let r = d.solve(&mut ipm);
                assert_eq!(r.status, IpmStatus::Optimal, "width {width}");
                let v = condensed_solution(&d);
                for k in 0..N {
                    for i in 0..NU {
                        let diff = (ipm.v[k][i] - v[k * NU + i]).abs();
                        worst = worst.max(diff);
                        assert!(
                            diff < 1e-6,
                            "width {width}, stage {k}: {} vs {}",
                            ipm.v[k][i],
                            v[k * NU + i]
                        );
                    }
                }
            }
        }
        assert!(worst < 1e-6);
    }

    #[test]
    fn the_rate_term_and_held_inputs_match_the_condensed_active_set_solver() {
        // S on uₖ − uₖ₋₁ (u₋₁ fixed, ū random), with some inputs held for a few stages (their
        // columns of B zero): the augmented recursion against the condensed QP with the rate term
        // added as the condensed solver adds it. Held inputs' steps are not decisions (the caller
        // discards them); every other step must agree.
        let mut rng = Lcg(77);
        let mut worst: Real = 0.0;
        for (case, width) in [0.05, 0.3, 1.0, 100.0].into_iter().cycle().take(60).enumerate() {
            let mut d = random_data(&mut rng, width);
            for i in 0..NU {
                // 0, 0.5, 5, 50, 500 (the default is 50)
                d.s[i] = if (case + i) % 5 == 0 {
                    0.0
                } else {
                    0.05 * Real::powi(10.0, ((case + i) % 5) as i32)
                };
                if (case / 2 + i) % 3 == 1 {
                    d.hold(i, 1 + (case + 3 * i) % 5);
                }
            }
            let mut ipm = RiccatiIpm::new();
            let r = d.solve(&mut ipm);
            assert_eq!(r.status, IpmStatus::Optimal, "case {case}");
            let v = condensed_solution(&d);
            for k in 0..N {
                for i in 0..NU {
                    if k < d.lead[i] {
                        continue;
                    }
                    let diff = (ipm.v[k][i] - v[k * NU + i]).abs();
                    worst = worst.max(diff);
                    assert!(
                        diff < 1e-6,
                        "case {case} (S {:?}, lead {:?}), stage {k}: {} vs {}",
                        d.s,
                        d.lead,
                        ipm.v[k][i],
                        v[k * NU + i]
                    );
                }
            }
        }
        assert!(worst < 1e-6);
    }

    #[test]
    fn a_heavy_rate_weight_holds_the_previous_input() {
        // A = 0, B = 0 (nothing to track), ū = 0, u₋₁ = 0.3 inside the box: with S ≫ R the optimal
        // plan stays near u₋₁; by hand, the stationarity of the tridiagonal system.
        let mut d = random_data(&mut Lcg(8), 1.0);
        d.a = [[[0.0; NX]; NX]; N];
        d.b = [[[0.0; NU]; NX]; N];
        d.us = [[0.0; NU]; N];
        d.lo = [[-1.0; NU]; N];
        d.hi = [[1.0; NU]; N];
        d.u_prev = [0.3; NU];
        d.s = [1e4; NU];
        let mut ipm = RiccatiIpm::new();
        assert_eq!(d.solve(&mut ipm).status, IpmStatus::Optimal);
        for i in 0..NU {
            for k in 0..N {
                // (R + δ) vₖ + S (2vₖ − vₖ₋₁ − vₖ₊₁) = 0 inside (v₋₁ = u₋₁, last stage S (v − vₖ₋₁))
                let before = if k == 0 { d.u_prev[i] } else { ipm.v[k - 1][i] };
                let after = if k + 1 < N { ipm.v[k + 1][i] } else { ipm.v[k][i] };
                let residual =
                    (R[i] + REGULARISATION) * ipm.v[k][i] + d.s[i] * ((ipm.v[k][i] - before) - (after - ipm.v[k][i]));
                assert!(residual.abs() < 1e-8, "stage {k}: residual {residual:e}");
                assert!(ipm.v[k][i] > 0.2 && ipm.v[k][i] <= 0.3, "stage {k}: {}", ipm.v[k][i]);
            }
        }
    }

    #[test]
    fn iteration_cap_is_reported_with_a_finite_iterate() {
        let d = random_data(&mut Lcg(9), 0.05);
        let mut ipm = RiccatiIpm::new();
        assert!(ipm.prepare(&d.qp()));
        let r = ipm.solve(&d.qp(), &d.z0, 2);
        assert_eq!(
            r,
            IpmResult {
                status: IpmStatus::IterationCap,
                iterations: 2
            }
        );
        assert!(ipm.v.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn non_finite_data_is_a_numerical_failure() {
        let mut d = random_data(&mut Lcg(3), 1.0);
        d.a[7][1][0] = Real::NAN;
        let mut ipm = RiccatiIpm::new();
        assert!(!ipm.prepare(&d.qp()));
        d = random_data(&mut Lcg(3), 1.0);
        d.e[4][0] = Real::INFINITY;
        assert!(ipm.prepare(&d.qp()));
        assert_eq!(ipm.solve(&d.qp(), &d.z0, 30).status, IpmStatus::NumericalFailure);
    }
}
