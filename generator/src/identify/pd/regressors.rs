//! The Euler-Lagrange residual of the PD model, written linearly in ξ.
//!
//! Translation (rows x, y, z), with b = R e3 and η = [x y z]:
//!
//! ```text
//! ξ1 (b u_vz) + ξ7 (−b ż) + ξ11 (−b z̈) + ξ13 b = m (η̈ + g e3)
//! ```
//!
//! Rotation (rows roll, pitch, yaw), Ω = [φ θ ψ]:
//!
//! ```text
//! τ(ξ2..ξ10) − ξ12 ψ̈ e3 − Σ_k I_k col_k(Ω, Ω̇, Ω̈) = 0,   col_k = M_k Ω̈ + C_k Ω̇,
//! ```
//!
//! where M_k = w_kᵀ w_k is the part of M(Ω) = Wᵀ diag(Ix, Iy, Iz) W that multiplies I_k (w_k is the k-th
//! row of W) and C_k its Christoffel matrix. M_k Ω̈ + C_k Ω̇ is the Euler-Lagrange operator
//! d/dt ∂L/∂Ω̇ − ∂L/∂Ω of L = ½ ω_k², ω_k = w_k · Ω̇ (the k-th body rate):
//!
//! ```text
//! col_k = (w_k · Ω̈ + (J_k Ω̇) · Ω̇) w_k + ω_k (J_k − J_kᵀ) Ω̇,   J_k = ∂w_k/∂Ω.
//! ```

/// Parameters of the translational rows, in column order.
pub const TRANSLATION_XI: [usize; 4] = [1, 7, 11, 13];
/// Parameters of the rotational rows, in column order.
pub const ROTATION_XI: [usize; 12] = [2, 3, 4, 5, 6, 8, 9, 10, 12, 14, 15, 16];

/// Rows of W(Ω) and their Jacobians J_k[i][j] = ∂w_k[i]/∂Ω_j.
fn w_and_jacobians(phi: f64, theta: f64) -> ([[f64; 3]; 3], [[[f64; 3]; 3]; 3]) {
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let w = [[1.0, 0.0, -st], [0.0, cp, sp * ct], [0.0, -sp, cp * ct]];
    let j = [
        [[0.0; 3], [0.0; 3], [0.0, -ct, 0.0]],
        [[0.0; 3], [-sp, 0.0, 0.0], [cp * ct, -sp * st, 0.0]],
        [[0.0; 3], [-cp, 0.0, 0.0], [-sp * ct, -cp * st, 0.0]],
    ];
    (w, j)
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn matvec(m: &[[f64; 3]; 3], v: &[f64; 3]) -> [f64; 3] {
    [dot(&m[0], v), dot(&m[1], v), dot(&m[2], v)]
}

fn matvec_t(m: &[[f64; 3]; 3], v: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|j| m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2])
}

/// col_k = M_k Ω̈ + C_k Ω̇ for k = x, y, z: the inertial torque per unit inertia.
pub fn inertia_columns(omega: &[f64; 3], omega_d: &[f64; 3], omega_dd: &[f64; 3]) -> [[f64; 3]; 3] {
    let (w, jac) = w_and_jacobians(omega[0], omega[1]);
    [0, 1, 2].map(|k| {
        let wk = &w[k];
        let jw = matvec(&jac[k], omega_d);
        let jtw = matvec_t(&jac[k], omega_d);
        let rate = dot(wk, omega_d);
        let rate_d = dot(wk, omega_dd) + dot(&jw, omega_d);
        [0, 1, 2].map(|i| rate_d * wk[i] + rate * (jw[i] - jtw[i]))
    })
}

/// M(Ω) = Wᵀ diag(Ix, Iy, Iz) W.
pub fn mass_matrix(omega: &[f64; 3], inertia: &[f64; 3]) -> [[f64; 3]; 3] {
    let (w, _) = w_and_jacobians(omega[0], omega[1]);
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = (0..3).map(|k| w[k][i] * inertia[k] * w[k][j]).sum();
        }
    }
    m
}

