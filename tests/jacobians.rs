//! Analytic Jacobians of the generated discrete map equal central finite
//! differences of `discrete_dynamics` (1e-6 relative), and the generated
//! continuous Jacobians equal the symbolic ones (1e-12).

use proptest::prelude::*;
use uavgen_tests::{close, envelope_points, max_scaled_error, shipped_ir, INPUT_BOUNDS, STATE_BOUNDS};

/// Central differences of `f` at (x, u), step εⱼ = 1e-6 · max(1, |zⱼ|).
fn finite_differences(
    f: impl Fn(&[f64; 12], &[f64; 4]) -> [f64; 12],
    x: &[f64; 12],
    u: &[f64; 4],
) -> ([[f64; 12]; 12], [[f64; 4]; 12]) {
    let mut a = [[0.0; 12]; 12];
    let mut b = [[0.0; 4]; 12];
    for j in 0..16 {
        let (mut xp, mut xm, mut up, mut um) = (*x, *x, *u, *u);
        let eps = if j < 12 {
            let e = 1e-6 * x[j].abs().max(1.0);
            xp[j] += e;
            xm[j] -= e;
            e
        } else {
            let e = 1e-6 * u[j - 12].abs().max(1.0);
            up[j - 12] += e;
            um[j - 12] -= e;
            e
        };
        let (fp, fm) = (f(&xp, &up), f(&xm, &um));
        for i in 0..12 {
            let d = (fp[i] - fm[i]) / (2.0 * eps);
            if j < 12 {
                a[i][j] = d;
            } else {
                b[i][j - 12] = d;
            }
        }
    }
    (a, b)
}

/// Asserts every entry within 1e-6 (scaled) and returns the worst scaled error.
fn assert_jacobians_match_fd(
    name: &str,
    f: impl Fn(&[f64; 12], &[f64; 4]) -> [f64; 12] + Copy,
    jac: impl Fn(&[f64; 12], &[f64; 4]) -> ([[f64; 12]; 12], [[f64; 4]; 12]),
    x: &[f64; 12],
    u: &[f64; 4],
) -> f64 {
    let (a, b) = jac(x, u);
    let (fa, fb) = finite_differences(f, x, u);
    for i in 0..12 {
        for j in 0..12 {
            assert!(
                close(a[i][j], fa[i][j], 1e-6),
                "{name}: A[{i}][{j}] = {} vs FD {} at x={x:?} u={u:?}",
                a[i][j],
                fa[i][j]
            );
        }
        for j in 0..4 {
            assert!(
                close(b[i][j], fb[i][j], 1e-6),
                "{name}: B[{i}][{j}] = {} vs FD {} at x={x:?} u={u:?}",
                b[i][j],
                fb[i][j]
            );
        }
    }
    let flat = |m: &[[f64; 12]; 12], n: &[[f64; 4]; 12]| -> Vec<f64> {
        m.iter().flatten().chain(n.iter().flatten()).copied().collect()
    };
    max_scaled_error(&flat(&a, &b), &flat(&fa, &fb))
}

macro_rules! jacobian_tests {
    ($fd:ident, $prop:ident, $sym:ident, $krate:ident, $model:literal) => {
        #[test]
        fn $fd() {
            let mut worst: f64 = 0.0;
            for (x, u) in envelope_points(1000, 11) {
                let e = assert_jacobians_match_fd(
                    $model,
                    $krate::discrete_dynamics,
                    $krate::discrete_jacobians,
                    &x,
                    &u,
                );
                worst = worst.max(e);
            }
            eprintln!(
                "{}: worst scaled error of [A B] vs central differences {worst:.1e}",
                $model
            );
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(200))]
            #[test]
            fn $prop(
                x in proptest::array::uniform12(-1.0f64..1.0),
                u in proptest::array::uniform4(-1.0f64..1.0),
            ) {
                let x: [f64; 12] = core::array::from_fn(|i| x[i] * STATE_BOUNDS[i]);
                let u: [f64; 4] = core::array::from_fn(|i| u[i] * INPUT_BOUNDS[i]);
                assert_jacobians_match_fd($model, $krate::discrete_dynamics, $krate::discrete_jacobians, &x, &u);
                let (_, a, b) = $krate::discrete_linearization(&x, &u);
                let (a2, b2) = $krate::discrete_jacobians(&x, &u);
                prop_assert_eq!(a, a2);
                prop_assert_eq!(b, b2);
            }
        }

        #[test]
        fn $sym() {
            let ir = shipped_ir($model);
            for (x, u) in envelope_points(1000, 12) {
                let (fx, fu) = $krate::continuous_jacobians(&x, &u);
                let (sx, su) = ir.eval_jacobian(&x, &u);
                for i in 0..12 {
                    let e = max_scaled_error(&fx[i], &sx[i]).max(max_scaled_error(&fu[i], &su[i]));
                    assert!(
                        e <= 1e-12,
                        "{}: row {i} of the continuous Jacobian differs by {e:e}",
                        $model
                    );
                }
            }
        }
    };
}

jacobian_tests!(
    pd_paper_discrete_jacobians_match_fd,
    pd_paper_prop,
    pd_paper_continuous_jacobians_match_symbolic,
    pd_paper,
    "pd_paper"
);
jacobian_tests!(
    pd_hover_discrete_jacobians_match_fd,
    pd_hover_prop,
    pd_hover_continuous_jacobians_match_symbolic,
    pd_hover,
    "pd_hover"
);
jacobian_tests!(
    pd_m100_discrete_jacobians_match_fd,
    pd_m100_prop,
    pd_m100_continuous_jacobians_match_symbolic,
    pd_m100,
    "pd_m100"
);
jacobian_tests!(
    sindy_discrete_jacobians_match_fd,
    sindy_prop,
    sindy_continuous_jacobians_match_symbolic,
    sindy_m100,
    "sindy_m100"
);
