//! Crates generated from corrected models compile, and their `continuous_dynamics`,
//! `continuous_jacobians` and `discrete_dynamics` equal the symbolic evaluator's (1e-12, 1e-10),
//! their `discrete_jacobians` central differences of `discrete_dynamics` (1e-6); the new
//! constants (`INPUT_DELAY`, `INPUT_DELAY_SAMPLES`, `STATE_NAMES`) and the zero MPC weights of the
//! extra states are in place. Both crates build in one target directory (libm once).

use serde_json::{json, Value};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use uavgen::codegen::write::write_all;
use uavgen::discretize::{discrete_step, Envelope};
use uavgen::model::parse;
use uavgen::{generate, GenerateOptions, Model, ModelIr};

fn corrected(file: &str, corrections: Value) -> Model {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models").join(file);
    let mut value: Value = serde_json::from_str(&fs::read_to_string(path).unwrap()).unwrap();
    value["corrections"] = corrections;
    parse(&value.to_string(), &format!("corrected_{file}")).unwrap_or_else(|e| panic!("{e}"))
}

/// `[a, b, …]` with round-trip floats (Rust array syntax).
fn list(v: &[f64]) -> String {
    format!(
        "[{}]",
        v.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", ")
    )
}

fn matrix(m: &[Vec<f64>]) -> String {
    format!("[{}]", m.iter().map(|r| list(r)).collect::<Vec<_>>().join(", "))
}

