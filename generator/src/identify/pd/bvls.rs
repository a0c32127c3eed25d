//! Bounded least squares: min ‖A θ − y‖² subject to l ≤ θ ≤ u, for a few unknowns.
//!
//! 1. Column equilibration: every column of A is scaled to unit norm (θ and its bounds scale with it).
//! 2. A thin QR of the scaled A reduces the problem to the n×n triangle R and c = Qᵀ y:
//!    ‖A θ − y‖² = ‖R θ − c‖² + (‖y‖² − ‖c‖²). A is never held: its rows are folded into R and c a
//!    chunk at a time ([`Reduction`]), with its column norms alongside for step 1 (the QR of the
//!    scaled A D⁻¹ is Q (R D⁻¹)), so the memory is O(n²) whatever the number of rows.
//! 3. A primal active-set method for the box-constrained QP (Nocedal & Wright, algorithm 16.3, the
//!    bounded variant of Lawson-Hanson NNLS): starting from the unconstrained solution projected on the
//!    box, variables at a bound are held there, the others solve the unconstrained sub-problem
//!    (by SVD, so a rank-deficient sub-problem gives its minimum-norm step); a step that leaves the box is
//!    cut at the first bound it meets, which joins the held set; at a sub-problem minimum the held
//!    variable with the most negative Lagrange multiplier is released, and the method stops when none is
//!    negative (the KKT conditions hold).

use nalgebra::{DMatrix, DVector};

/// The solution and what the solver saw.
#[derive(Clone, Debug)]
pub struct BoundedSolution {
    pub theta: Vec<f64>,
    /// Which unknowns ended on a bound.
    pub at_bound: Vec<bool>,
    /// σ_max / σ_min of the column-equilibrated A (∞ if rank-deficient).
    pub condition: f64,
    pub iterations: usize,
    pub converged: bool,
}

/// Rows of [A | y] folded, a chunk at a time, into the n×n triangle R and c = Qᵀ y of A's QR
/// (step 2 without A): the rows of a chunk are stacked under [R | c] and a Householder QR of the
/// stack ([R; chunk] = Q' R') makes the new triangle, so only n + `chunk` rows are ever held.
/// Beside it: the column norms of A (step 1's equilibration: the QR of A D is Q (R D), so R's
/// columns are scaled afterwards) and ‖y‖² (the residual ‖A θ − y‖² = ‖R θ − c‖² + ‖y‖² − ‖c‖²).
#[derive(Clone, Debug)]
pub struct Reduction {
    n: usize,
    chunk: usize,
    /// (n + chunk) × (n + 1): [R | c] in the first n rows, the pending rows of [A | y] below.
    work: DMatrix<f64>,
    pending: usize,
    rows: usize,
    col_sq: Vec<f64>,
    y_sq: f64,
}

/// Rows folded at once by [`Reduction::new`] (a few tens of kB for a dozen unknowns; the result
/// does not depend on it beyond round-off).
pub const CHUNK_ROWS: usize = 256;

impl Reduction {
    /// For `n` unknowns, folding [`CHUNK_ROWS`] rows at a time.
    pub fn new(n: usize) -> Self {
        Self::with_chunk(n, CHUNK_ROWS)
    }

    /// For `n` unknowns, folding `chunk` (≥ 1) rows at a time.
    pub fn with_chunk(n: usize, chunk: usize) -> Self {
        let chunk = chunk.max(1);
        Reduction {
            n,
            chunk,
            work: DMatrix::zeros(n + chunk, n + 1),
            pending: 0,
            rows: 0,
            col_sq: vec![0.0; n],
            y_sq: 0.0,
        }
    }

    /// One row a (n coefficients) with its target y.
    pub fn push(&mut self, a: &[f64], y: f64) {
        assert_eq!(a.len(), self.n);
        let i = self.n + self.pending;
        for (j, &v) in a.iter().enumerate() {
            self.work[(i, j)] = v;
            self.col_sq[j] += v * v;
        }
        self.work[(i, self.n)] = y;
        self.y_sq += y * y;
        self.rows += 1;
        self.pending += 1;
        if self.pending == self.chunk {
            self.fold();
        }
    }

    /// Rows pushed.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// ‖column j of A‖.
    pub fn column_norm(&self, j: usize) -> f64 {
        self.col_sq[j].sqrt()
    }

