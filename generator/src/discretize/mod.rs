//! Discretisation: explicit RK4 with M substeps per sample, evaluated
//! generically (f64, interpreted) and the automatic choice of M.

mod envelope;
mod stability;

pub use envelope::Envelope;
pub use stability::{auto_substeps, rk4_stability_function, SubstepChoice, SubstepError, SAFETY_FACTOR};

use crate::ir::ModelIr;

/// One RK4 substep of length h:
/// k1 = f(x), k2 = f(x + h/2 k1), k3 = f(x + h/2 k2), k4 = f(x + h k3),
/// x⁺ = x + h/6 (k1 + 2k2 + 2k3 + k4).
pub fn rk4_substep(ir: &ModelIr, x: &[f64], u: &[f64], h: f64) -> Vec<f64> {
    let axpy = |a: f64, k: &[f64]| -> Vec<f64> { x.iter().zip(k).map(|(xi, ki)| xi + a * ki).collect() };
    let k1 = ir.eval_f(x, u);
    let k2 = ir.eval_f(&axpy(h / 2.0, &k1), u);
    let k3 = ir.eval_f(&axpy(h / 2.0, &k2), u);
    let k4 = ir.eval_f(&axpy(h, &k3), u);
    (0..x.len())
        .map(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
        .collect()
}

/// x⁺ = F(x, u): `substeps` RK4 substeps over one sample of length `dt`.
pub fn discrete_step(ir: &ModelIr, x: &[f64], u: &[f64], dt: f64, substeps: usize) -> Vec<f64> {
    let h = dt / substeps as f64;
    let mut xk = x.to_vec();
    for _ in 0..substeps {
        xk = rk4_substep(ir, &xk, u, h);
    }
    xk
}