/// Generate `model` as crate `name` into `dir`, add a test that compares it with the interpreter
/// at envelope points, and run `cargo test` there.
fn generate_and_test(model: &Model, name: &str, dir: &Path, extra_checks: &str) {
    let options = GenerateOptions {
        crate_name: Some(name.to_string()),
        ..GenerateOptions::default()
    };
    let generated = generate(model, &options).unwrap();
    let out = dir.join(name);
    write_all(&out, &generated.files).unwrap();
    let ir = ModelIr::new(model);
    let env = Envelope {
        samples: 6,
        seed: 3,
        ..Envelope::default()
    };
    let mut cases = String::new();
    for p in env.points(&model.variables()).iter().skip(1) {
        let (x, u) = p.split_at(ir.nx);
        let f = ir.eval_f(x, u);
        let (fx, fu) = ir.eval_jacobian(x, u);
        let step = discrete_step(&ir, x, u, 1.0 / 30.0, generated.substeps);
        cases.push_str(&format!(
            "    check(&{}, &{}, &{}, &{}, &{}, &{});\n",
            list(x),
            list(u),
            list(&f),
            matrix(&fx),
            matrix(&fu),
            list(&step)
        ));
    }
    let test = format!(
        r#"#![allow(clippy::all)]
use {name}::*;

fn close(a: f64, b: f64) -> bool {{
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0)
}}

fn check(x: &[f64; NX], u: &[f64; NU], f: &[f64; NX], fx: &[[f64; NX]; NX], fu: &[[f64; NU]; NX], step: &[f64; NX]) {{
    let g = continuous_dynamics(x, u);
    let (gx, gu) = continuous_jacobians(x, u);
    let s = discrete_dynamics(x, u);
    for i in 0..NX {{
        assert!(close(g[i], f[i]), "f[{{i}}] = {{}} vs {{}}", g[i], f[i]);
        assert!((s[i] - step[i]).abs() <= 1e-10 * step[i].abs().max(1.0), "x+[{{i}}] = {{}} vs {{}}", s[i], step[i]);
        for j in 0..NX {{ assert!(close(gx[i][j], fx[i][j]), "fx[{{i}}][{{j}}]"); }}
        for j in 0..NU {{ assert!(close(gu[i][j], fu[i][j]), "fu[{{i}}][{{j}}]"); }}
    }}
    // The forward sensitivities through RK4 against central differences of discrete_dynamics.
    let (a, b) = discrete_jacobians(x, u);
    for j in 0..NX + NU {{
        let (mut xp, mut xm, mut up, mut um) = (*x, *x, *u, *u);
        let eps = if j < NX {{
            let e = 1e-6 * x[j].abs().max(1.0);
            xp[j] += e;
            xm[j] -= e;
            e
        }} else {{
            let e = 1e-6 * u[j - NX].abs().max(1.0);
            up[j - NX] += e;
            um[j - NX] -= e;
            e
        }};
        let (fp, fm) = (discrete_dynamics(&xp, &up), discrete_dynamics(&xm, &um));
        for i in 0..NX {{
            let fd = (fp[i] - fm[i]) / (2.0 * eps);
            let exact = if j < NX {{ a[i][j] }} else {{ b[i][j - NX] }};
            assert!((exact - fd).abs() <= 1e-6 * exact.abs().max(fd.abs()).max(1.0), "∂x+{{i}}/∂z{{j}}: {{exact}} vs FD {{fd}}");
        }}
    }}
}}

#[test]
fn matches_the_symbolic_evaluator() {{
{cases}}}

#[test]
fn constants_and_a_solve() {{
{extra_checks}
    for i in 12..NX {{
        assert_eq!((Q[i], Q_TERMINAL[i]), (0.0, 0.0), "extra state {{}} is not weighted", STATE_NAMES[i]);
    }}
    let mut x0 = [0.0; NX];
    x0[2] = 1.0;
    let mut reference = [[0.0; NX]; N + 1];
    for r in reference.iter_mut() {{ r[0] = 1.0; r[2] = 2.0; }}
    let mut mpc = Mpc::new();
    let s = mpc.solve(&x0, &reference);
    assert!(matches!(s.status, Status::Solved | Status::IterationCap | Status::HessianRegularised), "{{:?}}", s.status);
    for i in 0..NU {{ assert!(s.u0[i].is_finite() && s.u0[i] >= U_MIN[i] && s.u0[i] <= U_MAX[i]); }}
}}
"#
    );
    fs::create_dir_all(out.join("tests")).unwrap();
    fs::write(out.join("tests/matches.rs"), test).unwrap();
    let target = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("corrections-crates-target");
    let o = Command::new(env!("CARGO"))
        .args(["test", "--quiet", "--offline", "--target-dir", target.to_str().unwrap()])
        .current_dir(&out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{name} failed to build or test:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn corrected_sindy_crate_matches_the_interpreter() {
    let model = corrected(
        "sindy_m100.json",
        json!({
            "source": "corrections_crates.rs",
            "linear_drag": {"xy": 0.27, "z": 0.5},
            "quadratic_drag": {"xy": 0.02, "z": 0.04},
            "force_bias": [0.1, -0.05, 0.0],
            "thrust_gain": 0.08,
            "thrust_decay": {"per_second": -0.0008},
            "ground_effect": {"gain": 1.0, "rotor_radius": 0.165},
            "actuator_lag": {"u_roll": 0.08, "u_pitch": 0.08},
            "latency": {"u_vz": 0.1, "u_roll": 0.1, "u_pitch": 0.1, "u_yaw_rate": 0.05}
        }),
    );
    let tmp = tempfile::tempdir().unwrap();
    let checks = r#"
    assert_eq!(NX, 15);
    assert_eq!(STATE_NAMES[12..], ["u_roll_lagged", "u_pitch_lagged", "flight_time"]);
    assert_eq!(INPUT_DELAY, [0.1, 0.1, 0.1, 0.05]);
    // round(0.05 · 30) = round(1.5) = 2
    assert_eq!(INPUT_DELAY_SAMPLES, [3, 3, 3, 2]);"#;
    generate_and_test(&model, "corrected_sindy", tmp.path(), checks);
    let model_rs = fs::read_to_string(tmp.path().join("corrected_sindy/src/model.rs")).unwrap();
    assert!(model_rs.contains("sqrt("), "the quadratic drag's √ is emitted");
}

#[test]
fn corrected_pd_crate_matches_the_interpreter() {
    let model = corrected(
        "pd_m100.json",
        json!({
            "linear_drag": {"xy": 0.3, "z": 0.2},
            "quadratic_drag": {"xy": 0.01, "z": 0.0},
            "actuator_lag": {"u_vz": 0.15, "u_roll": 0.08, "u_pitch": 0.08},
            "acceleration_lag": {"roll_rate": 0.04, "pitch_rate": 0.04}
        }),
    );
    let tmp = tempfile::tempdir().unwrap();
    let checks = r#"
    assert_eq!(NX, 17);
    assert_eq!(
        STATE_NAMES[12..],
        ["u_vz_lagged", "u_roll_lagged", "u_pitch_lagged", "roll_rate_dot_lagged", "pitch_rate_dot_lagged"]
    );
    assert_eq!(INPUT_DELAY, [0.0; NU]);
    assert_eq!(INPUT_DELAY_SAMPLES, [0; NU]);"#;
    generate_and_test(&model, "corrected_pd", tmp.path(), checks);
}