    /// Householder QR of [R | c] stacked over the pending rows: column j's reflection acts on row j
    /// and the pending rows only (R is upper triangular, so the rows between hold zeros there).
    fn fold(&mut self) {
        let (n, p) = (self.n, self.pending);
        let w = &mut self.work;
        for j in 0..n {
            let head = w[(j, j)];
            let mut tail_sq = 0.0;
            for i in n..n + p {
                tail_sq += w[(i, j)] * w[(i, j)];
            }
            if tail_sq == 0.0 {
                continue;
            }
            let sigma = (head * head + tail_sq).sqrt();
            let alpha = if head > 0.0 { -sigma } else { sigma };
            // v = [head − α; tail], vᵀv = (head − α)² + ‖tail‖².
            let v0 = head - alpha;
            let vv = v0 * v0 + tail_sq;
            for k in j + 1..=n {
                let mut s = v0 * w[(j, k)];
                for i in n..n + p {
                    s += w[(i, j)] * w[(i, k)];
                }
                let f = 2.0 * s / vv;
                w[(j, k)] -= f * v0;
                for i in n..n + p {
                    let vi = w[(i, j)];
                    w[(i, k)] -= f * vi;
                }
            }
            w[(j, j)] = alpha;
            for i in n..n + p {
                w[(i, j)] = 0.0;
            }
        }
        self.pending = 0;
    }

    /// The triangle R (n × n; with fewer rows than unknowns its rows beyond the rank are zero)
    /// and c = Qᵀ y.
    pub fn triangle(mut self) -> (DMatrix<f64>, DVector<f64>) {
        if self.pending > 0 {
            self.fold();
        }
        let n = self.n;
        let r = self.work.view((0, 0), (n, n)).into_owned();
        let c = DVector::from_fn(n, |i, _| self.work[(i, n)]);
        (r, c)
    }

    /// ‖A θ − y‖² at θ (from R, c and ‖y‖²: no row is revisited).
    pub fn residual_sq(&self, theta: &[f64]) -> f64 {
        let y_sq = self.y_sq;
        let (r, c) = self.clone().triangle();
        let fit = (&r * DVector::from_column_slice(theta) - &c).norm_squared();
        (fit + y_sq - c.norm_squared()).max(0.0)
    }
}

/// Solve min ‖A θ − y‖² s.t. lower ≤ θ ≤ upper (bounds may be infinite). Every column of A must be non-zero.
pub fn solve(a: &DMatrix<f64>, y: &DVector<f64>, lower: &[f64], upper: &[f64]) -> BoundedSolution {
    let mut reduction = Reduction::new(a.ncols());
    let mut row = vec![0.0; a.ncols()];
    for i in 0..a.nrows() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[(i, j)];
        }
        reduction.push(&row, y[i]);
    }
    solve_reduced(reduction, lower, upper)
}

/// [`solve`] from the rows folded into a [`Reduction`]. Every column of A must be non-zero.
pub fn solve_reduced(reduction: Reduction, lower: &[f64], upper: &[f64]) -> BoundedSolution {
    let n = reduction.n;
    assert_eq!(lower.len(), n);
    assert_eq!(upper.len(), n);
    let scale: Vec<f64> = (0..n).map(|j| reduction.column_norm(j)).collect();
    assert!(
        scale.iter().all(|&s| s > 0.0 && s.is_finite()),
        "zero or non-finite column"
    );
    let lo: Vec<f64> = (0..n).map(|j| lower[j] * scale[j]).collect();
    let hi: Vec<f64> = (0..n).map(|j| upper[j] * scale[j]).collect();
    // Step 2 on the equilibrated A D⁻¹: its R is R D⁻¹, its c the same.
    let reduction_rows = reduction.rows;
    let (mut r, c) = reduction.triangle();
    for j in 0..n {
        r.column_mut(j).scale_mut(1.0 / scale[j]);
    }
    // With fewer rows than unknowns, A has only that many singular values (the largest of R's).
    let mut sv: Vec<f64> = r.singular_values().iter().copied().collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    sv.truncate(reduction_rows.min(n).max(1));
    let (smax, smin) = (sv[0], sv[sv.len() - 1]);
    let condition = if smin > 0.0 { smax / smin } else { f64::INFINITY };

    let (phi, held, iterations, converged) = active_set(&r, &c, &lo, &hi);
    BoundedSolution {
        theta: (0..n).map(|j| phi[j] / scale[j]).collect(),
        at_bound: held,
        condition,
        iterations,
        converged,
    }
}

