//! One-step derivative residuals, filtered so that an exact model has none.
//!
//! The Savitzky-Golay derivative of the log at sample k is Σ_j c_j x_{k+j} (j = −h..h). Summing by
//! parts, with Δx_m = x_{m+1} − x_m,
//!
//! ```text
//! ẋ_SG,k = Σ_{μ=−h}^{h−1} w_μ Δx_{k+μ}/Δt,    w_μ = Δt Σ_{j=μ+1}^{h} c_j,    Σ_μ w_μ = 1
//! ```
//!
//! so the derivative target is a weighted mean (kernel w) of the sample increments. The model's
//! prediction is filtered by the same kernel: its one-step increment F(x_m, u_m) − x_m (RK4 over one
//! sample from the **logged** state, inputs held), so the residual
//!
//! ```text
//! r_k = ẋ_SG,k − Σ_μ w_μ (F(x_{k+μ}, u_{k+μ}) − x_{k+μ})/Δt = Σ_μ w_μ (x_{k+μ+1} − F(x_{k+μ}, u_{k+μ}))/Δt
//! ```
//!
//! is the kernel-weighted one-step prediction error, in the units of ẋ. It is zero for an exact
//! model whatever the inputs do (a pointwise f(x_k, u_k) against a smoothed derivative is not: a
//! step of the input shows up fully in f and smoothed in the target). A correction Δf of the model
//! changes the residual by −Σ_μ w_μ Δf_{k+μ} to first order in Δt (the candidates' fits use this;
//! the shrink figures step the corrected model exactly).

use super::DiagnoseError;
use crate::discretize::{auto_substeps, Envelope};
use crate::identify::preprocess::SavGol;
use crate::ir::ModelIr;
use crate::model::{Dynamics, Model};
use serde::Serialize;
use std::cell::RefCell;

/// How the model's prediction is compared with the Savitzky-Golay derivative.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualKind {
    /// ẋ_SG,k − Σ_μ w_μ (F(x, u) − x)/Δt: the model filtered by the derivative's own kernel (an
    /// exact model has no residual).
    #[default]
    Matched,
    /// ẋ_SG,k − f(x_k, u_k): the target the identification fits (docs/sindy.md, docs/pd-fit.md).
    Pointwise,
}

/// The identity kernel (w_0 = 1): L[g]_k = g_k, for [`ResidualKind::Pointwise`].
pub(crate) fn impulse(h: usize) -> Vec<f64> {
    let mut w = vec![0.0; 2 * h];
    w[h] = 1.0;
    w
}

/// The input response a model file carries (`corrections.latency`, `corrections.actuator_lag`), per
/// input channel: part of the base model in a diagnosis (docs/diagnose.md, "The corrected model").
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct OwnResponse {
    pub delay: [f64; 4],
    pub lag: [Option<f64>; 4],
}

/// The base model, lowered once, with its RK4 step and the substep rule.
pub(crate) struct Base {
    pub ir: ModelIr,
    /// The model's own input response (its `latency` / `actuator_lag`): the inputs the base model
    /// sees. None for a model without a `corrections` block.
    pub own: OwnResponse,
    pub gravity: f64,
    fixed_substeps: Option<usize>,
    cache: RefCell<Vec<(f64, usize)>>,
}

impl Base {
    pub fn new(model: &Model, substeps: Option<usize>, gravity: Option<f64>) -> Self {
        let g = gravity.unwrap_or(match &model.dynamics {
            Dynamics::Pd(p) => p.gravity,
            Dynamics::Sindy(_) => crate::model::corrections::STANDARD_GRAVITY,
        });
        Self {
            ir: ModelIr::new(model),
            own: OwnResponse::default(),
            gravity: g,
            fixed_substeps: substeps,
            cache: RefCell::new(Vec::new()),
        }
    }

