//! Bounded least squares: min ‖A θ − y‖² subject to l ≤ θ ≤ u, for a few unknowns.
//!
//! 1. Column equilibration: every column of A is scaled to unit norm (θ and its bounds scale with it).
//! 2. A thin QR of the scaled A reduces the problem to the n×n triangle R and c = Qᵀ y:
//!    ‖A θ − y‖² = ‖R θ − c‖² + (‖y‖² − ‖c‖²).
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

/// Solve min ‖A θ − y‖² s.t. lower ≤ θ ≤ upper (bounds may be infinite). Every column of A must be non-zero.
pub fn solve(a: &DMatrix<f64>, y: &DVector<f64>, lower: &[f64], upper: &[f64]) -> BoundedSolution {
    let n = a.ncols();
    assert_eq!(lower.len(), n);
    assert_eq!(upper.len(), n);
    let scale: Vec<f64> = (0..n).map(|j| a.column(j).norm()).collect();
    assert!(
        scale.iter().all(|&s| s > 0.0 && s.is_finite()),
        "zero or non-finite column"
    );
    let mut scaled = a.clone();
    for j in 0..n {
        scaled.column_mut(j).scale_mut(1.0 / scale[j]);
    }
    let lo: Vec<f64> = (0..n).map(|j| lower[j] * scale[j]).collect();
    let hi: Vec<f64> = (0..n).map(|j| upper[j] * scale[j]).collect();

    let (r, c) = if scaled.nrows() >= n {
        let qr = scaled.clone().qr();
        let c = qr.q().transpose() * y;
        (qr.r(), c)
    } else {
        // Fewer rows than unknowns: work with A itself.
        (scaled.clone(), y.clone())
    };
    let sv = r.singular_values();
    let (smax, smin) = (sv.max(), sv.min());
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
