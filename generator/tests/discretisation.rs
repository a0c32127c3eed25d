//! The automatic substep rule: discrete stability wherever the continuous
//! model is stable, over the envelope.

use nalgebra::DMatrix;
use std::path::PathBuf;
use uavgen::discretize::{auto_substeps, discrete_step, Envelope};
use uavgen::ModelIr;

fn ir(name: &str) -> ModelIr {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models").join(name);
    ModelIr::new(&uavgen::load(&path).unwrap())
}

/// Spectral radius of the discrete map's Jacobian ∂F/∂x (central differences).
fn discrete_spectral_radius(ir: &ModelIr, x: &[f64], u: &[f64], substeps: usize) -> f64 {
    let n = ir.nx;
    let mut a = DMatrix::zeros(n, n);
    for j in 0..n {
        let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
        xp[j] += 1e-6;
        xm[j] -= 1e-6;
        let (fp, fm) = (
            discrete_step(ir, &xp, u, 1.0 / 30.0, substeps),
            discrete_step(ir, &xm, u, 1.0 / 30.0, substeps),
        );
        for i in 0..n {
            a[(i, j)] = (fp[i] - fm[i]) / 2e-6;
        }
    }
    a.complex_eigenvalues().iter().map(|l| l.norm()).fold(0.0, f64::max)
}

#[test]
fn paper_pd_model_needs_three_substeps_at_30_hz() {
    let ir = ir("pd_paper.json");
    let choice = auto_substeps(&ir, 1.0 / 30.0, &Envelope::default()).unwrap();
    assert_eq!(choice.substeps, 3);
    assert!(
        (choice.stiffest.re + 183.0).abs() < 1.0,
        "stiffest eigenvalue {}",
        choice.stiffest
    );
    // At hover the continuous model is stable in roll; with 2 substeps RK4 is not.
    let hover = [0.0; 12];
    let u = [0.0; 4];
    assert!(discrete_spectral_radius(&ir, &hover, &u, 2) > 1.5);
    assert!(discrete_spectral_radius(&ir, &hover, &u, 3) <= 1.0 + 1e-9);
}

#[test]
fn automatic_choice_is_stable_where_the_continuous_model_is() {
    // At envelope points where every eigenvalue of ∂f/∂x has Re λ ≤ 0 (the
    // model is locally stable), the discrete map with the chosen M must not
    // amplify: ρ(∂F/∂x) ≤ 1 + 1e-2. The margin is the frozen-Jacobian premise, not slack for M:
    // the eigenvalue-0 directions (positions and yaw integrate velocities) move off 1 by O(h² ∂A/∂x f)
    // when heading terms (sin/cos yaw) change along the step — 1.006 for sindy_m100 at its worst
    // point — while a too-small M gives |R(hλ)| ≫ 1 (pd_paper with M = 1: |R(−6.1)| ≈ 20).
    for name in ["pd_paper.json", "pd_hover.json", "pd_m100.json", "sindy_m100.json"] {
        let ir = ir(name);
        let m = auto_substeps(&ir, 1.0 / 30.0, &Envelope::default()).unwrap().substeps;
        let names: Vec<String> = ir.state_names.iter().chain(&ir.input_names).cloned().collect();
        let env = Envelope {
            samples: 200,
            seed: 99,
            ..Envelope::default()
        };
        let mut checked = 0;
        for p in env.points(&names) {
            let (x, u) = p.split_at(ir.nx);
            let (fx, _) = ir.eval_jacobian(x, u);
            let a = DMatrix::from_fn(ir.nx, ir.nx, |i, j| fx[i][j]);
            let max_re = a.complex_eigenvalues().iter().map(|l| l.re).fold(f64::MIN, f64::max);
            if max_re > 1e-9 {
                continue;
            }
            checked += 1;
            let rho = discrete_spectral_radius(&ir, x, u, m);
            assert!(
                rho <= 1.0 + 1e-2,
                "{name}: ρ(∂F/∂x) = {rho} > 1 with M = {m} at a stable point {p:?}"
            );
        }
        assert!(checked > 0, "{name}: no locally stable envelope point was checked");
        eprintln!("{name}: M = {m}, {checked} locally stable points checked");
    }
}

#[test]
fn models_whose_jacobians_stall_schur_still_get_a_substep_count() {
    // ẋ = −vx³ and friends: nalgebra's uncapped Schur iteration never returned on these.
    let text = r#"{"format": "uavgen-model/1", "kind": "sindy", "name": "cube",
        "library": ["vx^3", "vx*roll", "sin(roll)^2"], "kinematic": [["x", "vx"]],
        "coefficients": [{"state": "vx", "term": "vx^3", "coefficient": -1.0},
                         {"state": "vy", "term": "vx*roll", "coefficient": -1.0},
                         {"state": "vz", "term": "sin(roll)^2", "coefficient": 1.0}]}"#;
    let ir = ModelIr::new(&uavgen::model::parse(text, "cube.json").unwrap());
    let choice = auto_substeps(&ir, 1.0 / 30.0, &Envelope::default()).unwrap();
    // ∂(−vx³)/∂vx = −3 vx² reaches −75 1/s at |vx| = 5: 75·1.25/30 = 3.1 > 2.785 → M = 2.
    assert_eq!(choice.substeps, 2);
}
