//! Automatic substep count: the discrete model must be stable wherever the
//! continuous one is, over the operating envelope.
//!
//! Rule: at every envelope point the eigenvalues λ of ∂f/∂x are computed;
//! M is the smallest integer such that every λ with Re λ < 0 satisfies
//! |R(s·hλ/M)| ≤ 1, where h = 1/rate, R(z) = 1 + z + z²/2 + z³/6 + z⁴/24 is
//! RK4's stability function and s = [`SAFETY_FACTOR`] covers eigenvalues
//! between the sampled points. Eigenvalues with Re λ ≥ 0 (modes that are
//! not stable in continuous time, e.g. the free integrators of position)
//! impose nothing.
//!
//! Eigenvalues come from a Schur decomposition with an iteration cap. If it
//! does not converge (nalgebra's QR iteration can stall on some exactly
//! structured matrices), it is retried on a perturbation of relative size
//! 1e-12; if that fails too, every eigenvalue is assumed to lie anywhere in
//! the left half-disc of radius ‖A‖∞ (which bounds the spectral radius), a
//! conservative choice.

use super::Envelope;
use crate::ir::ModelIr;
use nalgebra::{Complex, DMatrix, Schur};

/// Margin on |hλ| when testing RK4's stability region.
pub const SAFETY_FACTOR: f64 = 1.25;
/// Largest substep count the automatic rule will choose.
pub const MAX_SUBSTEPS: usize = 256;

/// R(z) = 1 + z + z²/2 + z³/6 + z⁴/24
pub fn rk4_stability_function(z: Complex<f64>) -> Complex<f64> {
    let one = Complex::new(1.0, 0.0);
    one + z * (one + z * (one / 2.0 + z * (one / 6.0 + z / 24.0)))
}

/// The chosen M and the eigenvalue that decided it.
#[derive(Clone, Debug)]
pub struct SubstepChoice {
    pub substeps: usize,
    pub stiffest: Complex<f64>,
    pub points: usize,
    /// The eigenvalue with the largest real part over the envelope (0 if every one is stable):
    /// the rule imposes nothing for it, the code generator refuses absurd growth rates.
    pub fastest_growth: Complex<f64>,
}

#[derive(Debug, thiserror::Error)]
pub enum SubstepError {
    #[error("∂f/∂x is not finite at envelope point {0:?} (the model is singular there)")]
    NonFinite(Vec<f64>),
    #[error("explicit RK4 would need more than {MAX_SUBSTEPS} substeps at this rate (eigenvalue {0} 1/s); pass --substeps explicitly")]
    TooStiff(Complex<f64>),
}

/// Schur iterations before giving up on one matrix.
const MAX_SCHUR_ITERATIONS: usize = 10_000;

/// Eigenvalues of `a`, or — if the Schur iteration stalls twice — a
/// conservative cover of the left half-disc of radius ‖A‖∞.
fn eigenvalues(a: &DMatrix<f64>) -> Vec<Complex<f64>> {
    // nalgebra can return a NaN imaginary part for a 2×2 block whose discriminant rounds to
    // a tiny negative number (seen on nilpotent Jacobians): such a result is not used.
    let schur = |m: DMatrix<f64>| {
        Schur::try_new(m, f64::EPSILON, MAX_SCHUR_ITERATIONS)
            .map(|s| s.complex_eigenvalues().iter().copied().collect::<Vec<Complex<f64>>>())
            .filter(|l| l.iter().all(|z| z.re.is_finite() && z.im.is_finite()))
    };
    if let Some(l) = schur(a.clone()) {
        return l;
    }
    let n = a.nrows();
    let scale = 1e-12 * a.amax().max(1.0);
    // Deterministic, unstructured perturbation.
    let perturbed = a + DMatrix::from_fn(n, n, |i, j| scale * (((7 * i + 3 * j) % 11) as f64 - 5.0) / 5.0);
    if let Some(l) = schur(perturbed) {
        return l;
    }
    let radius = a
        .row_iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    (0..=32)
        .map(|k| {
            let theta = std::f64::consts::FRAC_PI_2 * (1.0 + k as f64 / 16.0);
            Complex::from_polar(radius, theta) - Complex::new(1e-12, 0.0)
        })
        .collect()
}