    /// ẋ = f(x, u).
    pub fn f(&self, x: &[f64; 12], u: &[f64; 4]) -> [f64; 12] {
        let mut vars = [0.0; 16];
        vars[..12].copy_from_slice(x);
        vars[12..].copy_from_slice(u);
        let mut out = [0.0; 12];
        self.ir.eval_f_into(&vars, &mut out);
        out
    }

    /// RK4 substeps per sample of `dt`: fixed, or the code generator's automatic rule.
    pub fn substeps(&self, dt: f64, file: &str) -> Result<usize, DiagnoseError> {
        if let Some(m) = self.fixed_substeps {
            return Ok(m);
        }
        if let Some(&(_, m)) = self.cache.borrow().iter().find(|(d, _)| *d == dt) {
            return Ok(m);
        }
        let m = auto_substeps(&self.ir, dt, &Envelope::default())
            .map_err(|e| DiagnoseError::Substeps {
                file: file.to_string(),
                dt,
                message: e.to_string(),
            })?
            .substeps;
        self.cache.borrow_mut().push((dt, m));
        Ok(m)
    }

    /// F(x, u): `m` RK4 substeps over `dt`, the input held.
    pub fn step(&self, x: &[f64; 12], u: &[f64; 4], dt: f64, m: usize) -> [f64; 12] {
        rk4(|x| self.f(x, u), x, dt, m)
    }
}

/// `m` RK4 substeps of ẋ = g(x) over `dt`.
pub(crate) fn rk4<const N: usize>(g: impl Fn(&[f64; N]) -> [f64; N], x: &[f64; N], dt: f64, m: usize) -> [f64; N] {
    let h = dt / m as f64;
    let mut x = *x;
    let axpy = |x: &[f64; N], a: f64, k: &[f64; N]| {
        let mut o = *x;
        for i in 0..N {
            o[i] += a * k[i];
        }
        o
    };
    for _ in 0..m {
        let k1 = g(&x);
        let k2 = g(&axpy(&x, h / 2.0, &k1));
        let k3 = g(&axpy(&x, h / 2.0, &k2));
        let k4 = g(&axpy(&x, h, &k3));
        for i in 0..N {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    x
}

/// The kernel w_μ, μ = −h..h−1 (length 2h), of the Savitzky-Golay derivative at step `dt`.
pub(crate) fn kernel(savgol: &SavGol, dt: f64) -> Vec<f64> {
    let c = savgol.coefficients(1, dt);
    let h = savgol.half_window();
    // w_μ = Δt Σ_{j > μ} c_j; c is indexed j + h.
    (0..2 * h)
        .map(|i| {
            let mu = i as isize - h as isize;
            dt * c[(mu + 1 + h as isize) as usize..].iter().sum::<f64>()
        })
        .collect()
}

/// L[g]_k = Σ_μ w_μ g_{k+μ} at the interior samples k = h..n−h (g has one entry per row; only
/// rows 0..n−1 are read).
pub(crate) fn filter<const N: usize>(kernel: &[f64], g: &[[f64; N]], n: usize) -> Vec<[f64; N]> {
    let h = kernel.len() / 2;
    (h..n - h)
        .map(|k| {
            let mut acc = [0.0; N];
            for (i, w) in kernel.iter().enumerate() {
                let row = &g[k + i - h];
                for c in 0..N {
                    acc[c] += w * row[c];
                }
            }
            acc
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_reproduces_the_savgol_derivative() {
        let sg = SavGol { window: 9, order: 3 };
        let dt = 0.05;
        let y: Vec<f64> = (0..40)
            .map(|k| (0.3 * k as f64).sin() + 0.01 * (k * k) as f64)
            .collect();
        let d = sg.derivative(&y, dt);
        let w = kernel(&sg, dt);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let inc: Vec<[f64; 1]> = y.windows(2).map(|p| [(p[1] - p[0]) / dt]).chain([[0.0]]).collect();
        let f = filter(&w, &inc, y.len());
        for (k, v) in f.iter().enumerate() {
            assert!((v[0] - d[k + 4]).abs() < 1e-9, "{k}: {} vs {}", v[0], d[k + 4]);
        }
    }
}
