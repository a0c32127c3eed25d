//! Box-constrained strictly convex QP by a primal active-set method with
//! Cholesky updates:
//!
//!   min ½ vᵀ H v + gᵀ v   s.t.  lo ≤ v ≤ hi,   H = Hᵀ ≻ 0,  v ∈ ℝⁿ.
//!
//! The working set W holds the variables fixed at a bound, F the free ones.
//! L is the Cholesky factor of H_FF (rows and columns in the order of `free`), stored
//! transposed (column j of L contiguous), so that the substitutions and the updates run over
//! contiguous slices: the forward substitution by columns (elementwise updates, eight columns at
//! a time), the backward one by rows of Lᵀ (eight at a time), the rotations along rows of Lᵀ.
//! Each iteration solves the equality-constrained subproblem on F,
//!
//!   v_F* = −H_FF⁻¹ (g_F + H_FW v_W),
//!
//! moves towards it as far as the box allows, and either fixes the blocking
//! variable (a row/column deletion of L by a rank-one update, O(n²)) or, at
//! the subproblem's minimiser, frees the variable with the most negative
//! multiplier (a row/column append, O(n²)). Every iterate is inside the box and
//! the objective never increases, so stopping at the iteration cap returns the
//! best bounded iterate found.

use crate::math::sqrt;
use crate::Real;

/// Where a variable is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    Free,
    Lower,
    Upper,
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpStatus {
    /// KKT conditions hold: the exact minimiser (up to rounding).
    Optimal,
    /// The iteration cap or the work budget was reached; the iterate is feasible and no worse
    /// than the start.
    IterationCap,
    /// A pivot of the reduced Hessian was not positive: H is not numerically positive definite.
    NotPositiveDefinite,
}

/// Result of [`BoxQp::solve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QpResult {
    pub status: QpStatus,
    pub iterations: usize,
    /// Multiply-adds charged to the work budget (upper bounds of what ran; [`BoxQp::solve`]).
    pub work: usize,
}

/// The work budget of one solve, in multiply-adds: every costly operation is charged an upper
/// bound of its multiply-adds before it runs, and does not run if that would exceed `max`.
struct Budget {
    spent: usize,
    max: usize,
}

impl Budget {
    /// Whether `cost` more fits.
    fn fits(&self, cost: usize) -> bool {
        self.spent.saturating_add(cost) <= self.max
    }

    /// Charge `cost` if it fits; false (nothing charged) if not.
    fn charge(&mut self, cost: usize) -> bool {
        let fits = self.fits(cost);
        if fits {
            self.spent += cost;
        }
        fits
    }
}

/// Multiply-adds of rows `from..to` of a Cholesky factor (Σ i²/2 for the substitutions and i
/// for the pivots, bounded above); in u64, saturated to usize (a 32-bit usize cannot hold NV³ for
/// NV > 1625).
const fn rows_cost(from: usize, to: usize) -> usize {
    let (f, t) = (from as u64, to as u64);
    let cost = (t * t * t).saturating_sub(f * f * f) / 6 + t * t;
    if cost > usize::MAX as u64 {
        usize::MAX
    } else {
        cost as usize
    }
}

/// How [`BoxQp::drop_fixed`] drops the variables that are no longer free ([`BoxQp::drop_plan`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct DropPlan {
    /// By rotations (one deletion each) rather than by recomputing the rows after the first.
    by_rotations: bool,
    /// Upper bound of the multiply-adds of the way taken.
    cost: usize,
    /// Free positions no longer free.
    dropped: usize,
}

/// Workspace of the active-set solver for `NV` variables (no allocation).
#[derive(Clone, Debug)]
pub struct BoxQp<const NV: usize> {
    /// Cholesky factor of H_FF, stored transposed: `u[j][i]` = L_ij for j ≤ i (row j of `u` is
    /// column j of L, so the substitutions and updates run over contiguous slices), `nf × nf` used.
    u: [[Real; NV]; NV],
    /// Free variables in factor order.
    free: [usize; NV],
    nf: usize,
    /// Working set: the bound each variable sits at (or Free).
    state: [Bound; NV],
    rhs: [Real; NV],
    target: [Real; NV],
    /// H_{·,W} v_W (H's columns of the working set times their bound values),
    /// kept up to date as variables are fixed and freed.
    fixed_gradient: [Real; NV],
    work: [Real; NV],
    /// Component of each variable in H's coupling graph (`with_groups`; all 0: one component).
    /// H_ij = 0 exactly for variables of different components, so the factor of any H_FF has
    /// exact zeros between them, which the factorisation skips.
    group: [u8; NV],
    /// Number of components (largest `group` + 1; 0 before `ensure_groups`: one component).
    groups: u8,
}

impl<const NV: usize> Default for BoxQp<NV> {
    fn default() -> Self {
        Self::new()
    }
}