fn stable_with(m: usize, lambda: Complex<f64>, h: f64) -> bool {
    rk4_stability_function(lambda * (SAFETY_FACTOR * h / m as f64)).norm() <= 1.0
}

/// Choose M for sample period `dt` over `envelope`.
pub fn auto_substeps(ir: &ModelIr, dt: f64, envelope: &Envelope) -> Result<SubstepChoice, SubstepError> {
    let names: Vec<String> = ir.state_names.iter().chain(&ir.input_names).cloned().collect();
    let points = envelope.points(&names);
    let mut best = SubstepChoice {
        substeps: 1,
        stiffest: Complex::new(0.0, 0.0),
        points: points.len(),
        fastest_growth: Complex::new(0.0, 0.0),
    };
    for p in &points {
        let (x, u) = p.split_at(ir.nx);
        let (fx, _) = ir.eval_jacobian(x, u);
        let a = DMatrix::from_fn(ir.nx, ir.nx, |i, j| fx[i][j]);
        if a.iter().any(|v| !v.is_finite()) {
            return Err(SubstepError::NonFinite(p.clone()));
        }
        for lambda in eigenvalues(&a) {
            if lambda.re >= 0.0 {
                if lambda.re > best.fastest_growth.re {
                    best.fastest_growth = lambda;
                }
                continue;
            }
            let need = (1..=MAX_SUBSTEPS)
                .find(|&m| stable_with(m, lambda, dt))
                .ok_or(SubstepError::TooStiff(lambda))?;
            if need > best.substeps || (need == best.substeps && lambda.norm() > best.stiffest.norm()) {
                best.substeps = need;
                best.stiffest = lambda;
            }
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rk4_region_on_the_real_axis_ends_near_minus_2_785() {
        let r = |x: f64| rk4_stability_function(Complex::new(x, 0.0)).norm();
        assert!(r(-2.78) <= 1.0);
        assert!(r(-2.79) > 1.0);
        // Imaginary axis: stable up to 2√2.
        assert!(rk4_stability_function(Complex::new(0.0, 2.8)).norm() <= 1.0);
        assert!(rk4_stability_function(Complex::new(0.0, 2.9)).norm() > 1.0);
    }

    #[test]
    fn eigenvalues_are_always_finite() {
        // Kinematic rows only (a model whose dynamic rows are all empty): nilpotent.
        let mut a = DMatrix::zeros(12, 12);
        for i in 0..6 {
            a[(i, i + 6)] = 1.0;
        }
        a[(6, 3)] = 10.03;
        a[(6, 4)] = 10.12;
        a[(7, 3)] = -9.44;
        let l = eigenvalues(&a);
        assert!(l.iter().all(|z| z.re.is_finite() && z.im.is_finite()), "{l:?}");
    }

    #[test]
    fn stalled_schur_iterations_do_not_hang() {
        // The Jacobian of ẋ = −vx³ at vx = 0 style matrices made nalgebra's
        // uncapped Schur loop spin forever; capped, it must return.
        let mut a = DMatrix::zeros(12, 12);
        for i in 0..6 {
            a[(i, i + 6)] = 1.0;
        }
        let l = eigenvalues(&a);
        assert_eq!(l.len(), 12);
        assert!(l.iter().all(|z| z.norm() < 1e-3 || z.re < 0.0));
    }

    #[test]
    fn stiff_real_mode_needs_three_substeps_at_30_hz() {
        // λ = −183 1/s (the paper's roll mode): 183·1.25/30 = 7.6 → M = 3.
        let l = Complex::new(-183.0, 0.0);
        assert!(!stable_with(2, l, 1.0 / 30.0));
        assert!(stable_with(3, l, 1.0 / 30.0));
    }
}
