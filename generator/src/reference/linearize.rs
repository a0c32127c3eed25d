//! The discrete map x⁺ = F(x, u) and its Jacobians (A = ∂F/∂x, B = ∂F/∂u),
//! interpreted: `substeps` explicit RK4 substeps with forward sensitivities,
//! evaluated through [`ModelIr::eval_f`] and [`ModelIr::eval_jacobian`].
//!
//! x⁺ is computed with exactly the arithmetic of
//! [`crate::discretize::rk4_substep`], so it equals
//! [`crate::discretize::discrete_step`] bit for bit.

use crate::ir::ModelIr;
use nalgebra::DMatrix;

/// (x⁺, A, B) of `substeps` RK4 substeps of length h = dt / substeps from (x, u).
///
/// The sensitivity S = ∂x/∂(x₀, u) (NX × (NX + NU)) starts at [I 0] and is
/// carried through every substep next to the state:
///
/// ```text
/// stage i = 1..4:  xᵢ = x + cᵢ h kᵢ₋₁,     Sᵢ = S + cᵢ h dkᵢ₋₁     (c = 0, ½, ½, 1)
///                  kᵢ = f(xᵢ, u),          dkᵢ = fx(xᵢ, u) Sᵢ + fu(xᵢ, u) [0 I]
/// substep:         x⁺ = x + h/6 (k1 + 2k2 + 2k3 + k4)
///                  S⁺ = S + h/6 (dk1 + 2dk2 + 2dk3 + dk4)
/// ```
///
/// After the last substep A = S[:, ..NX] and B = S[:, NX..].
///
/// # Panics
/// If `x` or `u` has the wrong length, or `substeps` is 0.
pub fn discrete_linearization(
    ir: &ModelIr,
    x: &[f64],
    u: &[f64],
    dt: f64,
    substeps: usize,
) -> (Vec<f64>, DMatrix<f64>, DMatrix<f64>) {
    let (nx, nu) = (ir.nx, ir.nu);
    assert_eq!(x.len(), nx, "state length");
    assert_eq!(u.len(), nu, "input length");
    assert!(substeps >= 1, "substeps must be at least 1");
    let h = dt / substeps as f64;

    // dk = fx(xᵢ, u) Sᵢ + fu(xᵢ, u) [0 I]: the input columns of [0 I] add fu to the last NU columns.
    let stage_sensitivity = |xi: &[f64], si: &DMatrix<f64>| -> DMatrix<f64> {
        let (fx, fu) = ir.eval_jacobian(xi, u);
        let fx = DMatrix::from_fn(nx, nx, |r, c| fx[r][c]);
        let mut dk = &fx * si;
        for r in 0..nx {
            for c in 0..nu {
                dk[(r, nx + c)] += fu[r][c];
            }
        }
        dk
    };
    // x + a k, written as in `rk4_substep` so x⁺ is bitwise the same.
    let axpy = |x: &[f64], a: f64, k: &[f64]| -> Vec<f64> { x.iter().zip(k).map(|(xi, ki)| xi + a * ki).collect() };

    let mut xk = x.to_vec();
    // S = [I 0]
    let mut s = DMatrix::<f64>::identity(nx, nx + nu);
    for _ in 0..substeps {
        let k1 = ir.eval_f(&xk, u);
        let dk1 = stage_sensitivity(&xk, &s);

        let x2 = axpy(&xk, h / 2.0, &k1);
        let s2 = &s + &dk1 * (h / 2.0);
        let k2 = ir.eval_f(&x2, u);
        let dk2 = stage_sensitivity(&x2, &s2);

        let x3 = axpy(&xk, h / 2.0, &k2);
        let s3 = &s + &dk2 * (h / 2.0);
        let k3 = ir.eval_f(&x3, u);
        let dk3 = stage_sensitivity(&x3, &s3);

        let x4 = axpy(&xk, h, &k3);
        let s4 = &s + &dk3 * h;
        let k4 = ir.eval_f(&x4, u);
        let dk4 = stage_sensitivity(&x4, &s4);

        xk = (0..nx)
            .map(|i| xk[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
            .collect();
        s += (dk1 + dk2 * 2.0 + dk3 * 2.0 + dk4) * (h / 6.0);
    }
    let a = s.columns(0, nx).into_owned();
    let b = s.columns(nx, nu).into_owned();
    (xk, a, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discretize::discrete_step;
    use std::path::PathBuf;

    fn model_ir(name: &str) -> ModelIr {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models").join(name);
        ModelIr::new(&crate::load(&path).expect("shipped model loads"))
    }

    /// |a − b| / max(|a|, |b|, 1)
    fn scaled_error(a: f64, b: f64) -> f64 {
        (a - b).abs() / a.abs().max(b.abs()).max(1.0)
    }

    /// A and B against central differences of `discrete_step`; x⁺ against `discrete_step` itself.
    #[test]
    fn jacobians_match_central_differences_on_pd_paper() {
        let ir = model_ir("pd_paper.json");
        let (dt, substeps) = (1.0 / 30.0, 3);
        let points: [([f64; 12], [f64; 4]); 3] = [
            ([0.0; 12], [0.0; 4]),
            (
                [1.0, -2.0, 5.0, 0.2, -0.3, 0.7, 1.5, -0.5, 0.3, 0.4, -0.6, 0.2],
                [1.0, 0.1, -0.2, 0.5],
            ),
            (
                [-3.0, 0.5, 2.0, -0.4, 0.25, -2.0, -1.0, 2.0, -1.5, -0.8, 0.3, -1.0],
                [-2.0, -0.3, 0.4, -1.5],
            ),
        ];
        let eps = 1e-6;
        let mut worst = 0.0_f64;
        for (x, u) in &points {
            let (xp, a, b) = discrete_linearization(&ir, x, u, dt, substeps);
            let reference = discrete_step(&ir, x, u, dt, substeps);
            for i in 0..12 {
                assert!(
                    (xp[i] - reference[i]).abs() <= 1e-14 * reference[i].abs().max(1.0),
                    "x⁺[{i}]"
                );
            }
            for j in 0..16 {
                let (mut xp_, mut xm_, mut up_, mut um_) = (x.to_vec(), x.to_vec(), u.to_vec(), u.to_vec());
                if j < 12 {
                    xp_[j] += eps;
                    xm_[j] -= eps;
                } else {
                    up_[j - 12] += eps;
                    um_[j - 12] -= eps;
                }
                let fp = discrete_step(&ir, &xp_, &up_, dt, substeps);
                let fm = discrete_step(&ir, &xm_, &um_, dt, substeps);
                for i in 0..12 {
                    let fd = (fp[i] - fm[i]) / (2.0 * eps);
                    let exact = if j < 12 { a[(i, j)] } else { b[(i, j - 12)] };
                    let e = scaled_error(exact, fd);
                    worst = worst.max(e);
                    assert!(
                        e < 1e-6,
                        "d x⁺[{i}] / d z[{j}]: analytic {exact}, finite difference {fd}"
                    );
                }
            }
        }
        println!("worst scaled error of A, B vs central differences: {worst:.2e}");
    }

    /// For ẋ = a x + b u one RK4 substep is x⁺ = p(ha) x + q(ha) h b u with
    /// p(z) = 1 + z + z²/2 + z³/6 + z⁴/24 and q(z) = 1 + z/2 + z²/6 + z³/24.
    #[test]
    fn scalar_linear_model_has_the_rk4_polynomials() {
        let text = r#"{
          "format": "uavgen-model/1", "kind": "sindy", "name": "scalar",
          "states": ["p"], "inputs": ["w"], "library": ["p", "w"],
          "coefficients": [
            {"state": "p", "term": "p", "coefficient": -0.5},
            {"state": "p", "term": "w", "coefficient": 2.0}
          ]
        }"#;
        let ir = ModelIr::new(&crate::model::parse(text, "scalar.json").unwrap());
        let (dt, substeps) = (0.2, 2);
        let h = dt / substeps as f64;
        let z = -0.5 * h;
        let p = 1.0 + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0;
        let q = (1.0 + z / 2.0 + z * z / 6.0 + z * z * z / 24.0) * h * 2.0;
        // two substeps: A = p², B = (p + 1) q
        let (_, a, b) = discrete_linearization(&ir, &[0.7], &[-0.3], dt, substeps);
        assert!((a[(0, 0)] - p * p).abs() < 1e-15);
        assert!((b[(0, 0)] - (p + 1.0) * q).abs() < 1e-15);
    }
}
