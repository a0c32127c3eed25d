//! The PD model against an independent, hand-written nalgebra implementation
//! of MODEL_NOTES.md's equations (appendix C with its two typos fixed, the
//! full 6×6 system solved by LU), plus the structural checks: Ṁ − 2C is
//! skew-symmetric, and the self-consistent model hovers.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use uavgen::ir::pd::{coriolis, inertia, PdVars};
use uavgen::model::{Dynamics, PdParams};
use uavgen::symbolic::{Graph, Id, Tape};
use uavgen_tests::{envelope_points, max_scaled_error, shipped_model};

fn params(name: &str) -> PdParams {
    match shipped_model(name).dynamics {
        Dynamics::Pd(p) => p,
        Dynamics::Sindy(_) => panic!("{name} is not a PD model"),
    }
}

/// M(Ω) exactly as printed in the paper's appendix.
fn inertia_matrix(p: &PdParams, phi: f64, theta: f64) -> Matrix3<f64> {
    let (ix, iy, iz) = (p.xi(14), p.xi(15), p.xi(16));
    let (sf, cf, st, ct) = (phi.sin(), phi.cos(), theta.sin(), theta.cos());
    let m12 = 0.0;
    let m13 = -ix * st;
    let m22 = iz + (iy - iz) * cf * cf;
    let m23 = cf * sf * ct * (iy - iz);
    let m33 = iz * cf * cf * ct * ct + iy * sf * sf * ct * ct + ix * st * st;
    Matrix3::new(ix, m12, m13, m12, m22, m23, m13, m23, m33)
}

/// C(Ω, Ω̇) from the paper's appendix, with MODEL_NOTES.md's corrections:
/// c21's ψ̇ sφ cθ is ψ̇ sφ² cθ, and c32 gains −Iy ψ̇ sφ² sθ cθ − Iz ψ̇ cφ² sθ cθ.
fn coriolis_matrix(p: &PdParams, phi: f64, theta: f64, dphi: f64, dtheta: f64, dpsi: f64) -> Matrix3<f64> {
    let (ix, iy, iz) = (p.xi(14), p.xi(15), p.xi(16));
    let (sf, cf, st, ct) = (phi.sin(), phi.cos(), theta.sin(), theta.cos());
    let c11 = 0.0;
    let c12 = (iy - iz) * (dtheta * cf * sf + dpsi * sf * sf * ct) + (iz - iy) * (dpsi * cf * cf * ct) - ix * dpsi * ct;
    let c13 = (iz - iy) * dpsi * cf * sf * ct * ct;
    let c21 = (iz - iy) * (dtheta * cf * sf + dpsi * sf * sf * ct) + (iy - iz) * (dpsi * cf * cf * ct) + ix * dpsi * ct;
    let c22 = (iz - iy) * dphi * cf * sf;
    let c23 = -ix * dpsi * st * ct + iy * dpsi * sf * sf * st * ct + iz * dpsi * cf * cf * st * ct;
    let c31 = (iy - iz) * dpsi * ct * ct * sf * cf - ix * dtheta * ct;
    let c32 = (iz - iy) * (dtheta * cf * sf * st + dphi * sf * sf * ct)
        + (iy - iz) * dphi * cf * cf * ct
        + ix * dpsi * st * ct
        - iy * dpsi * sf * sf * st * ct
        - iz * dpsi * cf * cf * st * ct;
    let c33 = (iy - iz) * dphi * cf * sf * ct * ct - iy * dtheta * sf * sf * ct * st - iz * dtheta * cf * cf * ct * st
        + ix * dtheta * ct * st;
    Matrix3::new(c11, c12, c13, c21, c22, c23, c31, c32, c33)
}

/// R = Rz(ψ) Ry(θ) Rx(φ)
fn rotation(phi: f64, theta: f64, psi: f64) -> Matrix3<f64> {
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, phi.cos(), -phi.sin(), 0.0, phi.sin(), phi.cos());
    let ry = Matrix3::new(
        theta.cos(),
        0.0,
        theta.sin(),
        0.0,
        1.0,
        0.0,
        -theta.sin(),
        0.0,
        theta.cos(),
    );
    let rz = Matrix3::new(psi.cos(), -psi.sin(), 0.0, psi.sin(), psi.cos(), 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}