/// Σ aᵢ bᵢ over the shorter length, with 8 independent partial sums so that the
/// loop vectorises (the summation order is fixed, so results are deterministic). The last
/// n mod 8 elements go in pairs into two of them (then one scalar), which keeps short products
/// (the substitutions' rows) cheap.
#[inline]
pub fn dot(a: &[Real], b: &[Real]) -> Real {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0 as Real; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let (pa, pb) = (ra.chunks_exact(2), rb.chunks_exact(2));
    let (ta, tb) = (pa.remainder(), pb.remainder());
    for (x, y) in pa.zip(pb) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
    }
    let mut tail = 0.0;
    for (x, y) in ta.iter().zip(tb) {
        tail += x * y;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// w_k ← (((w_k − x₀ r₀_k) − x₁ r₁_k) − x₂ r₂_k) − x₃ r₃_k for every k (over the shortest
/// length): four columns of a substitution at once, one load and store of w per four
/// multiply-adds. Elementwise, two elements per iteration, so that it vectorises on x86-64 (SSE2)
/// without reassociating anything.
#[inline]
fn axpy4(w: &mut [Real], x: [Real; 4], r: [&[Real]; 4]) {
    let n = w.len().min(r[0].len()).min(r[1].len()).min(r[2].len()).min(r[3].len());
    let (w, r0, r1, r2, r3) = (&mut w[..n], &r[0][..n], &r[1][..n], &r[2][..n], &r[3][..n]);
    let rows = r0
        .chunks_exact(2)
        .zip(r1.chunks_exact(2))
        .zip(r2.chunks_exact(2))
        .zip(r3.chunks_exact(2));
    for (wk, (((a, b), c), d)) in w.chunks_exact_mut(2).zip(rows) {
        for l in 0..2 {
            wk[l] = (((wk[l] - x[0] * a[l]) - x[1] * b[l]) - x[2] * c[l]) - x[3] * d[l];
        }
    }
    if n % 2 == 1 {
        let k = n - 1;
        w[k] = (((w[k] - x[0] * r0[k]) - x[1] * r1[k]) - x[2] * r2[k]) - x[3] * r3[k];
    }
}

/// w_k ← w_k − x₀ r₀_k − … − x₇ r₇_k (subtracted in that order) for every k: eight columns
/// of a substitution at once (one load and store of w per eight multiply-adds). Elementwise, so
/// the loop vectorises without reassociating anything.
#[inline]
fn axpy8(w: &mut [Real], x: &[Real; 8], r: [&[Real]; 8]) {
    let mut n = w.len();
    for row in r {
        n = n.min(row.len());
    }
    let w = &mut w[..n];
    let [r0, r1, r2, r3, r4, r5, r6, r7] = r;
    let (r0, r1, r2, r3, r4, r5, r6, r7) = (
        &r0[..n],
        &r1[..n],
        &r2[..n],
        &r3[..n],
        &r4[..n],
        &r5[..n],
        &r6[..n],
        &r7[..n],
    );
    for k in 0..n {
        let a = ((w[k] - x[0] * r0[k]) - x[1] * r1[k]) - x[2] * r2[k];
        let b = ((a - x[3] * r3[k]) - x[4] * r4[k]) - x[5] * r5[k];
        w[k] = (b - x[6] * r6[k]) - x[7] * r7[k];
    }
}

/// w_k −= x r_k for every k (over the shorter length).
#[inline]
fn axpy(w: &mut [Real], x: Real, r: &[Real]) {
    for (wk, rk) in w.iter_mut().zip(r) {
        *wk -= x * rk;
    }
}

/// acc[c][r] −= Σ_{k in lo..hi} u[k][i0 + r] · u[k][j0 + c] = L_{i0+r,k} L_{j0+c,k}, k ascending:
/// the rank-one updates of an R × C block of the factor (row k of `u` is column k of L, so
/// each k reads R and C contiguous entries). R × C accumulators stay in registers; the loop over r
/// vectorises (SSE2: two lanes; AVX2: four) without reassociating anything.
#[inline(always)]
fn tile<const NV: usize, const R: usize, const C: usize>(
    u: &[[Real; NV]; NV],
    lo: usize,
    hi: usize,
    i0: usize,
    j0: usize,
    acc: &mut [[Real; R]; C],
) {
    let Some(rows) = u.get(lo..hi) else {
        return;
    };
    for row in rows {
        let (Some(a), Some(b)) = (row.get(i0..i0 + R), row.get(j0..j0 + C)) else {
            return;
        };
        let (Ok(a), Ok(b)) = (<&[Real; R]>::try_from(a), <&[Real; C]>::try_from(b)) else {
            return;
        };
        for c in 0..C {
            let bc = b[c];
            for r in 0..R {
                acc[c][r] -= a[r] * bc;
            }
        }
    }
}

/// Forward substitution with L by columns (column j of L is row j of `u`): for j in
/// `start..stop`, w_j ← w_j / L_jj, then w_k −= w_j L_kj for k in j + 1..`end` (end ≥ stop;
/// the rows of L from `stop` on only receive the updates). Eight columns at a time (then four,
/// then one); a block of eight exact zeros (another component's columns) is skipped.
fn forward<const NV: usize>(u: &[[Real; NV]; NV], w: &mut [Real; NV], start: usize, stop: usize, end: usize) {
    let end = end.min(NV);
    let stop = stop.min(end);
    let mut j = start;
    while j + 8 <= stop {
        let Some(rows) = u.get(j..j + 8) else {
            break;
        };
        // The 8 × 8 triangle (j + 7 < stop ≤ NV).
        let mut x = [0.0 as Real; 8];
        for c in 0..8 {
            let jc = (j + c).min(NV - 1);
            let mut s = w[jc];
            for (xc2, row) in x.iter().zip(rows).take(c) {
                s -= xc2 * row[jc];
            }
            let pivot = rows.get(c).map_or(1.0, |row| row[jc]);
            x[c] = s / pivot;
            w[jc] = x[c];
        }
        // All eight exactly zero (columns of another component, `with_groups`): nothing to do.
        if x.iter().any(|&xc| xc != 0.0) {
            let lo = (j + 8).min(end);
            let r = core::array::from_fn(|c| rows.get(c).map_or(&[][..], |row| tail(row, lo, end)));
            if let Some(w) = w.get_mut(lo..end) {
                axpy8(w, &x, r);
            }
        }
        j += 8;
    }
    while j + 4 <= stop {
        let (Some([r0, r1, r2, r3]), Some(wj)) = (u.get(j..j + 4), w.get_mut(j..j + 4)) else {
            break;
        };
        // The 4 × 4 triangle (j + 3 < stop ≤ NV).
        let x0 = wj[0] / r0[j];
        let x1 = (wj[1] - x0 * r0[j + 1]) / r1[j + 1];
        let x2 = ((wj[2] - x0 * r0[j + 2]) - x1 * r1[j + 2]) / r2[j + 2];
        let x3 = (((wj[3] - x0 * r0[j + 3]) - x1 * r1[j + 3]) - x2 * r2[j + 3]) / r3[j + 3];
        wj.copy_from_slice(&[x0, x1, x2, x3]);
        let lo = j + 4;
        if let Some(w) = w.get_mut(lo..end) {
            let r = [
                tail(r0, lo, end),
                tail(r1, lo, end),
                tail(r2, lo, end),
                tail(r3, lo, end),
            ];
            axpy4(w, [x0, x1, x2, x3], r);
        }
        j += 4;
    }
    while j < stop {
        let r = &u[j % NV];
        let x = w[j % NV] / r[j % NV];
        w[j % NV] = x;
        let lo = (j + 1).min(end);
        if let Some(w) = w.get_mut(lo..end) {
            axpy(w, x, tail(r, lo, end));
        }
        j += 1;
    }
}

/// `r[lo..end]`, or nothing where that range is not in `r` (never, by the callers' loop bounds:
/// a checked slice keeps a bounds-check panic path out of builds that cannot prove it).
#[inline(always)]
fn tail(r: &[Real], lo: usize, end: usize) -> &[Real] {
    r.get(lo..end).unwrap_or(&[])
}

/// Σ_{c<8} r_c x_c, in pairs (vectorises on SSE2).
#[inline]
fn dot8(r: &[Real; 8], x: &[Real; 8]) -> Real {
    ((r[0] * x[0] + r[4] * x[4]) + (r[1] * x[1] + r[5] * x[5]))
        + ((r[2] * x[2] + r[6] * x[6]) + (r[3] * x[3] + r[7] * x[7]))
}

/// Backward substitution Lᵀ x = y in place on `y[..nf]` (Lᵀ = `u`, upper triangular, by rows),
/// eight rows at a time from the bottom: solve the 8 × 8 diagonal block, then subtract its
/// contribution from every row above it (eight contiguous entries of each: fixed-length products,
/// no per-row loop overhead). `start[k]`: L's row k is zero before it, so the rows above
/// min(start) of a block have no entries in its columns.
fn backward<const NV: usize>(u: &[[Real; NV]; NV], y: &mut [Real; NV], nf: usize, start: &[usize; NV]) {
    let mut hi = nf.min(NV);
    while hi >= 8 {
        let lo = hi - 8;
        // The diagonal block, rows hi − 1 down to lo.
        for i in (lo..hi).rev() {
            triangle_row(u, y, i, hi);
        }
        // (Slices by `get`: no bounds check, no panic path.)
        let (Some(yb), Some(sb)) = (y.get(lo..hi), start.get(lo..hi)) else {
            break;
        };
        let Ok(xb) = <[Real; 8]>::try_from(yb) else {
            break;
        };
        let top = sb.iter().fold(lo, |m, &s| m.min(s));
        if let (Some(rows), Some(ys)) = (u.get(top..lo), y.get_mut(top..lo)) {
            for (row, yi) in rows.iter().zip(ys) {
                if let Some(Ok(r)) = row.get(lo..hi).map(<&[Real; 8]>::try_from) {
                    *yi -= dot8(r, &xb);
                }
            }
        }
        hi = lo;
    }
    for i in (0..hi).rev() {
        triangle_row(u, y, i, hi);
    }
}

/// y_i ← (y_i − Σ_{k in i+1..hi} u_ik y_k) / u_ii (one row of a backward substitution).
#[inline]
fn triangle_row<const NV: usize>(u: &[[Real; NV]; NV], y: &mut [Real; NV], i: usize, hi: usize) {
    let (Some(row), Some(&yi)) = (u.get(i), y.get(i)) else {
        return;
    };
    let mut s = yi;
    let (r, yk) = (row.get(i + 1..hi).unwrap_or(&[]), y.get(i + 1..hi).unwrap_or(&[]));
    for (r, yk) in r.iter().zip(yk) {
        s -= r * yk;
    }
    if let (Some(yi), Some(&pivot)) = (y.get_mut(i), row.get(i)) {
        *yi = s / pivot;
    }
}

/// Violated bounds that trigger a projection restart.
const RESTART_VIOLATIONS: usize = 2;
/// Projection restarts per solve (each costs a partial refactorisation).
const MAX_RESTARTS: usize = 30;
/// Variables freed per iteration at most (those with the most negative multipliers): freeing
/// every one at once after a reference jump mostly frees variables that the next projection
/// restart fixes again, each at the cost of a row of the factor. With the vectorised kernels
/// (cheaper rows, cheaper iterations) 16 gave the smallest slowest step of 4, 6, 10 and 16 on the
/// shipped models (6 before them); with the blocked factorisation (appended rows four at a time)
/// 32 gives the smallest sum of the two shipped models' slowest steps of 16, 32, 64 and NV
/// (docs/benchmarks.md, session 10).
const RELEASE_CAP: usize = 32;
/// A fresh factorisation orders the free variables last stage first.
const REVERSED_ORDER: bool = true;

/// Relative pivot tolerance of the factorisation.
const PIVOT_TOLERANCE: Real = 1e3 * Real::EPSILON;

impl<const NV: usize> BoxQp<NV> {
    /// All variables free, nothing factorised.
    pub const fn new() -> Self {
        let mut qp = Self::with_groups([0; NV]);
        // All zero bits (a static solver in .bss); 0 components reads as one.
        qp.groups = 0;
        qp
    }

    /// Set the components once (see [`Self::with_groups`]): a no-op if they are set already.
    /// Kept out of [`Self::new`] so that a new solver stays all zero bits (a static one then
    /// lands in .bss, not in flash).
    pub fn ensure_groups(&mut self, group: &[u8; NV]) {
        if self.groups == 0 {
            let with = Self::with_groups(*group);
            self.group = with.group;
            self.groups = with.groups;
        }
    }

    /// Like [`Self::new`] for an H whose variables fall into components that never couple:
    /// H_ij = 0 (exactly) whenever `group[i] != group[j]`. Fresh factorisations order the free
    /// variables by component (component 0 first), and the factorisation skips the exact zeros
    /// of the factor between components.
    pub const fn with_groups(group: [u8; NV]) -> Self {
        let mut groups = 0u8;
        let mut i = 0;
        while i < NV {
            if group[i] >= groups {
                groups = group[i].saturating_add(1);
            }
            i += 1;
        }
        Self {
            u: [[0.0; NV]; NV],
            free: [0; NV],
            nf: 0,
            state: [Bound::Free; NV],
            rhs: [0.0; NV],
            target: [0.0; NV],
            fixed_gradient: [0.0; NV],
            work: [0.0; NV],
            group,
            groups,
        }
    }

    /// Free variable number `i` (factor order), clamped so that indexing with
    /// it needs no bounds check (it is always < NV by construction).
    #[inline]
    fn var(&self, i: usize) -> usize {
        self.free[i % NV].min(NV - 1)
    }

    /// Number of free variables, ≤ NV.
    #[inline]
    fn free_count(&self) -> usize {
        self.nf.min(NV)
    }

    /// The working set (read access).
    #[allow(dead_code)] // used by tests; the MPC keeps its working set inside
    pub fn working_set(&self) -> &[Bound; NV] {
        &self.state
    }

    /// Replace the working set (e.g. a warm start); call [`Self::factorize`] afterwards.
    #[allow(dead_code)] // used by tests; the MPC keeps its working set inside
    pub fn set_working_set(&mut self, state: &[Bound; NV]) {
        self.state = *state;
    }

    /// Shift the working set by `block` variables (one MPC stage): variable i
    /// takes the state of i + block; the last block repeats.
    pub fn shift_working_set(&mut self, block: usize) {
        if block == 0 || block >= NV {
            return;
        }
        for i in 0..NV - block {
            self.state[i] = self.state[i + block];
        }
    }

    /// Cholesky factorisation of H_FF for the current working set:
    /// L Lᵀ = H_FF, row by row, L_ij = (H_ij − Σ_{k<j} L_ik L_jk) / L_jj.
    /// Fails if a pivot is ≤ tolerance · H_ii (H not numerically positive definite).
    pub fn factorize(&mut self, h: &[[Real; NV]; NV]) -> Result<(), QpStatus> {
        self.nf = 0;
        for g in 0..self.groups.max(1) {
            for k in 0..NV {
                let i = if REVERSED_ORDER { NV - 1 - k } else { k };
                if self.state[i] == Bound::Free && self.group[i] == g {
                    self.free[self.nf % NV] = i;
                    self.nf += 1;
                }
            }
        }
        self.factor_rows(h, 0)
    }

    /// Drop the variables that are no longer free from the factor, keeping the
    /// order of the others. The rows before the first dropped position are
    /// unchanged (the leading block of H_FF is), so only the rows from there
    /// on are recomputed. `plan`: [`Self::drop_plan`] for the current working set.
    fn drop_fixed(&mut self, h: &[[Real; NV]; NV], plan: DropPlan) -> Result<(), QpStatus> {
        let nf = self.free_count();
        if plan.by_rotations {
            for i in (0..nf).rev() {
                if self.state[self.var(i)] != Bound::Free {
                    self.remove(i);
                }
            }
            return Ok(());
        }
        let mut first = nf;
        let mut kept = 0;
        for i in 0..nf {
            let var = self.var(i);
            if self.state[var] == Bound::Free {
                self.free[kept % NV] = var;
                kept += 1;
            } else if first == nf {
                first = i;
            }
        }
        self.nf = kept;
        self.factor_rows(h, first)
    }

    /// How [`Self::drop_fixed`] is to drop the variables that are no longer free, and an upper
    /// bound of its multiply-adds: removing position p by rotations moves the rows below it and
    /// rotates the trailing block, ≤ (nf² − p²)/2 + 3 (nf − p)²; recomputing rows first..nf'
    /// costs ≤ [`rows_cost`]. The cheaper way is taken.
    fn drop_plan(&self) -> DropPlan {
        let nf = self.free_count();
        let (mut by_rotations, mut dropped, mut first) = (0usize, 0usize, nf);
        for i in 0..nf {
            if self.state[self.var(i)] != Bound::Free {
                by_rotations = by_rotations.saturating_add((nf * nf - i * i) / 2 + 3 * (nf - i) * (nf - i));
                dropped += 1;
                first = first.min(i);
            }
        }
        let kept = nf - dropped;
        // The choice compares the leading terms; the cost charged is the bound.
        if by_rotations < (kept * kept * kept).saturating_sub(first * first * first) / 6 {
            DropPlan {
                by_rotations: true,
                cost: by_rotations,
                dropped,
            }
        } else {
            DropPlan {
                by_rotations: false,
                cost: rows_cost(first.min(kept), kept),
                dropped,
            }
        }
    }

    /// Rows `from..nf` of the Cholesky factor of H_FF, rows before `from` given.
    ///
    /// Left-looking and blocked: four rows of L at a time (one where a block would cross a
    /// component boundary or the end), and in them four columns at a time,
    /// L_ij = (H_ij − Σ_{k<j} L_ik L_jk) / L_jj, i in the rows, j in the columns. The sums over
    /// k < (the block's first column) run as rank-one updates of a 4 × 4 register tile
    /// ([`tile`]; columns k of L are rows of `u`, so each k reads two contiguous runs of four),
    /// then the block's own triangle. Every L_ij is H_ij with the terms L_ik L_jk subtracted in
    /// ascending k, then divided: the same operations in the same order as the row-by-row forward
    /// substitution (and [`forward`]), so the factor is the same to the bit, with 16 multiply-adds
    /// per k held in registers instead of one load and store of the row per eight.
    fn factor_rows(&mut self, h: &[[Real; NV]; NV], from: usize) -> Result<(), QpStatus> {
        let nf = self.nf.min(NV);
        let free = self.free;
        let var = |i: usize| free[i % NV].min(NV - 1);
        let group = self.group;
        // First factor position of each component: L[i][..first[group of i]] is exactly zero.
        let grouped = self.groups > 1;
        let mut first = [0; NV];
        if grouped {
            first = [nf; NV];
            for i in (0..nf).rev() {
                first[usize::from(group[var(i)]) % NV] = i;
            }
        }
        let mut i0 = from;
        while i0 < nf {
            let g = group[var(i0)];
            let start = first[usize::from(g) % NV].min(i0);
            let whole = i0 + 4 <= nf && (1..4).all(|r| group[var(i0 + r)] == g);
            if whole {
                self.factor_block::<4>(h, &free, i0, start)?;
                i0 += 4;
            } else {
                self.factor_row(h, &free, i0, start)?;
                i0 += 1;
            }
        }
        Ok(())
    }

    /// Row i of L alone (a block of one): the forward substitution L₁₁ x = H_{F(start..i), F(i)}
    /// in column form ([`forward`], eight columns at a time along the row), then the pivot.
    fn factor_row(&mut self, h: &[[Real; NV]; NV], free: &[usize; NV], i: usize, start: usize) -> Result<(), QpStatus> {
        if i >= NV || start > i {
            return Ok(());
        }
        let var = |k: usize| free[k % NV].min(NV - 1);
        let hi = &h[var(i)];
        let w = &mut self.work;
        for (wk, &v) in w[start..i].iter_mut().zip(&free[start..i]) {
            *wk = hi[v.min(NV - 1)];
        }
        forward(&self.u, w, start, i, i);
        let s = hi[var(i)] - dot(&w[start..i], &w[start..i]);
        if !(s > PIVOT_TOLERANCE * hi[var(i)].abs()) {
            return Err(QpStatus::NotPositiveDefinite);
        }
        for (row, &x) in self.u.iter_mut().zip(&w[..i]).skip(start) {
            row[i] = x;
        }
        for row in self.u[..start].iter_mut() {
            row[i] = 0.0;
        }
        self.u[i][i] = sqrt(s);
        Ok(())
    }

    /// Rows i0..i0 + R of L (all of one component, whose first position is `start`), rows
    /// before i0 given: the columns start..i0 in 4-wide then 1-wide blocks, then the R × R
    /// diagonal block with its pivots. Entries before `start` are exact zeros.
    fn factor_block<const R: usize>(
        &mut self,
        h: &[[Real; NV]; NV],
        free: &[usize; NV],
        i0: usize,
        start: usize,
    ) -> Result<(), QpStatus> {
        if i0 + R > NV || start > i0 {
            return Ok(());
        }
        let var = |i: usize| free[i % NV].min(NV - 1);
        let rows: [usize; R] = core::array::from_fn(|r| var(i0 + r));
        let mut j0 = start;
        while j0 + 4 <= i0 {
            let mut acc: [[Real; R]; 4] = core::array::from_fn(|c| {
                let vj = var(j0 + c);
                core::array::from_fn(|r| h[rows[r]][vj])
            });
            tile(&self.u, start, j0, i0, j0, &mut acc);
            self.finish_columns(&mut acc, i0, j0);
            j0 += 4;
        }
        while j0 < i0 {
            let vj = var(j0);
            let mut acc: [[Real; R]; 1] = [core::array::from_fn(|r| h[rows[r]][vj])];
            tile(&self.u, start, j0, i0, j0, &mut acc);
            self.finish_columns(&mut acc, i0, j0);
            j0 += 1;
        }
        // The diagonal block: acc[c][r] for r > c is L_{i0+r, i0+c} once finished.
        let mut acc: [[Real; R]; R] = core::array::from_fn(|c| {
            let vc = var(i0 + c);
            core::array::from_fn(|r| h[rows[r]][vc])
        });
        tile(&self.u, start, i0, i0, i0, &mut acc);
        for c in 0..R {
            let q = i0 + c;
            if q >= NV {
                break;
            }
            // Row q of L over start..q (gathered), for its pivot: the order of `dot` as before.
            let w = &mut self.work;
            for (wk, row) in w[start..i0].iter_mut().zip(&self.u[start..i0]) {
                *wk = row[q];
            }
            if let Some(wb) = w.get_mut(i0..q) {
                for (wk, col) in wb.iter_mut().zip(&acc) {
                    *wk = col[c];
                }
            }
            let vq = var(q);
            let hq = h[vq][vq];
            let s = hq - dot(&w[start..q], &w[start..q]);
            if !(s > PIVOT_TOLERANCE * hq.abs()) {
                return Err(QpStatus::NotPositiveDefinite);
            }
            let pivot = sqrt(s);
            // Column q of L below the pivot, within the block.
            for r in c + 1..R {
                let mut v = acc[c][r];
                for c2 in 0..c {
                    v -= acc[c2][r] * acc[c2][c];
                }
                acc[c][r] = v / pivot;
            }
            // Column q of U (row q of L) is zero before `start`; start..i0 is stored by the
            // column blocks, i0..q below.
            for row in self.u[..start].iter_mut() {
                row[q] = 0.0;
            }
            self.u[q][q] = pivot;
        }
        for (c, col) in acc.iter().enumerate() {
            let Some(urow) = self.u.get_mut(i0 + c) else {
                break;
            };
            if let (Some(dst), Some(src)) = (urow.get_mut(i0 + c + 1..i0 + R), col.get(c + 1..R)) {
                dst.copy_from_slice(src);
            }
        }
        Ok(())
    }

    /// The triangle of a column block j0..j0 + C of rows i0..i0 + R (the sums over k < j0 done):
    /// acc[c][r] −= L_{i,j0+c2} L_{j0+c,j0+c2} for c2 < c in order, then / L_{j0+c,j0+c}; stored
    /// as column j0 + c of L (row of `u`).
    #[inline(always)]
    fn finish_columns<const R: usize, const C: usize>(&mut self, acc: &mut [[Real; R]; C], i0: usize, j0: usize) {
        if j0 + C > NV || i0 + R > NV {
            return;
        }
        for c in 0..C {
            let j = j0 + c;
            if j >= NV {
                break;
            }
            let (done, rest) = acc.split_at_mut(c);
            let Some(col) = rest.first_mut() else {
                break;
            };
            for (prev, urow) in done.iter().zip(&self.u[j0..j]) {
                let ljk = urow[j];
                for r in 0..R {
                    col[r] -= prev[r] * ljk;
                }
            }
            let pivot = self.u[j][j];
            for x in col.iter_mut() {
                *x /= pivot;
            }
            if let Some(dst) = self.u[j].get_mut(i0..i0 + R) {
                dst.copy_from_slice(col);
            }
        }
    }

    /// Solve L Lᵀ y = b in place on `rhs[..nf]`: forward substitution by columns (four at a
    /// time, as in [`Self::factor_rows`]), backward by rows of Lᵀ (dot products).
    fn solve_factored(&mut self) {
        let nf = self.free_count();
        let start = self.row_starts();
        let y = &mut self.rhs;
        // L y = b
        forward(&self.u, y, 0, nf, nf);
        // Lᵀ x = y: x_i = (y_i − Σ_{k>i} L_ki x_k) / L_ii, L_ki = u[i][k].
        backward(&self.u, y, nf, &start);
    }

    /// For each free position i, the first position of its component (0 for one component):
    /// L[i][..start[i]] is exactly zero (`with_groups`).
    fn row_starts(&self) -> [usize; NV] {
        let nf = self.free_count();
        let mut start = [0; NV];
        if self.groups <= 1 {
            return start;
        }
        let mut first = [nf; NV];
        for i in (0..nf).rev() {
            first[usize::from(self.group[self.var(i)]) % NV] = i;
        }
        for i in 0..nf {
            start[i] = first[usize::from(self.group[self.var(i)]) % NV].min(i);
        }
        start
    }

    /// Remove free position `p` from the factor. With L = [L11 0 0; l21ᵀ l22 0; L31 l32 L33],
    /// the factor of H_FF without p is [L11 0; L31 L33'] with L33' L33'ᵀ = L33 L33ᵀ + l32 l32ᵀ
    /// (a rank-one update by rotations, applied along the rows of U = Lᵀ).
    fn remove(&mut self, p: usize) {
        let nf = self.free_count();
        if p >= nf {
            return;
        }
        // x = l32 (column p of L below the diagonal = row p of U). (Slices by `get`: no bounds
        // check, no panic path.)
        if let (Some(t), Some(x)) = (self.target.get_mut(p..nf - 1), self.u[p % NV].get(p + 1..nf)) {
            for (t, x) in t.iter_mut().zip(x) {
                *t = *x;
            }
        }
        // Delete column p of U (row p of L) in the rows above p ...
        for row in self.u.iter_mut().take(p) {
            if let Some(seg) = row.get_mut(p..nf) {
                if seg.len() > 1 {
                    seg.copy_within(1.., 0);
                }
            }
        }
        // ... and row p of U, shifting the rows below it up and left by one.
        for k in p + 1..nf {
            let (head, tail) = self.u.split_at_mut(k.min(NV));
            if let (Some(dst), Some(src)) = (head.last_mut(), tail.first()) {
                for (d, s) in dst.iter_mut().skip(k - 1).zip(src.iter().skip(k)).take(nf - k) {
                    *d = *s;
                }
            }
        }
        for i in p..nf - 1 {
            self.free[i % NV] = self.free[(i + 1) % NV];
        }
        self.nf -= 1;
        let nf = self.free_count();
        // Rank-one update of the trailing block rows/cols p..nf by x = target[p..nf].
        for k in p..nf {
            let row = &mut self.u[k % NV];
            let lkk = row[k % NV];
            let xk = self.target[k % NV];
            let r = sqrt(lkk * lkk + xk * xk);
            let (c, s) = (r / lkk, xk / lkk);
            row[k % NV] = r;
            if let (Some(l), Some(t)) = (row.get_mut(k + 1..nf), self.target.get_mut(k + 1..nf)) {
                for (l, t) in l.iter_mut().zip(t.iter_mut()) {
                    let lik = (*l + s * *t) / c;
                    *t = c * *t - s * lik;
                    *l = lik;
                }
            }
        }
    }

    /// If at least [`RESTART_VIOLATIONS`] free variables of the subproblem's
    /// minimiser (in `rhs`) leave the box and its projection onto the box is no
    /// worse than `v`, move there and fix the violated variables at their bounds.
    fn try_projection_restart(
        &mut self,
        h: &[[Real; NV]; NV],
        lo: &[Real; NV],
        hi: &[Real; NV],
        v: &mut [Real; NV],
    ) -> bool {
        let violations = (0..self.free_count())
            .filter(|&i| {
                let var = self.var(i);
                self.rhs[i] < lo[var] || self.rhs[i] > hi[var]
            })
            .count();
        if violations < RESTART_VIOLATIONS {
            return false;
        }
        // On F (v_W fixed) the objective is q(x*) + ½ (x − x*)ᵀ H_FF (x − x*), x* = rhs, and
        // (x − x*)ᵀ H_FF (x − x*) = ‖Lᵀ (x − x*)‖²: compare the projection p with v by that.
        // p − x* is zero except at the k violated variables, so its term is a k × k quadratic
        // form in H (k²/2 multiply-adds) when that is cheaper than the triangular product (nf²/2).
        let nf = self.free_count();
        let at_projection = if violations * violations < nf * nf {
            self.projection_form(h, lo, hi)
        } else {
            for i in 0..nf {
                let var = self.var(i);
                self.target[i] = self.rhs[i].max(lo[var]).min(hi[var]) - self.rhs[i];
            }
            self.factor_norm()
        };
        for i in 0..nf {
            self.target[i] = v[self.var(i)] - self.rhs[i];
        }
        if !(at_projection < self.factor_norm()) {
            return false;
        }
        for i in 0..nf {
            let var = self.var(i);
            let bound = if self.rhs[i] < lo[var] {
                Bound::Lower
            } else if self.rhs[i] > hi[var] {
                Bound::Upper
            } else {
                v[var] = self.rhs[i];
                continue;
            };
            v[var] = if bound == Bound::Lower { lo[var] } else { hi[var] };
            self.state[var] = bound;
            self.add_fixed(h, var, v[var]);
        }
        true
    }

    /// zᵀ H_FF z for z = (the projection of `rhs` onto the box) − `rhs`, which is zero except at
    /// the violated variables: a quadratic form in H over those only.
    fn projection_form(&self, h: &[[Real; NV]; NV], lo: &[Real; NV], hi: &[Real; NV]) -> Real {
        let mut violated = [(0, 0.0 as Real); NV];
        let mut k = 0;
        for i in 0..self.free_count() {
            let var = self.var(i);
            let z = self.rhs[i].max(lo[var]).min(hi[var]) - self.rhs[i];
            if z != 0.0 {
                violated[k % NV] = (var, z);
                k += 1;
            }
        }
        let mut sum = 0.0;
        for (a, &(va, za)) in violated[..k.min(NV)].iter().enumerate() {
            // va, vb < NV (they are `var`s); `% NV` says so, so that no bounds check (panic path)
            // is left in the solve loop.
            let (va, row) = (va % NV, &h[va % NV]);
            let mut cross = 0.0;
            for &(vb, zb) in &violated[..a] {
                cross += row[vb % NV] * zb;
            }
            sum += za * (row[va] * za + 2.0 * cross);
        }
        sum
    }

    /// ‖Lᵀ z‖² for z = target[..nf] (factor order).
    fn factor_norm(&mut self) -> Real {
        let nf = self.free_count();
        // (Lᵀ z)_j = Σ_{i ≥ j} L_ij z_i = u[j][j..nf] · z[j..nf].
        let mut sum = 0.0;
        for j in 0..nf {
            let y = dot(&self.u[j][j..nf], &self.target[j..nf]);
            sum += y * y;
        }
        sum
    }

    /// At a step of length 0: every free variable that sits at a bound while the direction
    /// `rhs − v` leaves the box there blocks. Fix all of them at once (objective and iterate
    /// unchanged) — except that if they include every variable of the last release (`fresh`, the
    /// iterate not moved since), the last of those stays free: fixing them all would restore the
    /// working set before the release, whose minimiser is the iterate, and cycle; with one of
    /// them free the next step strictly descends (it was released for a negative multiplier).
    /// (In exact arithmetic that cannot happen — the direction descends, and only the released
    /// variables have a non-zero gradient, so one of them moves inward — but rounding can.)
    /// Returns false, changing nothing, if at most one variable would be fixed (the caller fixes
    /// the first blocking one as before).
    fn fix_degenerate(
        &mut self,
        h: &[[Real; NV]; NV],
        lo: &[Real; NV],
        hi: &[Real; NV],
        v: &mut [Real; NV],
        fresh: &mut [bool; NV],
    ) -> bool {
        let nf = self.free_count();
        // Free position i (variable var) sits at the bound its direction leaves by.
        let blocks = |rhs: &[Real; NV], v: &[Real; NV], i: usize, var: usize| {
            let d = rhs[i % NV] - v[var];
            (d < 0.0 && v[var] <= lo[var]) || (d > 0.0 && v[var] >= hi[var])
        };
        let (mut blocking, mut fresh_blocking, mut keep) = (0, 0, NV);
        for i in 0..nf {
            let var = self.var(i);
            if blocks(&self.rhs, v, i, var) {
                blocking += 1;
                if fresh[var] {
                    fresh_blocking += 1;
                    keep = var;
                }
            }
        }
        if fresh_blocking == 0 || fresh_blocking < fresh.iter().filter(|f| **f).count() {
            keep = NV;
        }
        if blocking - usize::from(keep < NV) < 2 {
            return false;
        }
        for i in 0..nf {
            let var = self.var(i);
            if var != keep && blocks(&self.rhs, v, i, var) {
                let bound = if self.rhs[i] < v[var] {
                    Bound::Lower
                } else {
                    Bound::Upper
                };
                v[var] = if bound == Bound::Lower { lo[var] } else { hi[var] };
                self.state[var] = bound;
                fresh[var] = false;
                self.add_fixed(h, var, v[var]);
            }
        }
        true
    }

    /// `work` = H v = H_{·W} v_W (`fixed_gradient`) + Σ_{k∈F} v_k H_{·k} (H is symmetric: rows of
    /// H, four at a time).
    fn hv_by_free_rows(&mut self, h: &[[Real; NV]; NV], v: &[Real; NV]) {
        self.work = self.fixed_gradient;
        let nf = self.free_count();
        let mut i = 0;
        while i + 4 <= nf {
            let vars = [self.var(i), self.var(i + 1), self.var(i + 2), self.var(i + 3)];
            // axpy4 subtracts: z − (−v_k) H_k.
            let x = vars.map(|var| -v[var]);
            axpy4(&mut self.work, x, vars.map(|var| &h[var][..]));
            i += 4;
        }
        while i < nf {
            let var = self.var(i);
            axpy(&mut self.work, -v[var], &h[var]);
            i += 1;
        }
    }

    /// `fixed_gradient` += H_{·,var} value (H is symmetric: its row `var`).
    fn add_fixed(&mut self, h: &[[Real; NV]; NV], var: usize, value: Real) {
        if value != 0.0 {
            for (w, hv) in self.fixed_gradient.iter_mut().zip(&h[var % NV]) {
                *w += hv * value;
            }
        }
    }

    /// Solve from `v` (clamped into the box) with the current working set;
    /// [`Self::factorize`] must have been called for it with the same `h`.
    /// `v` holds the solution (or the best bounded iterate) on return.
    ///
    /// At most `max_iterations` iterations and `max_work` multiply-adds: each costly operation
    /// (setting up the fixed variables' gradient, a pair of triangular solves, a projection
    /// restart, a removal from the factor, the multipliers, appending rows) is charged an upper
    /// bound of its multiply-adds before it runs; if that does not fit, the solve stops with
    /// [`QpStatus::IterationCap`] at the current iterate, which is feasible and no worse than the
    /// start (a restart that would not fit is skipped instead). The multiply-adds of one solve are
    /// then at most `max_work` plus O(NV) bookkeeping per iteration, whatever the data.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        h: &[[Real; NV]; NV],
        g: &[Real; NV],
        lo: &[Real; NV],
        hi: &[Real; NV],
        v: &mut [Real; NV],
        max_iterations: usize,
        max_work: usize,
    ) -> QpResult {
        let mut budget = Budget {
            spent: 0,
            max: max_work,
        };
        for i in 0..NV {
            v[i] = match self.state[i] {
                Bound::Lower => lo[i],
                Bound::Upper => hi[i],
                Bound::Free => v[i].max(lo[i]).min(hi[i]),
            };
        }
        self.fixed_gradient = [0.0; NV];
        let mut iterations = 0;
        let capped = |iterations: usize, budget: &Budget| QpResult {
            status: QpStatus::IterationCap,
            iterations,
            work: budget.spent,
        };
        if !budget.charge((NV - self.free_count()) * NV) {
            return capped(iterations, &budget);
        }
        for j in 0..NV {
            if self.state[j] != Bound::Free {
                self.add_fixed(h, j, v[j]);
            }
        }
        let scale = g.iter().fold(1.0 as Real, |m, x| m.max(x.abs()));
        let tolerance = 10.0 * Real::EPSILON * scale;
        let mut restarts = 0;
        // The variables freed by the last release, while the iterate has not moved since.
        let mut fresh = [false; NV];
        while iterations < max_iterations {
            let nf = self.free_count();
            if !budget.charge(nf * nf + 2 * nf) {
                return capped(iterations, &budget);
            }
            iterations += 1;
            // rhs = −(g_F + H_FW v_W)
            for i in 0..self.free_count() {
                let var = self.var(i);
                self.rhs[i] = -(g[var] + self.fixed_gradient[var]);
            }
            self.solve_factored();
            // Many bounds violated at once (e.g. after a reference jump): instead of
            // fixing them one per iteration, jump to the projection of v_F* onto the
            // box, fix every violated variable and refactorise — if that does not
            // increase the objective. At most MAX_RESTARTS times per solve.
            // (Only if the budget holds its test, fixing every free variable and refactorising
            // all of them: what it charges below then fits.)
            let restart_bound = (2 * nf * nf + nf * NV).saturating_add(rows_cost(0, nf).max(7 * nf * nf));
            if restarts < MAX_RESTARTS
                && budget.fits(restart_bound)
                && budget.charge(2 * nf * nf)
                && self.try_projection_restart(h, lo, hi, v)
            {
                restarts += 1;
                fresh = [false; NV];
                let plan = self.drop_plan();
                budget.charge((plan.dropped * NV).saturating_add(plan.cost));
                if self.drop_fixed(h, plan).is_err() {
                    return QpResult {
                        status: QpStatus::NotPositiveDefinite,
                        iterations,
                        work: budget.spent,
                    };
                }
                continue;
            }
            // Largest α ≤ 1 keeping v_F + α (v_F* − v_F) in the box.
            let mut alpha: Real = 1.0;
            let mut blocking = None;
            for i in 0..self.free_count() {
                let var = self.var(i);
                let d = self.rhs[i] - v[var];
                let (limit, bound) = if d < 0.0 {
                    (lo[var], Bound::Lower)
                } else {
                    (hi[var], Bound::Upper)
                };
                if d != 0.0 {
                    let a = (limit - v[var]) / d;
                    if a < alpha {
                        alpha = a.max(0.0);
                        blocking = Some((i, bound));
                    }
                }
            }
            for i in 0..self.free_count() {
                let var = self.var(i);
                v[var] += alpha * (self.rhs[i] - v[var]);
            }
            if alpha > 0.0 {
                fresh = [false; NV];
            }
            if let Some((p, bound)) = blocking {
                // A step of length 0 with several blocking variables (typically after a release
                // of several variables, some of which the joint direction pushes out again):
                // fix them all at once instead of one per iteration.
                if alpha == 0.0 && self.fix_degenerate(h, lo, hi, v, &mut fresh) {
                    // The iterate did not move (α = 0); the variables just fixed sit at their bounds.
                    let plan = self.drop_plan();
                    if !budget.charge((plan.dropped * NV).saturating_add(plan.cost)) {
                        return capped(iterations, &budget);
                    }
                    if self.drop_fixed(h, plan).is_err() {
                        return QpResult {
                            status: QpStatus::NotPositiveDefinite,
                            iterations,
                            work: budget.spent,
                        };
                    }
                    continue;
                }
                if !budget.charge(NV + (nf * nf - p * p) / 2 + 3 * (nf - p) * (nf - p)) {
                    return capped(iterations, &budget);
                }
                let var = self.var(p);
                v[var] = if bound == Bound::Lower { lo[var] } else { hi[var] };
                self.state[var] = bound;
                fresh[var] = false;
                self.add_fixed(h, var, v[var]);
                self.remove(p);
                continue;
            }
            // At the subproblem's minimiser: multipliers of the working set. The variables with
            // the RELEASE_CAP most negative multipliers are freed: the subproblem on the larger
            // free set has a lower minimum, and the step towards it is a descent direction that
            // the step rule keeps feasible. Their rows are appended to the factor together
            // (`factor_rows` from the old nf, one forward substitution each): the factor one append
            // each would give, up to rounding.
            // (Hv)_W: with fewer free than fixed variables as H_{·W} v_W (kept) + Σ_{k∈F} v_k H_k
            // (rows of H, four at a time), else one product with H per fixed variable.
            let by_free_rows = self.free_count() < NV - self.free_count();
            if !budget.charge(nf.min(NV - nf) * NV) {
                return capped(iterations, &budget);
            }
            if by_free_rows {
                self.hv_by_free_rows(h, v);
            }
            let mut chosen = [(0.0 as Real, NV); RELEASE_CAP]; // most negative first; NV: empty
            for j in 0..NV {
                let sign = match self.state[j] {
                    Bound::Free => continue,
                    Bound::Lower => 1.0,
                    Bound::Upper => -1.0,
                };
                let hv = if by_free_rows { self.work[j] } else { dot(&h[j], &v[..]) };
                let mut entry = (sign * (g[j] + hv), j);
                if !(entry.0 < -tolerance) {
                    continue;
                }
                for slot in chosen.iter_mut() {
                    if slot.1 == NV || entry.0 < slot.0 {
                        core::mem::swap(slot, &mut entry);
                        if entry.1 == NV {
                            break;
                        }
                    }
                }
            }
            // Released in variable order (a deterministic factor order): flag the chosen, then walk
            // the variables (no sort: core's sort of more than 20 entries links a panic path).
            let mut flagged = [false; NV];
            let mut count = 0;
            for &(_, j) in chosen.iter().filter(|c| c.1 < NV) {
                flagged[j % NV] = true;
                count += 1;
            }
            if count > 0 && !budget.charge((count * NV).saturating_add(rows_cost(nf, (nf + count).min(NV)))) {
                return capped(iterations, &budget);
            }
            let mut released = 0;
            fresh = [false; NV];
            let kept = self.free_count();
            for j in (0..NV).filter(|&j| flagged[j]) {
                self.free[(kept + released) % NV] = j;
                self.state[j] = Bound::Free;
                self.add_fixed(h, j, -v[j]);
                fresh[j] = true;
                released += 1;
            }
            if released == 0 {
                return QpResult {
                    status: QpStatus::Optimal,
                    iterations,
                    work: budget.spent,
                };
            }
            self.nf = (kept + released).min(NV);
            if self.factor_rows(h, kept).is_err() {
                return QpResult {
                    status: QpStatus::NotPositiveDefinite,
                    iterations,
                    work: budget.spent,
                };
            }
        }
        capped(iterations, &budget)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ½ vᵀHv + gᵀv
    fn objective<const NV: usize>(h: &[[Real; NV]; NV], g: &[Real; NV], v: &[Real; NV]) -> Real {
        let mut f = 0.0;
        for i in 0..NV {
            f += g[i] * v[i];
            for j in 0..NV {
                f += 0.5 * v[i] * h[i][j] * v[j];
            }
        }
        f
    }

    /// KKT of the box QP: gradient zero on free variables, sign-correct at bounds.
    fn assert_kkt<const NV: usize>(
        h: &[[Real; NV]; NV],
        g: &[Real; NV],
        lo: &[Real; NV],
        hi: &[Real; NV],
        v: &[Real; NV],
    ) {
        for i in 0..NV {
            assert!(
                v[i] >= lo[i] && v[i] <= hi[i],
                "v[{i}] = {} outside [{}, {}]",
                v[i],
                lo[i],
                hi[i]
            );
            let mut grad = g[i];
            for j in 0..NV {
                grad += h[i][j] * v[j];
            }
            if v[i] > lo[i] && v[i] < hi[i] {
                assert!(grad.abs() < 1e-9, "free v[{i}] has gradient {grad}");
            } else if v[i] == lo[i] {
                assert!(grad > -1e-9, "v[{i}] at lower bound with gradient {grad}");
            } else {
                assert!(grad < 1e-9, "v[{i}] at upper bound with gradient {grad}");
            }
        }
    }

    #[test]
    fn unconstrained_two_by_two_by_hand() {
        // H = [[2, 1], [1, 2]], g = [−1, −1]: v* = H⁻¹[1, 1] = [1/3, 1/3].
        let h = [[2.0, 1.0], [1.0, 2.0]];
        let g = [-1.0, -1.0];
        let (lo, hi) = ([-10.0; 2], [10.0; 2]);
        let mut qp = BoxQp::<2>::new();
        qp.factorize(&h).unwrap();
        let mut v = [0.0; 2];
        let r = qp.solve(&h, &g, &lo, &hi, &mut v, 10, usize::MAX);
        assert_eq!(r.status, QpStatus::Optimal);
        assert!((v[0] - 1.0 / 3.0).abs() < 1e-15 && (v[1] - 1.0 / 3.0).abs() < 1e-15);
        assert_eq!(r.iterations, 1);
    }

    #[test]
    fn active_bound_by_hand() {
        // Same H, g = [−4, 0]: unconstrained v* = [8/3, −4/3]; with v0 ≤ 1 the
        // optimum is v0 = 1, v1 = −1/2 (∂/∂v1: v0 + 2 v1 = 0), multiplier of v0: 2 + v1 − 4 = −2.5 < 0 → upper bound holds.
        let h = [[2.0, 1.0], [1.0, 2.0]];
        let g = [-4.0, 0.0];
        let (lo, hi) = ([-10.0, -10.0], [1.0, 10.0]);
        let mut qp = BoxQp::<2>::new();
        qp.factorize(&h).unwrap();
        let mut v = [0.0; 2];
        let r = qp.solve(&h, &g, &lo, &hi, &mut v, 10, usize::MAX);
        assert_eq!(r.status, QpStatus::Optimal);
        assert_eq!(v[0], 1.0);
        assert!((v[1] + 0.5).abs() < 1e-15);
        assert_eq!(qp.working_set(), &[Bound::Upper, Bound::Free]);
        // Warm start from the optimal working set: one iteration.
        qp.factorize(&h).unwrap();
        let mut v = [0.0; 2];
        let r = qp.solve(&h, &g, &lo, &hi, &mut v, 10, usize::MAX);
        assert_eq!((r.status, r.iterations), (QpStatus::Optimal, 1));
    }

    #[test]
    fn releases_a_wrongly_fixed_variable() {
        let h = [[2.0, 1.0], [1.0, 2.0]];
        let g = [-1.0, -1.0];
        let (lo, hi) = ([-10.0; 2], [10.0; 2]);
        let mut qp = BoxQp::<2>::new();
        qp.set_working_set(&[Bound::Lower, Bound::Upper]);
        qp.factorize(&h).unwrap();
        let mut v = [0.0; 2];
        let r = qp.solve(&h, &g, &lo, &hi, &mut v, 10, usize::MAX);
        assert_eq!(r.status, QpStatus::Optimal);
        assert!((v[0] - 1.0 / 3.0).abs() < 1e-14 && (v[1] - 1.0 / 3.0).abs() < 1e-14);
        // Both multipliers are negative: both are freed in the first iteration.
        assert_eq!(r.iterations, 2);
    }

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

    fn random_problem<const NV: usize>(rng: &mut Lcg) -> ([[Real; NV]; NV], [Real; NV], [Real; NV], [Real; NV]) {
        // H = MᵀM + 0.1 I
        let mut m = [[0.0; NV]; NV];
        for row in m.iter_mut() {
            for x in row.iter_mut() {
                *x = rng.next();
            }
        }
        let mut h = [[0.0; NV]; NV];
        for i in 0..NV {
            for j in 0..NV {
                for k in 0..NV {
                    h[i][j] += m[k][i] * m[k][j];
                }
            }
            h[i][i] += 0.1;
        }
        let g = core::array::from_fn(|_| 3.0 * rng.next());
        let lo = core::array::from_fn(|_| -0.5 - 0.5 * rng.next().abs());
        let hi = core::array::from_fn(|_| 0.5 + 0.5 * rng.next().abs());
        (h, g, lo, hi)
    }

    #[test]
    fn random_problems_satisfy_kkt_cold_and_warm() {
        let mut rng = Lcg(42);
        for _ in 0..200 {
            let (h, g, lo, hi) = random_problem::<12>(&mut rng);
            let mut qp = BoxQp::<12>::new();
            qp.factorize(&h).unwrap();
            let mut v = [0.0; 12];
            let r = qp.solve(&h, &g, &lo, &hi, &mut v, 200, usize::MAX);
            assert_eq!(r.status, QpStatus::Optimal);
            assert_kkt(&h, &g, &lo, &hi, &v);
            // Warm start from the optimal working set with a perturbed gradient.
            let g2: [Real; 12] = core::array::from_fn(|i| g[i] + 0.1 * rng.next());
            qp.factorize(&h).unwrap();
            let mut w = [0.0; 12];
            let r2 = qp.solve(&h, &g2, &lo, &hi, &mut w, 200, usize::MAX);
            assert_eq!(r2.status, QpStatus::Optimal);
            assert_kkt(&h, &g2, &lo, &hi, &w);
        }
    }

    #[test]
    fn iteration_cap_returns_a_bounded_iterate_no_worse_than_the_start() {
        let mut rng = Lcg(7);
        for _ in 0..50 {
            let (h, g, lo, hi) = random_problem::<12>(&mut rng);
            let mut qp = BoxQp::<12>::new();
            qp.factorize(&h).unwrap();
            let mut v = [0.0; 12];
            let start = objective(&h, &g, &v);
            let r = qp.solve(&h, &g, &lo, &hi, &mut v, 2, usize::MAX);
            assert!(r.iterations <= 2);
            for i in 0..12 {
                assert!(v[i] >= lo[i] && v[i] <= hi[i] && v[i].is_finite());
            }
            assert!(objective(&h, &g, &v) <= start + 1e-12);
        }
    }

    #[test]
    fn work_budget_bounds_the_solve_and_changes_nothing_when_it_does_not_bind() {
        // Cold solves (every variable free) of problems whose minimiser leaves the box in many
        // places: restarts, removals and releases. A budget with room for the unbounded solve's
        // work changes nothing; smaller ones stop it at a feasible iterate no worse than the
        // start, with no more work charged than allowed.
        const N: usize = 40;
        let mut rng = Lcg(53);
        let mut binding = 0;
        for _ in 0..20 {
            let (h, mut g, lo, hi) = random_problem::<N>(&mut rng);
            for x in g.iter_mut() {
                *x *= 10.0;
            }
            let mut qp = BoxQp::<N>::new();
            qp.factorize(&h).unwrap();
            let mut free = [0.0; N];
            let full = qp.solve(&h, &g, &lo, &hi, &mut free, 200, usize::MAX);
            assert_eq!(full.status, QpStatus::Optimal);
            assert!(full.work > 0);
            let start = objective(&h, &g, &[0.0; N]);
            // A restart runs only if the budget holds its worst case (fixing and refactorising
            // every free variable), so the unbounded path is kept once that much is spare.
            let spare = full.work + 2 * N * N + N * N + rows_cost(0, N);
            for budget in [0, full.work / 10, full.work / 3, full.work - 1, spare] {
                let mut qp = BoxQp::<N>::new();
                qp.factorize(&h).unwrap();
                let mut v = [0.0; N];
                let r = qp.solve(&h, &g, &lo, &hi, &mut v, 200, budget);
                assert!(r.work <= budget, "charged {} > budget {budget}", r.work);
                for i in 0..N {
                    assert!(v[i] >= lo[i] && v[i] <= hi[i] && v[i].is_finite());
                }
                assert!(objective(&h, &g, &v) <= start + 1e-9);
                if budget == spare {
                    assert_eq!(r, full);
                    assert_eq!(v, free);
                } else {
                    binding += usize::from(r.status == QpStatus::IterationCap);
                }
            }
        }
        assert!(binding >= 40, "the smaller budgets bound only {binding} of 80 solves");
    }

    #[test]
    fn decoupled_components_match_the_one_component_solver() {
        // Variables alternate between three components (as inputs of interleaved stages do);
        // H has exact zeros between components. The grouped solver must agree with the plain one,
        // and its factor must have exact zeros between components through removals, appends and
        // partial refactorisations.
        const G: [u8; 12] = [0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2];
        let mut rng = Lcg(19);
        for _ in 0..100 {
            let (mut h, g, lo, hi) = random_problem::<12>(&mut rng);
            for i in 0..12 {
                for j in 0..12 {
                    if G[i] != G[j] {
                        h[i][j] = 0.0;
                    }
                }
            }
            let (mut plain, mut grouped) = (BoxQp::<12>::new(), BoxQp::<12>::with_groups(G));
            plain.factorize(&h).unwrap();
            grouped.factorize(&h).unwrap();
            // Fresh order: component 0 first.
            assert!(grouped.free[..4].iter().all(|&v| G[v] == 0));
            let (mut v, mut w) = ([0.0; 12], [0.0; 12]);
            let r = plain.solve(&h, &g, &lo, &hi, &mut v, 200, usize::MAX);
            let s = grouped.solve(&h, &g, &lo, &hi, &mut w, 200, usize::MAX);
            assert_eq!(s.status, QpStatus::Optimal);
            assert_eq!(r.status, QpStatus::Optimal);
            assert_kkt(&h, &g, &lo, &hi, &w);
            for i in 0..12 {
                assert!((v[i] - w[i]).abs() < 1e-10, "v[{i}] = {} vs {}", v[i], w[i]);
            }
            for i in 0..grouped.nf {
                for j in 0..i {
                    if G[grouped.free[i]] != G[grouped.free[j]] {
                        assert_eq!(grouped.u[j][i], 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn blocked_kernels_on_a_size_that_is_no_multiple_of_eight() {
        // 37 variables: the substitutions' blocks of eight, four and one, the backward blocks and
        // the top rows; two components (the first 13 variables and the rest) for the skips.
        const N: usize = 37;
        let group: [u8; N] = core::array::from_fn(|i| u8::from(i >= 13));
        let mut rng = Lcg(29);
        for _ in 0..20 {
            let (mut h, g, lo, hi) = random_problem::<N>(&mut rng);
            let (mut plain, mut grouped) = (BoxQp::<N>::new(), BoxQp::<N>::with_groups(group));
            plain.factorize(&h).unwrap();
            // L Lᵀ = H_FF.
            for i in 0..N {
                for j in 0..=i {
                    let s: Real = (0..=j).map(|k| plain.u[k][i] * plain.u[k][j]).sum();
                    let expect = h[plain.free[i]][plain.free[j]];
                    assert!(
                        (s - expect).abs() < 1e-10 * expect.abs().max(1.0),
                        "({i}, {j}): {s} vs {expect}"
                    );
                }
            }
            let mut v = [0.0; N];
            assert_eq!(
                plain.solve(&h, &g, &lo, &hi, &mut v, 200, usize::MAX).status,
                QpStatus::Optimal
            );
            assert_kkt(&h, &g, &lo, &hi, &v);
            for i in 0..N {
                for j in 0..N {
                    if group[i] != group[j] {
                        h[i][j] = 0.0;
                    }
                }
            }
            plain.set_working_set(&[Bound::Free; N]);
            plain.factorize(&h).unwrap();
            grouped.factorize(&h).unwrap();
            let (mut v, mut w) = ([0.0; N], [0.0; N]);
            assert_eq!(
                plain.solve(&h, &g, &lo, &hi, &mut v, 200, usize::MAX).status,
                QpStatus::Optimal
            );
            assert_eq!(
                grouped.solve(&h, &g, &lo, &hi, &mut w, 200, usize::MAX).status,
                QpStatus::Optimal
            );
            assert_kkt(&h, &g, &lo, &hi, &w);
            for i in 0..N {
                assert!((v[i] - w[i]).abs() < 1e-10, "v[{i}] = {} vs {}", v[i], w[i]);
            }
        }
    }

    /// The textbook recursion in the order the blocked factorisation keeps: L_ij = (H_ij −
    /// Σ_{k<j} L_ik L_jk, k ascending) / L_jj, L_ii = √(H_ii − dot(L_i·, L_i·)), zero between
    /// components.
    fn reference_factor<const N: usize>(qp: &BoxQp<N>, h: &[[Real; N]; N]) -> [[Real; N]; N] {
        let nf = qp.free_count();
        let mut l = [[0.0; N]; N];
        for i in 0..nf {
            let (vi, gi) = (qp.var(i), qp.group[qp.var(i)]);
            for j in 0..i {
                let vj = qp.var(j);
                if qp.groups > 1 && qp.group[vj] != gi {
                    continue;
                }
                let mut s = h[vi][vj];
                for k in 0..j {
                    if qp.groups <= 1 || qp.group[qp.var(k)] == gi {
                        s -= l[i][k] * l[j][k];
                    }
                }
                l[i][j] = s / l[j][j];
            }
            let start = (0..i)
                .find(|&k| qp.groups <= 1 || qp.group[qp.var(k)] == gi)
                .unwrap_or(i);
            l[i][i] = sqrt(h[vi][vi] - dot(&l[i][start..i], &l[i][start..i]));
        }
        l
    }

    #[test]
    fn blocked_factorisation_equals_the_textbook_recursion_to_the_bit() {
        // 23 and 30 variables (blocks of four and single rows and columns), one component and
        // three interleaved ones (blocks cut at component boundaries), whole and from a middle row.
        fn check<const N: usize>(seed: u64, groups: bool) {
            let mut rng = Lcg(seed);
            let group: [u8; N] = core::array::from_fn(|i| if groups { (i % 3) as u8 } else { 0 });
            let (mut h, _, _, _) = random_problem::<N>(&mut rng);
            for i in 0..N {
                for j in 0..N {
                    if group[i] != group[j] {
                        h[i][j] = 0.0;
                    }
                }
            }
            let mut qp = if groups {
                BoxQp::<N>::with_groups(group)
            } else {
                BoxQp::<N>::new()
            };
            let mut state = [Bound::Free; N];
            state[5] = Bound::Lower;
            state[N - 2] = Bound::Upper;
            qp.set_working_set(&state);
            qp.factorize(&h).unwrap();
            let expect = reference_factor(&qp, &h);
            let nf = qp.free_count();
            for i in 0..nf {
                for j in 0..=i {
                    assert_eq!(qp.u[j][i].to_bits(), expect[i][j].to_bits(), "L[{i}][{j}]");
                }
            }
            // Rows 9.. again, the rows before kept: the same factor.
            for row in qp.u.iter_mut() {
                for x in row[9..].iter_mut() {
                    *x = Real::NAN;
                }
            }
            qp.factor_rows(&h, 9).unwrap();
            for i in 0..nf {
                for j in 0..=i {
                    assert_eq!(qp.u[j][i].to_bits(), expect[i][j].to_bits(), "from 9: L[{i}][{j}]");
                }
            }
        }
        check::<23>(31, false);
        check::<23>(37, true);
        check::<30>(41, false);
        check::<30>(43, true);
    }

    #[test]
    fn indefinite_hessian_is_reported() {
        let h = [[1.0, 2.0], [2.0, 1.0]];
        let mut qp = BoxQp::<2>::new();
        assert_eq!(qp.factorize(&h), Err(QpStatus::NotPositiveDefinite));
    }

    #[test]
    fn dropping_fixed_variables_matches_a_fresh_factorisation() {
        let mut rng = Lcg(11);
        let (h, _, _, _) = random_problem::<10>(&mut rng);
        let mut qp = BoxQp::<10>::new();
        qp.factorize(&h).unwrap();
        // Rows 0 and 1 of L: L00, L10, L11.
        let old_first_rows = [qp.u[0][0], qp.u[0][1], qp.u[1][1]];
        // Fix the variables at positions 2, 3 and 7: rows 0 and 1 are kept, the rest recomputed.
        let fixed = [qp.free[2], qp.free[3], qp.free[7]];
        for &var in &fixed {
            qp.state[var] = Bound::Upper;
        }
        let plan = qp.drop_plan();
        qp.drop_fixed(&h, plan).unwrap();
        assert_eq!(qp.nf, 7);
        assert_eq!([qp.u[0][0], qp.u[0][1], qp.u[1][1]], old_first_rows);
        assert!(qp.free[..qp.nf].iter().all(|v| !fixed.contains(v)));
        for i in 0..qp.nf {
            for j in 0..=i {
                let s: Real = (0..=j).map(|k| qp.u[k][i] * qp.u[k][j]).sum();
                let expect = h[qp.free[i]][qp.free[j]];
                assert!((s - expect).abs() < 1e-12, "(LLᵀ)[{i}][{j}] = {s} vs {expect}");
            }
        }
    }

    #[test]
    fn the_restart_tests_sparse_form_matches_the_factor_norm() {
        let mut rng = Lcg(23);
        for _ in 0..20 {
            let (h, _, lo, hi) = random_problem::<10>(&mut rng);
            let mut qp = BoxQp::<10>::new();
            qp.state[4] = Bound::Lower;
            qp.factorize(&h).unwrap();
            for i in 0..qp.nf {
                qp.rhs[i] = 2.0 * rng.next();
            }
            let sparse = qp.projection_form(&h, &lo, &hi);
            for i in 0..qp.nf {
                let var = qp.free[i];
                qp.target[i] = qp.rhs[i].max(lo[var]).min(hi[var]) - qp.rhs[i];
            }
            let dense = qp.factor_norm();
            assert!(dense > 0.0);
            assert!((sparse - dense).abs() <= 1e-12 * dense, "{sparse} vs {dense}");
        }
    }

    #[test]
    fn a_zero_length_step_fixes_every_blocking_variable() {
        // Free variables 0 and 1 sit at their lower bounds, 2 at its upper bound, 3 inside; the
        // subproblem's minimiser leaves the box at 0 and 2 and moves 1 and 3 inward: both
        // blocking ones are fixed at once (no release to protect: nothing is fresh).
        let h = [
            [4.0, 1.0, 0.0, 0.0],
            [1.0, 4.0, 1.0, 0.0],
            [0.0, 1.0, 4.0, 1.0],
            [0.0, 0.0, 1.0, 4.0],
        ];
        let (lo, hi) = ([-1.0; 4], [1.0; 4]);
        let mut qp = BoxQp::<4>::new();
        qp.factorize(&h).unwrap();
        let mut v = [-1.0, -1.0, 1.0, 0.0];
        for (i, &var) in qp.free[..4].iter().enumerate() {
            qp.rhs[i] = [-2.0, 0.0, 2.0, 0.5][var];
        }
        let mut fresh = [false; 4];
        assert!(qp.fix_degenerate(&h, &lo, &hi, &mut v, &mut fresh));
        assert_eq!(qp.state, [Bound::Lower, Bound::Free, Bound::Upper, Bound::Free]);
        assert_eq!(v, [-1.0, -1.0, 1.0, 0.0]);
        // If the blocking ones are the whole last release, the last of them stays free; with only
        // one left to fix, nothing changes here (the caller fixes the first one).
        let mut qp = BoxQp::<4>::new();
        qp.factorize(&h).unwrap();
        for (i, &var) in qp.free[..4].iter().enumerate() {
            qp.rhs[i] = [-2.0, 0.0, 2.0, 0.5][var];
        }
        let mut fresh = [true, false, true, false];
        assert!(!qp.fix_degenerate(&h, &lo, &hi, &mut v, &mut fresh));
        assert_eq!(qp.state, [Bound::Free; 4]);
    }

    #[test]
    fn factor_updates_match_a_fresh_factorisation() {
        let mut rng = Lcg(3);
        let (h, _, _, _) = random_problem::<8>(&mut rng);
        let mut qp = BoxQp::<8>::new();
        qp.factorize(&h).unwrap();
        // Remove positions 3 and 0, append the first back: compare with factorising that set directly.
        let back = qp.free[3];
        qp.state[back] = Bound::Lower;
        qp.remove(3);
        qp.state[qp.free[0]] = Bound::Upper;
        qp.remove(0);
        // Appended as a release does: as the last free variable, its row by `factor_rows`.
        qp.free[qp.nf] = back;
        qp.nf += 1;
        qp.factor_rows(&h, qp.nf - 1).unwrap();
        qp.state[back] = Bound::Free;
        // L Lᵀ must equal H_FF in the solver's order.
        for i in 0..qp.nf {
            for j in 0..=i {
                let mut s = 0.0;
                for k in 0..=j {
                    s += qp.u[k][i] * qp.u[k][j];
                }
                let expect = h[qp.free[i]][qp.free[j]];
                assert!((s - expect).abs() < 1e-12, "(LLᵀ)[{i}][{j}] = {s} vs {expect}");
            }
        }
    }
}