/// Minimum-norm least-squares solution of `m z = b`.
fn lstsq(m: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let svd = m.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let tol = smax * 1e-13 * (m.nrows().max(m.ncols()) as f64);
    svd.solve(b, tol).unwrap_or_else(|_| DVector::zeros(m.ncols()))
}

#[allow(clippy::type_complexity)]
fn active_set(r: &DMatrix<f64>, c: &DVector<f64>, lo: &[f64], hi: &[f64]) -> (Vec<f64>, Vec<bool>, usize, bool) {
    let n = r.ncols();
    let clamp = |v: f64, j: usize| v.max(lo[j]).min(hi[j]);
    // Start: the unconstrained minimiser projected on the box; variables on a bound are held.
    let free0 = lstsq(r, c);
    let mut phi: Vec<f64> = (0..n).map(|j| clamp(free0[j], j)).collect();
    let mut held: Vec<bool> = (0..n).map(|j| phi[j] == lo[j] || phi[j] == hi[j]).collect();
    let max_iterations = 20 * n + 50;
    for iteration in 1..=max_iterations {
        let free: Vec<usize> = (0..n).filter(|&j| !held[j]).collect();
        // Sub-problem: minimise over the free variables with the held ones fixed.
        let mut rhs = c.clone();
        for j in (0..n).filter(|&j| held[j]) {
            rhs -= r.column(j) * phi[j];
        }
        let target = if free.is_empty() {
            DVector::zeros(0)
        } else {
            let rf = DMatrix::from_fn(r.nrows(), free.len(), |i, k| r[(i, free[k])]);
            lstsq(&rf, &rhs)
        };
        // Longest feasible step towards the sub-problem minimum.
        let mut alpha = 1.0;
        let mut blocking = None;
        for (k, &j) in free.iter().enumerate() {
            let p = target[k] - phi[j];
            let a = if p < 0.0 && lo[j].is_finite() {
                (lo[j] - phi[j]) / p
            } else if p > 0.0 && hi[j].is_finite() {
                (hi[j] - phi[j]) / p
            } else {
                continue;
            };
            if a < alpha {
                alpha = a.max(0.0);
                blocking = Some((j, p < 0.0));
            }
        }
        for (k, &j) in free.iter().enumerate() {
            phi[j] = clamp(phi[j] + alpha * (target[k] - phi[j]), j);
        }
        if let Some((j, to_lower)) = blocking {
            phi[j] = if to_lower { lo[j] } else { hi[j] };
            held[j] = true;
            continue;
        }
        // At the sub-problem minimum: Lagrange multipliers of the held bounds, from the gradient
        // g = Rᵀ (R φ − c); a bound is right where the gradient pushes against it.
        let resid = r * DVector::from_column_slice(&phi) - c;
        let grad = r.transpose() * resid;
        let mut worst = None;
        // Multipliers within rounding of zero (relative to the problem's scale ‖c‖; the columns of R
        // have unit norm) count as zero, so a parameter whose optimum is exactly on its bound does not
        // cycle between held and free.
        let tol = 1e-11 * c.norm().max(f64::MIN_POSITIVE);
        for j in (0..n).filter(|&j| held[j]) {
            let multiplier = if phi[j] == lo[j] { grad[j] } else { -grad[j] };
            if multiplier < -tol && worst.map_or(true, |(_, m)| multiplier < m) {
                worst = Some((j, multiplier));
            }
        }
        match worst {
            Some((j, _)) => held[j] = false,
            None => return (phi, held, iteration, true),
        }
    }
    (phi, held, max_iterations, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn objective(a: &DMatrix<f64>, y: &DVector<f64>, t: &[f64]) -> f64 {
        (a * DVector::from_column_slice(t) - y).norm_squared()
    }

    #[test]
    fn unconstrained_interior_solution_is_plain_least_squares() {
        let a = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, -1.0]);
        let truth = [2.0, 3.0];
        let y = &a * DVector::from_column_slice(&truth);
        let s = solve(&a, &y, &[0.0, 0.0], &[10.0, 10.0]);
        assert!(s.converged);
        for j in 0..2 {
            assert!((s.theta[j] - truth[j]).abs() < 1e-12);
        }
        assert!(s.at_bound.iter().all(|b| !b));
    }

    /// A hand-checked reduction: A = [3; 4], y = [1; 2] gives |R| = 5, |c| = (3 + 8)/5 = 2.2, and
    /// the residual ‖A θ − y‖² = 5 − 2.2² = 0.16 at θ = 0.44.
    #[test]
    fn one_column_reduction_by_hand() {
        for chunk in [1, 2, 7] {
            let mut red = Reduction::with_chunk(1, chunk);
            red.push(&[3.0], 1.0);
            red.push(&[4.0], 2.0);
            assert_eq!(red.rows(), 2);
            assert!((red.column_norm(0) - 5.0).abs() < 1e-15);
            assert!((red.residual_sq(&[0.44]) - 0.16).abs() < 1e-14);
            assert!((red.residual_sq(&[0.0]) - 5.0).abs() < 1e-14);
            let (r, c) = red.triangle();
            assert!((r[(0, 0)].abs() - 5.0).abs() < 1e-14);
            assert!((c[0] * r[(0, 0)].signum() - 2.2).abs() < 1e-14);
        }
    }

    /// The solver as it was before the rows were folded: the equilibrated A held whole, its
    /// one-shot QR (nalgebra) and thin Q.
    fn one_shot(a: &DMatrix<f64>, y: &DVector<f64>, lower: &[f64], upper: &[f64]) -> BoundedSolution {
        let n = a.ncols();
        let scale: Vec<f64> = (0..n).map(|j| a.column(j).norm()).collect();
        let mut scaled = a.clone();
        for j in 0..n {
            scaled.column_mut(j).scale_mut(1.0 / scale[j]);
        }
        let lo: Vec<f64> = (0..n).map(|j| lower[j] * scale[j]).collect();
        let hi: Vec<f64> = (0..n).map(|j| upper[j] * scale[j]).collect();
        let qr = scaled.clone().qr();
        let c = qr.q().transpose() * y;
        let r = qr.r();
        let sv = r.singular_values();
        let (phi, held, iterations, converged) = active_set(&r, &c, &lo, &hi);
        BoundedSolution {
            theta: (0..n).map(|j| phi[j] / scale[j]).collect(),
            at_bound: held,
            condition: sv.max() / sv.min(),
            iterations,
            converged,
        }
    }

    /// The rows folded in chunks of 1, 7 and more than the rows give the one-shot QR's R and c
    /// (RᵀR = AᵀA, Rᵀc = Aᵀy, ‖c‖ equal: R is unique up to the signs of its rows) and the same
    /// bounded solution to round-off, with bounds active and inactive; the residual from R, c and
    /// ‖y‖² is the direct one.
    #[test]
    fn chunked_reduction_equals_the_one_shot_qr() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut active = 0;
        let mut inactive = 0;
        for case in 0..120 {
            let n = rng.gen_range(1..9);
            let m = rng.gen_range(n..40);
            // Columns of very different scales, as PD's regressors have.
            let col_scale: Vec<f64> = (0..n).map(|_| 10f64.powf(rng.gen_range(-3.0..3.0))).collect();
            let a = DMatrix::from_fn(m, n, |_, j| col_scale[j] * rng.gen_range(-1.0..1.0));
            let y = DVector::from_fn(m, |_, _| rng.gen_range(-3.0..3.0));
            // Every other case without bounds (the unconstrained solution), else a box.
            let (lo, hi): (Vec<f64>, Vec<f64>) = if case % 2 == 0 {
                (vec![f64::NEG_INFINITY; n], vec![f64::INFINITY; n])
            } else {
                (0..n)
                    .map(|j| {
                        (
                            -0.2 / col_scale[j],
                            if rng.gen_bool(0.5) {
                                0.3 / col_scale[j]
                            } else {
                                f64::INFINITY
                            },
                        )
                    })
                    .unzip()
            };
            let reference = one_shot(&a, &y, &lo, &hi);
            if reference.at_bound.iter().any(|b| *b) {
                active += 1;
            } else {
                inactive += 1;
            }
            let gram = a.transpose() * &a;
            let aty = a.transpose() * &y;
            for chunk in [1, 7, m + 1] {
                let mut red = Reduction::with_chunk(n, chunk);
                for i in 0..m {
                    let row: Vec<f64> = (0..n).map(|j| a[(i, j)]).collect();
                    red.push(&row, y[i]);
                }
                let direct = objective(&a, &y, &reference.theta);
                let folded = red.residual_sq(&reference.theta);
                assert!(
                    (direct - folded).abs() <= 1e-9 * (1.0 + y.norm_squared()),
                    "{direct} {folded}"
                );
                let (r, c) = red.clone().triangle();
                let g = r.transpose() * &r;
                let b = r.transpose() * &c;
                for i in 0..n {
                    assert!((b[i] - aty[i]).abs() <= 1e-10 * (aty.amax() + gram[(i, i)].sqrt() * y.norm()));
                    for j in 0..n {
                        let tol = 1e-10 * (gram[(i, i)] * gram[(j, j)]).sqrt();
                        assert!((g[(i, j)] - gram[(i, j)]).abs() <= tol, "case {case} chunk {chunk}");
                    }
                }
                let s = solve_reduced(red, &lo, &hi);
                assert!(s.converged);
                assert_eq!(s.at_bound, reference.at_bound, "case {case} chunk {chunk}");
                assert!(
                    (s.condition - reference.condition).abs() <= 1e-8 * reference.condition,
                    "condition {} against {}",
                    s.condition,
                    reference.condition
                );
                for j in 0..n {
                    let tol = 1e-8 * (reference.theta[j].abs() + 1.0 / col_scale[j]);
                    assert!(
                        (s.theta[j] - reference.theta[j]).abs() <= tol,
                        "case {case} chunk {chunk} θ{j}: {} against {}",
                        s.theta[j],
                        reference.theta[j]
                    );
                }
            }
        }
        assert!(
            active > 10 && inactive > 10,
            "bounds active in {active} cases, inactive in {inactive}"
        );
    }

    /// Fewer rows than unknowns: A's own singular values give the condition number.
    #[test]
    fn fewer_rows_than_unknowns() {
        let a = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 2.0, 0.0, 1.0, 1.0]);
        let y = DVector::from_column_slice(&[1.0, 2.0]);
        let s = solve(&a, &y, &[-10.0; 3], &[10.0; 3]);
        assert!(s.converged && s.condition.is_finite());
        assert!(objective(&a, &y, &s.theta) < 1e-20);
    }

    /// Random problems: the result satisfies KKT and beats random feasible points.
    #[test]
    fn random_box_problems_satisfy_kkt() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let n = rng.gen_range(1..8);
            let m = rng.gen_range(n..3 * n + 5);
            let a = DMatrix::from_fn(m, n, |_, _| rng.gen_range(-1.0..1.0));
            let y = DVector::from_fn(m, |_, _| rng.gen_range(-3.0..3.0));
            let lo: Vec<f64> = (0..n)
                .map(|_| if rng.gen_bool(0.3) { f64::NEG_INFINITY } else { -0.5 })
                .collect();
            let hi: Vec<f64> = (0..n)
                .map(|_| if rng.gen_bool(0.3) { f64::INFINITY } else { 0.7 })
                .collect();
            let s = solve(&a, &y, &lo, &hi);
            assert!(s.converged);
            let best = objective(&a, &y, &s.theta);
            for j in 0..n {
                assert!(s.theta[j] >= lo[j] - 1e-12 && s.theta[j] <= hi[j] + 1e-12);
            }
            let g = a.transpose() * (&a * DVector::from_column_slice(&s.theta) - &y);
            for j in 0..n {
                let tol = 1e-8 * (1.0 + g.amax());
                if (s.theta[j] - lo[j]).abs() < 1e-12 {
                    assert!(g[j] >= -tol);
                } else if (s.theta[j] - hi[j]).abs() < 1e-12 {
                    assert!(g[j] <= tol);
                } else {
                    assert!(g[j].abs() <= tol, "free gradient {}", g[j]);
                }
            }
            for _ in 0..20 {
                let t: Vec<f64> = (0..n).map(|j| rng.gen_range(lo[j].max(-2.0)..hi[j].min(2.0))).collect();
                assert!(objective(&a, &y, &t) >= best - 1e-9);
            }
        }
    }
}