/// q̈ = (M̄ + R̄ S4)⁻¹ [R̄ (S1 μ − S2 q − S3 q̇ + S5) − C̄ q̇ − Ḡ], straight from MODEL_NOTES.md.
fn reference_dynamics(p: &PdParams, x: &[f64; 12], u: &[f64; 4]) -> [f64; 12] {
    let q = Vector6::from_column_slice(&x[..6]);
    let qd = Vector6::from_column_slice(&x[6..]);
    let mu = Vector6::new(0.0, 0.0, u[0], u[1], u[2], u[3]);
    let xi = |k: usize| p.xi(k);
    let s1 = Matrix6::from_diagonal(&Vector6::new(0.0, 0.0, xi(1), xi(2), xi(3), xi(4)));
    let s2 = Matrix6::from_diagonal(&Vector6::new(0.0, 0.0, 0.0, xi(5), xi(6), 0.0));
    let s3 = Matrix6::from_diagonal(&Vector6::new(0.0, 0.0, xi(7), xi(8), xi(9), xi(10)));
    let s4 = Matrix6::from_diagonal(&Vector6::new(0.0, 0.0, xi(11), 0.0, 0.0, xi(12)));
    let s5 = Vector6::new(0.0, 0.0, xi(13), 0.0, 0.0, 0.0);
    let mut r_bar = Matrix6::identity();
    r_bar
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&rotation(x[3], x[4], x[5]));
    let mut m_bar = Matrix6::zeros();
    m_bar
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * p.mass));
    m_bar
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&inertia_matrix(p, x[3], x[4]));
    let mut c_bar = Matrix6::zeros();
    c_bar
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&coriolis_matrix(p, x[3], x[4], x[9], x[10], x[11]));
    let g_bar = Vector6::new(0.0, 0.0, p.mass * p.gravity, 0.0, 0.0, 0.0);
    let lhs = m_bar + r_bar * s4;
    let rhs = r_bar * (s1 * mu - s2 * q - s3 * qd + s5) - c_bar * qd - g_bar;
    let qdd = lhs.lu().solve(&rhs).expect("M̄ + R̄S4 is invertible in the envelope");
    let mut f = [0.0; 12];
    f[..6].copy_from_slice(qd.as_slice());
    f[6..].copy_from_slice(qdd.as_slice());
    f
}

macro_rules! reference_test {
    ($test:ident, $krate:ident, $model:literal) => {
        #[test]
        fn $test() {
            let p = params($model);
            let mut worst: f64 = 0.0;
            for (x, u) in envelope_points(1000, 21) {
                let generated = $krate::continuous_dynamics(&x, &u);
                worst = worst.max(max_scaled_error(&generated, &reference_dynamics(&p, &x, &u)));
            }
            eprintln!(
                "{}: worst scaled error vs hand-written nalgebra {worst:.1e}",
                $model
            );
            assert!(
                worst <= 1e-10,
                "{}: generated vs hand-written nalgebra differ by {worst:e}",
                $model
            );
        }
    };
}

reference_test!(pd_paper_matches_hand_written_reference, pd_paper, "pd_paper");
reference_test!(pd_hover_matches_hand_written_reference, pd_hover, "pd_hover");
reference_test!(pd_m100_matches_hand_written_reference, pd_m100, "pd_m100");

/// Symbolic M and C of the generator, evaluated by its interpreter.
struct SymbolicMc {
    tape: Tape,
}

impl SymbolicMc {
    fn new(p: &PdParams) -> Self {
        let mut g = Graph::new();
        let vars: Vec<Id> = (0..16).map(|i| g.var(&format!("v{i}"))).collect();
        let v = PdVars::new(&vars);
        let m = inertia(&mut g, &v, p);
        let c = coriolis(&mut g, &v, &m);
        // Ṁ = Σₖ ∂M/∂Ωₖ Ω̇ₖ
        let mut outputs = Vec::new();
        for i in 0..3 {
            for j in 0..3 {
                let terms: Vec<Id> = (0..3)
                    .map(|k| {
                        let d = uavgen::symbolic::diff(&mut g, m[i][j], 3 + k);
                        g.mul(d, vars[9 + k])
                    })
                    .collect();
                outputs.push(g.sum(terms));
            }
        }
        outputs.extend(c.iter().flatten());
        outputs.extend(m.iter().flatten());
        Self {
            tape: Tape::new(&g, &outputs),
        }
    }