/// b = R e3 for ZYX Euler angles.
pub fn thrust_axis(phi: f64, theta: f64, psi: f64) -> [f64; 3] {
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let (ss, cs) = psi.sin_cos();
    [cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp]
}

/// The three translational rows of one sample: (a over [`TRANSLATION_XI`], target).
pub fn translation_rows(x: &[f64; 12], u: &[f64; 4], dx: &[f64; 12], mass: f64, gravity: f64) -> [([f64; 4], f64); 3] {
    let b = thrust_axis(x[3], x[4], x[5]);
    let (vz, zdd) = (x[8], dx[8]);
    [0, 1, 2].map(|r| {
        let a = [b[r] * u[0], -b[r] * vz, -b[r] * zdd, b[r]];
        let g = if r == 2 { gravity } else { 0.0 };
        (a, mass * (dx[6 + r] + g))
    })
}

/// The three rotational rows of one sample: coefficients over [`ROTATION_XI`]; the target is 0.
pub fn rotation_rows(x: &[f64; 12], u: &[f64; 4], dx: &[f64; 12]) -> [[f64; 12]; 3] {
    let omega = [x[3], x[4], x[5]];
    let omega_d = [x[9], x[10], x[11]];
    let omega_dd = [dx[9], dx[10], dx[11]];
    let cols = inertia_columns(&omega, &omega_d, &omega_dd);
    let mut rows = [[0.0; 12]; 3];
    // Gains ξ2, ξ3, ξ4 (columns 0..3) on u_roll, u_pitch, u_yaw_rate.
    for r in 0..3 {
        rows[r][r] = u[1 + r];
    }
    // Stiffness ξ5, ξ6 (columns 3, 4) on roll, pitch.
    rows[0][3] = -omega[0];
    rows[1][4] = -omega[1];
    // Damping ξ8, ξ9, ξ10 (columns 5..8).
    for r in 0..3 {
        rows[r][5 + r] = -omega_d[r];
    }
    // ξ12 (column 8): yaw acceleration feedback.
    rows[2][8] = -omega_dd[2];
    // Inertias ξ14..ξ16 (columns 9..12).
    for r in 0..3 {
        for k in 0..3 {
            rows[r][9 + k] = -cols[k][r];
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ I_k col_k equals M Ω̈ + C Ω̇ with C from Christoffel symbols of M (finite differences).
    #[test]
    fn inertia_columns_match_christoffel_form() {
        let omega = [0.3, -0.4, 1.1];
        let od = [0.7, -0.2, 0.5];
        let odd = [-1.3, 0.9, 0.4];
        let inertia = [0.05, 0.07, 0.11];
        let cols = inertia_columns(&omega, &od, &odd);
        let lhs: Vec<f64> = (0..3).map(|i| (0..3).map(|k| inertia[k] * cols[k][i]).sum()).collect();
        let h = 1e-6;
        let dm = |k: usize| {
            let (mut p, mut m) = (omega, omega);
            p[k] += h;
            m[k] -= h;
            let (a, b) = (mass_matrix(&p, &inertia), mass_matrix(&m, &inertia));
            let mut d = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    d[i][j] = (a[i][j] - b[i][j]) / (2.0 * h);
                }
            }
            d
        };
        let d = [dm(0), dm(1), dm(2)];
        let m = mass_matrix(&omega, &inertia);
        for i in 0..3 {
            let mut rhs: f64 = (0..3).map(|j| m[i][j] * odd[j]).sum();
            for j in 0..3 {
                for k in 0..3 {
                    let c = 0.5 * (d[k][i][j] + d[j][i][k] - d[i][j][k]);
                    rhs += c * od[k] * od[j];
                }
            }
            assert!((lhs[i] - rhs).abs() < 1e-8, "row {i}: {} vs {rhs}", lhs[i]);
        }
    }
}
