//! The generated code equals the symbolic evaluator (the generic side) on
//! random states and inputs: continuous dynamics to 1e-12 relative, the
//! discrete map to 1e-12 against the interpreted RK4.

use uavgen::discretize::discrete_step;
use uavgen_tests::{envelope_points, max_scaled_error, shipped_ir};

macro_rules! check_model {
    ($test:ident, $krate:ident, $model:literal) => {
        #[test]
        fn $test() {
            let ir = shipped_ir($model);
            let mut worst_f: f64 = 0.0;
            let mut worst_step: f64 = 0.0;
            for (x, u) in envelope_points(1000, 7) {
                let generated = $krate::continuous_dynamics(&x, &u);
                let symbolic = ir.eval_f(&x, &u);
                worst_f = worst_f.max(max_scaled_error(&generated, &symbolic));
                let generated = $krate::discrete_dynamics(&x, &u);
                let generic = discrete_step(&ir, &x, &u, $krate::DT, $krate::SUBSTEPS);
                worst_step = worst_step.max(max_scaled_error(&generated, &generic));
            }
            eprintln!(
                "{}: worst scaled error: continuous {worst_f:.1e}, discrete {worst_step:.1e}",
                $model
            );
            assert!(
                worst_f <= 1e-12,
                "{}: continuous dynamics differ by {worst_f:e}",
                $model
            );
            assert!(
                worst_step <= 1e-12,
                "{}: discrete dynamics differ by {worst_step:e}",
                $model
            );
        }
    };
}

check_model!(pd_paper_matches_symbolic, pd_paper, "pd_paper");
check_model!(pd_hover_matches_symbolic, pd_hover, "pd_hover");
check_model!(sindy_m100_matches_symbolic, sindy_m100, "sindy_m100");
check_model!(pd_m100_matches_symbolic, pd_m100, "pd_m100");

#[test]
fn f32_crate_tracks_the_f64_model() {
    let ir = shipped_ir("pd_hover");
    let mut worst: f64 = 0.0;
    for (x, u) in envelope_points(1000, 8) {
        let xf = x.map(|v| v as f32);
        let uf = u.map(|v| v as f32);
        let generated: Vec<f64> = pd_hover_f32::continuous_dynamics(&xf, &uf)
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let xr = xf.map(f64::from);
        let ur = uf.map(f64::from);
        worst = worst.max(max_scaled_error(&generated, &ir.eval_f(&xr, &ur)));
    }
    eprintln!("pd_hover_f32: worst scaled error vs f64 symbolic {worst:.1e}");
    assert!(worst <= 1e-4, "f32 dynamics differ by {worst:e}");
}

#[test]
fn sizes_and_names_follow_the_model() {
    assert_eq!((pd_paper::NX, pd_paper::NU, pd_paper::N), (12, 4, 30));
    assert!((pd_paper::DT - 1.0 / 30.0).abs() < 1e-15);
    assert_eq!(pd_paper::STATE_NAMES[3], "roll");
    assert_eq!(pd_paper::INPUT_NAMES[0], "u_vz");
    // The paper's ξ make the roll mode stiff: the automatic rule picks 3 substeps.
    assert_eq!(pd_paper::SUBSTEPS, 3);
    assert_eq!(core::mem::size_of::<pd_hover_f32::Real>(), 4);
}