    /// (Ṁ, C, M) at state x.
    fn eval(&self, x: &[f64; 12]) -> (Matrix3<f64>, Matrix3<f64>, Matrix3<f64>) {
        let mut vars = x.to_vec();
        vars.extend([0.0; 4]);
        let out = self.tape.eval(&vars);
        let m = |k: usize| Matrix3::from_row_slice(&out[9 * k..9 * k + 9]);
        (m(0), m(1), m(2))
    }
}

#[test]
fn mdot_minus_two_c_is_skew_symmetric() {
    let p = params("pd_paper");
    let mc = SymbolicMc::new(&p);
    for (x, _) in envelope_points(1000, 31) {
        let (mdot, c, _) = mc.eval(&x);
        let n = mdot - 2.0 * c;
        let skew = (n + n.transpose()).abs().max();
        assert!(
            skew <= 1e-12,
            "Ṁ − 2C is not skew-symmetric at {x:?}: |N + Nᵀ| = {skew:e}"
        );
    }
}

#[test]
fn christoffel_c_matches_corrected_appendix() {
    // C is not unique, C Ω̇ is: compare the products, and M entry by entry.
    let p = params("pd_paper");
    let mc = SymbolicMc::new(&p);
    for (x, _) in envelope_points(1000, 32) {
        let (_, c, m) = mc.eval(&x);
        let omega_dot = Vector3::new(x[9], x[10], x[11]);
        let appendix = coriolis_matrix(&p, x[3], x[4], x[9], x[10], x[11]);
        let e = (c * omega_dot - appendix * omega_dot).abs().max();
        assert!(e <= 1e-12, "C Ω̇ differs from the corrected appendix by {e:e}");
        let e = (m - inertia_matrix(&p, x[3], x[4])).abs().max();
        assert!(e <= 1e-15, "M differs from the appendix by {e:e}");
    }
}

#[test]
fn the_printed_appendix_c_is_wrong() {
    // The uncorrected c21 (ψ̇ sφ cθ instead of ψ̇ sφ² cθ) changes C Ω̇: the
    // comparison above is able to fail.
    let p = params("pd_paper");
    let (phi, theta, dphi, dtheta, dpsi) = (0.4, 0.3, 0.5, -0.7, 1.1);
    let fixed = coriolis_matrix(&p, phi, theta, dphi, dtheta, dpsi);
    let (ix, iy, iz) = (p.xi(14), p.xi(15), p.xi(16));
    let _ = ix;
    let (sf, cf, ct) = (phi.sin(), phi.cos(), theta.cos());
    let printed_c21 =
        (iz - iy) * (dtheta * cf * sf + dpsi * sf * ct) + (iy - iz) * (dpsi * cf * cf * ct) + p.xi(14) * dpsi * ct;
    assert!((printed_c21 - fixed[(1, 0)]).abs() > 1e-6);
}

#[test]
fn self_consistent_pd_model_hovers() {
    // f(x_hover, u = 0) = 0 for any position and heading.
    for (pos, yaw) in [
        ([0.0, 0.0, 0.0], 0.0),
        ([3.0, 3.0, 5.0], 1.2),
        ([-7.0, 2.0, 10.0], -3.0),
    ] {
        let x = [pos[0], pos[1], pos[2], 0.0, 0.0, yaw, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let f = pd_hover::continuous_dynamics(&x, &[0.0; 4]);
        assert!(
            f.iter().all(|v| v.abs() <= 1e-12),
            "pd_hover does not hover at {x:?}: f = {f:?}"
        );
        let next = pd_hover::discrete_dynamics(&x, &[0.0; 4]);
        assert!(next.iter().zip(&x).all(|(a, b)| (a - b).abs() <= 1e-12));
    }
    // The paper's ξ13 cannot hold 2.4 kg up: it falls.
    let f = pd_paper::continuous_dynamics(&[0.0; 12], &[0.0; 4]);
    assert!(f[8] < -1.0, "pd_paper vertical acceleration at hover: {}", f[8]);
}
