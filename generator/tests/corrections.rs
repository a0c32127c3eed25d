//! The `corrections` block (docs/model-format.md#corrections): each correction by hand in the
//! symbolic IR, the extra states, analytic Jacobians of corrected models against central finite
//! differences, the envelope of the extra states, `attach_corrections`, and the evaluation of a
//! corrected model on a log it generated itself.

use serde_json::{json, Value};
use std::path::PathBuf;
use uavgen::discretize::{auto_substeps, discrete_step, Envelope};
use uavgen::evaluate::{evaluate, EvaluateOptions};
use uavgen::logs::{parse_log, FlightLog};
use uavgen::model::{attach_corrections, parse, Corrections};
use uavgen::{Model, ModelIr};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A SINDy toy with the 12 standard states: kinematic rows, v̇z = 2 u_vz, v̇x = u_roll,
/// v̇y = −9.81 sin(roll); zero at hover.
fn toy() -> Value {
    json!({
        "format": "uavgen-model/1", "kind": "sindy", "name": "toy",
        "library": ["u_vz", "u_roll", "sin(roll)", "roll_rate"],
        "kinematic": [["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
        "coefficients": [
            {"state": "vz", "term": "u_vz", "coefficient": 2.0},
            {"state": "vx", "term": "u_roll", "coefficient": 1.0},
            {"state": "vy", "term": "sin(roll)", "coefficient": -9.81},
            {"state": "roll_rate", "term": "roll_rate", "coefficient": -3.0}
        ]
    })
}

fn shipped(name: &str) -> Value {
    let text = std::fs::read_to_string(repo().join("models").join(name)).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `base` with `corrections` set, parsed.
fn with(mut base: Value, corrections: Value) -> Model {
    base["corrections"] = corrections;
    parse(&base.to_string(), "corrected.json").unwrap_or_else(|e| panic!("{e}"))
}

fn without(base: Value) -> Model {
    parse(&base.to_string(), "base.json").unwrap()
}

/// A full state: the 12 given standard states, then `extra`.
fn state(x12: [f64; 12], extra: &[f64]) -> Vec<f64> {
    x12.iter().chain(extra).copied().collect()
}

const HOVER: [f64; 12] = [0.0; 12];
const G: f64 = 9.81;

fn v(vx: f64, vy: f64, vz: f64) -> [f64; 12] {
    let mut x = HOVER;
    x[6] = vx;
    x[7] = vy;
    x[8] = vz;
    x
}

#[test]
fn linear_drag_at_unit_velocity_is_minus_the_coefficient() {
    let ir = ModelIr::new(&with(toy(), json!({"linear_drag": {"xy": 0.27, "z": 0.5}})));
    let f = ir.eval_f(&v(1.0, 0.0, 0.0), &[0.0; 4]);
    assert_eq!(f[6], -0.27);
    assert_eq!((f[7], f[8]), (0.0, 0.0));
    let f = ir.eval_f(&v(0.0, -2.0, 2.0), &[0.0; 4]);
    assert_eq!((f[6], f[7], f[8]), (0.0, 0.54, -1.0));
    // The kinematic rows are untouched: ż = vz.
    assert_eq!(f[2], 2.0);
    // A missing axis is 0.
    let ir = ModelIr::new(&with(toy(), json!({"linear_drag": {"z": 0.5}})));
    assert_eq!(ir.eval_f(&v(1.0, 1.0, 1.0), &[0.0; 4])[6..9], [0.0, 0.0, -0.5]);
}

#[test]
fn quadratic_drag_uses_the_smoothed_speed() {
    let ir = ModelIr::new(&with(toy(), json!({"quadratic_drag": {"xy": 0.02, "z": 0.04}})));
    // ‖v‖ = 5: √(25 + 0.1²) = √25.01.
    let f = ir.eval_f(&v(3.0, 0.0, 4.0), &[0.0; 4]);
    let s = 25.01_f64.sqrt();
    assert!((f[6] - (-0.02 * s * 3.0)).abs() < 1e-15, "{}", f[6]);
    assert!((f[8] - (-0.04 * s * 4.0)).abs() < 1e-15, "{}", f[8]);
    assert_eq!(f[7], 0.0);
    // Smooth at rest: zero force, finite slope −xy·ε.
    assert_eq!(ir.eval_f(&HOVER, &[0.0; 4])[6..9], [0.0; 3]);
    let (fx, _) = ir.eval_jacobian(&HOVER, &[0.0; 4]);
    assert!((fx[6][6] - (-0.02 * 0.1)).abs() < 1e-15, "{}", fx[6][6]);
}

#[test]
fn force_bias_is_added_to_the_velocity_rows() {
    let ir = ModelIr::new(&with(toy(), json!({"force_bias": [0.1, -0.05, 0.0]})));
    assert_eq!(ir.eval_f(&HOVER, &[0.0; 4])[6..9], [0.1, -0.05, 0.0]);
}

#[test]
fn thrust_gain_at_hover_is_kappa_g() {
    // SINDy (g = 9.81): the base's acceleration is 0 at hover, the thrust acceleration is g e_z.
    let ir = ModelIr::new(&with(toy(), json!({"thrust_gain": 0.08})));
    let f = ir.eval_f(&HOVER, &[0.0; 4]);
    assert_eq!(f[8], 0.08 * G);
    assert_eq!((f[6], f[7]), (0.0, 0.0));
    // With the base accelerating, κ scales its acceleration plus g: v̇z = 2·1 + κ (2 + g).
    let f = ir.eval_f(&HOVER, &[1.0, 0.5, 0.0, 0.0]);
    assert_eq!(f[8], 2.0 + 0.08 * (2.0 + G));
    // Vertical only: the horizontal rows keep the base model's acceleration.
    assert_eq!(f[6], 0.5);
    // PD: g is the model's gravity; pd_hover hovers at the origin with zero input.
    let mut pd = shipped("pd_hover.json");
    pd["gravity"] = json!(9.7);
    pd["xi"]["xi13"] = json!(2.4 * 9.7);
    let base = ModelIr::new(&without(pd.clone())).eval_f(&HOVER, &[0.0; 4]);
    assert!(base[8].abs() < 1e-12, "pd_hover with g = 9.7 hovers: {}", base[8]);
    let f = ModelIr::new(&with(pd, json!({"thrust_gain": -0.1}))).eval_f(&HOVER, &[0.0; 4]);
    assert!((f[8] - (-0.1 * 9.7)).abs() < 1e-12, "{}", f[8]);
}

#[test]
fn thrust_decay_scales_with_flight_time_and_flight_time_counts_seconds() {
    let model = with(toy(), json!({"thrust_decay": {"per_second": -0.0008}}));
    assert_eq!(model.states.last().map(String::as_str), Some("flight_time"));
    let ir = ModelIr::new(&model);
    assert_eq!(ir.nx, 13);
    let f = ir.eval_f(&state(HOVER, &[100.0]), &[0.0; 4]);
    assert!((f[8] - (-0.0008 * 100.0 * G)).abs() < 1e-15, "{}", f[8]);
    assert_eq!(f[12], 1.0);
    // At take-off (flight_time = 0) nothing changes.
    assert_eq!(ir.eval_f(&state(HOVER, &[0.0]), &[0.0; 4])[8], 0.0);
}

#[test]
fn ground_effect_at_a_quarter_rotor_radius_is_half_the_gain() {
    let r = 0.165;
    let ir = ModelIr::new(&with(toy(), json!({"ground_effect": {"gain": 1.0, "rotor_radius": r}})));
    let mut x = HOVER;
    x[2] = r / 4.0;
    // ρ² = (R/4)² / ((R/4)² + (R/4)²) = 1/2.
    let f = ir.eval_f(&x, &[0.0; 4]);
    assert!((f[8] - 0.5 * G).abs() < 1e-14, "{}", f[8]);
    // Bounded on the ground (ρ² = 1) and fading with height: (R/4)² / (z² + (R/4)²).
    assert!((ir.eval_f(&HOVER, &[0.0; 4])[8] - G).abs() < 1e-14);
    x[2] = 2.0;
    let rr = (r / 4.0) * (r / 4.0);
    assert!((ir.eval_f(&x, &[0.0; 4])[8] - G * rr / (4.0 + rr)).abs() < 1e-15);
    // Only z: a tilted thrust does not change the horizontal rows.
    assert_eq!(ir.eval_f(&x, &[0.0, 0.3, 0.0, 0.0])[6], 0.3);
}

#[test]
fn actuator_lag_adds_a_first_order_state_that_the_base_model_sees() {
    let model = with(toy(), json!({"actuator_lag": {"u_vz": 0.08, "u_roll": 0.2}}));
    assert_eq!(model.states[12..], ["u_vz_lagged", "u_roll_lagged"]);
    assert_eq!(model.base_nx(), 12);
    let ir = ModelIr::new(&model);
    let x = state(HOVER, &[0.4, -0.1]);
    let u = [1.0, 0.5, 0.0, 0.0];
    let f = ir.eval_f(&x, &u);
    // ṡ = (u − s)/τ
    assert!((f[12] - (1.0 - 0.4) / 0.08).abs() < 1e-14, "{}", f[12]);
    assert!((f[13] - (0.5 + 0.1) / 0.2).abs() < 1e-14, "{}", f[13]);
    // The base sees s: v̇z = 2 s_vz, v̇x = s_roll; the inputs act only through the lag.
    assert_eq!((f[8], f[6]), (0.8, -0.1));
    let (fx, fu) = ir.eval_jacobian(&x, &u);
    assert_eq!((fu[8][0], fu[6][1]), (0.0, 0.0));
    assert_eq!((fx[8][12], fx[6][13]), (2.0, 1.0));
    assert!((fu[12][0] - 1.0 / 0.08).abs() < 1e-12 && (fx[12][12] + 1.0 / 0.08).abs() < 1e-12);
}

#[test]
fn acceleration_lag_replaces_a_row_by_its_lag_state() {
    let model = with(
        toy(),
        json!({"actuator_lag": {"u_vz": 0.08}, "acceleration_lag": {"roll_rate": 0.1, "vz": 0.05}}),
    );
    // Input lags, then acceleration lags in state order.
    assert_eq!(
        model.states[12..],
        ["u_vz_lagged", "vz_dot_lagged", "roll_rate_dot_lagged"]
    );
    let ir = ModelIr::new(&model);
    let mut x12 = HOVER;
    x12[9] = 0.5;
    let x = state(x12, &[0.4, 0.3, -0.2]);
    let u = [1.0, 0.0, 0.0, 0.0];
    let f = ir.eval_f(&x, &u);
    // v̇z = ℓ_vz, ℓ̇_vz = (2 s_vz − ℓ_vz)/τ: the base row sees the lagged input.
    assert_eq!(f[8], 0.3);
    assert!((f[13] - (2.0 * 0.4 - 0.3) / 0.05).abs() < 1e-12, "{}", f[13]);
    // roll_rate' = ℓ, ℓ̇ = (−3 roll_rate − ℓ)/τ.
    assert_eq!(f[9], -0.2);
    assert!((f[14] - (-3.0 * 0.5 + 0.2) / 0.1).abs() < 1e-12, "{}", f[14]);
    let (fx, _) = ir.eval_jacobian(&x, &u);
    assert_eq!((fx[8][13], fx[9][14]), (1.0, 1.0));
    assert!((fx[14][9] + 3.0 / 0.1).abs() < 1e-12 && (fx[14][14] + 1.0 / 0.1).abs() < 1e-12);
}

#[test]
fn latency_is_not_part_of_f() {
    let corrected = with(toy(), json!({"latency": {"u_vz": 0.1, "u_yaw_rate": 0.05}}));
    assert_eq!(corrected.nx(), 12);
    assert_eq!(corrected.input_delays(), [0.1, 0.0, 0.0, 0.05]);
    assert_eq!(without(toy()).input_delays(), [0.0; 4]);
    let (a, b) = (ModelIr::new(&corrected), ModelIr::new(&without(toy())));
    let (x, u) = (v(1.0, 2.0, 3.0), [0.3, 0.2, -0.1, 0.5]);
    assert_eq!(a.eval_f(&x, &u), b.eval_f(&x, &u));
}

/// Every correction: Δf = f − f_base follows the equations of docs/model-format.md at random
/// points, with v̇_base from the uncorrected model at the same state and (lagged) input.
fn every_correction() -> Value {
    json!({
        "source": "test",
        "linear_drag": {"xy": 0.27, "z": 0.5},
        "quadratic_drag": {"xy": 0.02, "z": 0.04},
        "force_bias": [0.1, -0.05, 0.02],
        "thrust_gain": 0.08,
        "thrust_decay": {"per_second": -0.0008},
        "ground_effect": {"gain": 1.0, "rotor_radius": 0.165},
        "actuator_lag": {"u_roll": 0.08, "u_pitch": 0.08},
        "acceleration_lag": {"vz": 0.05, "yaw_rate": 0.1},
        "latency": {"u_vz": 0.1, "u_roll": 0.1, "u_pitch": 0.1, "u_yaw_rate": 0.1}
    })
}

#[test]
fn all_corrections_together_are_the_sum_of_the_equations() {
    for (file, g) in [("sindy_m100.json", G), ("pd_m100.json", -1.0)] {
        let base_model = without(shipped(file));
        let g = if g < 0.0 {
            match &base_model.dynamics {
                uavgen::model::Dynamics::Pd(p) => p.gravity,
                _ => unreachable!(),
            }
        } else {
            g
        };
        let model = with(shipped(file), every_correction());
        assert_eq!(
            model.states[12..],
            [
                "u_roll_lagged",
                "u_pitch_lagged",
                "vz_dot_lagged",
                "yaw_rate_dot_lagged",
                "flight_time"
            ],
            "{file}"
        );
        let (ir, base) = (ModelIr::new(&model), ModelIr::new(&base_model));
        let names = model.variables();
        let env = Envelope {
            samples: 40,
            seed: 5,
            ..Envelope::default()
        };
        for p in env.points(&names) {
            let (x, u) = p.split_at(ir.nx);
            let f = ir.eval_f(x, u);
            // The base sees the lag states instead of u_roll, u_pitch.
            let ub = [u[0], x[12], x[13], u[3]];
            let fb = base.eval_f(&x[..12], &ub);
            let (vel, z, tf) = ([x[6], x[7], x[8]], x[2], x[16]);
            // The lagged rows: vz and yaw_rate are their lag states ℓ; thrust terms see ℓ_vz.
            let a = [fb[6], fb[7], x[14]];
            let speed = (vel.iter().map(|a| a * a).sum::<f64>() + 0.01).sqrt();
            let rr = (0.165_f64 / 4.0).powi(2);
            for k in 0..3 {
                let (lin, quad) = ([0.27, 0.27, 0.5][k], [0.02, 0.02, 0.04][k]);
                let thrust = a[k] + if k == 2 { g } else { 0.0 };
                let mut expected = a[k] - lin * vel[k] - quad * speed * vel[k] + [0.1, -0.05, 0.02][k];
                if k == 2 {
                    // The thrust terms act on the vertical row only.
                    expected += 0.08 * thrust - 0.0008 * tf * thrust + thrust * rr / (z * z + rr);
                }
                let got = f[6 + k];
                assert!(
                    (got - expected).abs() <= 1e-12 * expected.abs().max(1.0),
                    "{file}: row {} {got} vs {expected} at {p:?}",
                    6 + k
                );
            }
            for i in (0..11).filter(|i| !(6..9).contains(i)) {
                assert!((f[i] - fb[i]).abs() <= 1e-12 * fb[i].abs().max(1.0), "{file}: row {i}");
            }
            assert_eq!(f[11], x[15], "{file}: the yaw_rate row is its lag state");
            assert!((f[12] - (u[1] - x[12]) / 0.08).abs() < 1e-9);
            assert!((f[13] - (u[2] - x[13]) / 0.08).abs() < 1e-9);
            // ℓ̇ = (b − ℓ)/τ with b the base row.
            assert!((f[14] - (fb[8] - x[14]) / 0.05).abs() <= 1e-9 * fb[8].abs().max(1.0));
            assert!((f[15] - (fb[11] - x[15]) / 0.1).abs() <= 1e-9 * fb[11].abs().max(1.0));
            assert_eq!(f[16], 1.0);
        }
    }
}

#[test]
fn jacobians_of_corrected_models_match_central_differences() {
    for file in ["sindy_m100.json", "pd_m100.json", "pd_hover.json"] {
        let model = with(shipped(file), every_correction());
        let ir = ModelIr::new(&model);
        let (nx, nu) = (ir.nx, ir.nu);
        let env = Envelope {
            samples: 60,
            seed: 11,
            ..Envelope::default()
        };
        let mut worst: f64 = 0.0;
        for p in env.points(&model.variables()) {
            let (fx, fu) = ir.eval_jacobian(&p[..nx], &p[nx..]);
            for j in 0..nx + nu {
                let eps = 1e-6 * p[j].abs().max(1.0);
                let (mut pp, mut pm) = (p.clone(), p.clone());
                pp[j] += eps;
                pm[j] -= eps;
                let fp = ir.eval_f(&pp[..nx], &pp[nx..]);
                let fm = ir.eval_f(&pm[..nx], &pm[nx..]);
                for i in 0..nx {
                    let fd = (fp[i] - fm[i]) / (2.0 * eps);
                    let exact = if j < nx { fx[i][j] } else { fu[i][j - nx] };
                    let err = (exact - fd).abs() / exact.abs().max(fd.abs()).max(1.0);
                    assert!(err < 1e-6, "{file}: ∂f{i}/∂z{j} = {exact} vs FD {fd} at {p:?}");
                    worst = worst.max(err);
                }
            }
        }
        eprintln!("{file} + corrections: worst scaled Jacobian error vs FD {worst:.2e}");
    }
}

#[test]
fn the_envelope_covers_the_extra_states_and_substeps_are_chosen() {
    let model = with(shipped("sindy_m100.json"), every_correction());
    let names = model.variables();
    let points = Envelope::default().points(&names);
    let col = |name: &str| names.iter().position(|n| n == name).unwrap();
    let (tf, roll_lag, pitch_lag) = (col("flight_time"), col("u_roll_lagged"), col("u_pitch_lagged"));
    assert!(points.iter().all(|p| (0.0..=600.0).contains(&p[tf])));
    assert!(points.iter().any(|p| p[tf] > 300.0), "flight_time spans 0..600 s");
    assert!(points
        .iter()
        .all(|p| p[roll_lag].abs() <= 0.611 && p[pitch_lag].abs() <= 0.611));
    assert!(points.iter().any(|p| p[roll_lag].abs() > 0.3));
    // The lag (τ = 0.08 s, λ = −12.5 1/s) is not stiff at 30 Hz.
    let choice = auto_substeps(&ModelIr::new(&model), 1.0 / 30.0, &Envelope::default()).unwrap();
    assert!(choice.substeps <= 2, "{choice:?}");
    // A fast lag is: λ = −1/τ = −1000 1/s needs many substeps.
    let mut c = every_correction();
    c["actuator_lag"]["u_roll"] = json!(0.001);
    let stiff = auto_substeps(
        &ModelIr::new(&with(shipped("sindy_m100.json"), c)),
        1.0 / 30.0,
        &Envelope::default(),
    );
    assert!(stiff.as_ref().map_or(true, |s| s.substeps >= 10), "{stiff:?}");
}

#[test]
fn rk4_integrates_the_lag_state() {
    let model = with(toy(), json!({"actuator_lag": {"u_vz": 0.1}}));
    let ir = ModelIr::new(&model);
    let dt = 1.0 / 30.0;
    let x = discrete_step(&ir, &state(HOVER, &[0.0]), &[1.0, 0.0, 0.0, 0.0], dt, 4);
    // RK4's e^{−z} ≈ 1 − z + z²/2 − z³/6 + z⁴/24 per substep, z = h/τ = 1/12: error ~ z⁵/120 each.
    let exact = 1.0 - (-dt / 0.1_f64).exp();
    assert!((x[12] - exact).abs() < 1e-6, "{} vs {exact}", x[12]);
}

#[test]
fn attach_inserts_the_block_and_keeps_the_file_readable() {
    // The shipped model without the corrections it carries (its identified delays).
    let mut shipped: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(repo().join("models/sindy_m100.json")).unwrap()).unwrap();
    shipped.as_object_mut().unwrap().remove("corrections");
    let text = serde_json::to_string_pretty(&shipped).unwrap() + "\n";
    let corrections: Corrections = serde_json::from_value(every_correction()).unwrap();
    let out = attach_corrections(&text, "sindy_m100.json", &corrections).unwrap();
    assert!(out.starts_with(text.trim_end().trim_end_matches('}').trim_end()));
    let model = parse(&out, "corrected.json").unwrap();
    assert_eq!(model.corrections.as_ref(), Some(&corrections));
    assert_eq!(model.nx(), 17);
    // Attaching again replaces the block.
    let smaller = Corrections {
        thrust_gain: Some(0.1),
        ..Corrections::default()
    };
    let again = attach_corrections(&out, "corrected.json", &smaller).unwrap();
    let model = parse(&again, "corrected.json").unwrap();
    assert_eq!(model.corrections, Some(smaller));
    assert_eq!(model.nx(), 12);
    // An invalid block is refused with the usual located error.
    let bad = Corrections {
        thrust_gain: Some(f64::NAN),
        ..Corrections::default()
    };
    let e = attach_corrections(&text, "m.json", &bad).unwrap_err().to_string();
    assert!(e.starts_with("m.json: "), "{e}");
}

#[test]
fn summary_lists_every_effect_and_the_extra_states() {
    let model = with(toy(), every_correction());
    let lines = model.corrections_summary();
    assert_eq!(lines[0], "corrections (source: test):");
    let text = lines.join("\n");
    for part in [
        "linear drag: xy 0.27 1/s, z 0.5 1/s",
        "quadratic drag: xy 0.02 1/m, z 0.04 1/m (ε = 0.1 m/s)",
        "force bias: [0.1, -0.05, 0.02] m/s²",
        "thrust gain: κ = 0.08",
        "thrust decay: -0.0008 per second of flight_time",
        "ground effect: gain 1, rotor radius 0.165 m",
        "actuator lag: u_roll 0.08 s, u_pitch 0.08 s",
        "u_vz 0.1 s, u_roll 0.1 s, u_pitch 0.1 s, u_yaw_rate 0.1 s",
        "acceleration lag: vz 0.05 s, yaw_rate 0.1 s",
        "extra states: u_roll_lagged, u_pitch_lagged, vz_dot_lagged, yaw_rate_dot_lagged, flight_time",
    ] {
        assert!(text.contains(part), "missing {part:?} in\n{text}");
    }
    assert!(without(toy()).corrections_summary().is_empty());
}

// ------------------------------------------------------------------ evaluation

const HEADER: &str = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate";

/// A corrected model flown on its own: the plant receives the logged command delayed by the
/// latency (3 samples at 30 Hz), the lag and flight-time states are integrated with the model.
/// The log holds the 12 standard states and the commands as sent.
fn self_simulated_log(model: &Model, n: usize) -> FlightLog {
    let ir = ModelIr::new(model);
    let dt = 1.0 / 30.0;
    let command = |k: usize| {
        let t = k as f64 * dt;
        [
            0.4 * (0.9 * t).sin(),
            0.05 * (1.3 * t).sin(),
            0.04 * (0.7 * t).cos(),
            0.1,
        ]
    };
    // At rest at the first (delayed) command: input lag states = u_0, acceleration lag states =
    // their rows (v̇z = 2 u_vz, the toy's yaw_rate row is 0), flight time 0.
    let u0 = command(0);
    let mut x: Vec<f64> = [0.0; 12]
        .iter()
        .copied()
        .chain([u0[1], u0[2], 2.0 * u0[0], 0.0, 0.0])
        .collect();
    x[2] = 1.0;
    let mut csv = format!("# rate_hz: 30\n{HEADER}\n");
    for k in 0..n {
        let sent = command(k);
        let row: Vec<String> = std::iter::once(format!("{:e}", k as f64 * dt))
            .chain(x[..12].iter().map(|v| format!("{v:e}")))
            .chain(sent.iter().map(|v| format!("{v:e}")))
            .collect();
        csv.push_str(&row.join(","));
        csv.push('\n');
        let applied = command(k.saturating_sub(3));
        x = discrete_step(&ir, &x, &applied, dt, 4);
    }
    parse_log(&csv, "self.csv").unwrap()
}

#[test]
fn evaluate_runs_a_corrected_model_with_its_extra_states_and_delays() {
    let model = with(toy(), every_correction());
    let log = self_simulated_log(&model, 240);
    let options = EvaluateOptions {
        substeps: Some(4),
        ..EvaluateOptions::default()
    };
    let e = evaluate(&model, std::slice::from_ref(&log), &options).unwrap();
    let next = e.one_step_next.metrics.as_ref().unwrap();
    assert_eq!(next.names.len(), 12, "scored on the 12 logged states");
    // The lag states are reconstructed by the exact filter, the simulation used RK4: tiny
    // differences only.
    assert!(next.overall_rmse < 1e-7, "{next}");
    let horizon = e.horizon.metrics.as_ref().unwrap();
    assert!(horizon.overall_rmse < 1e-6, "{horizon}");
    let whole = e.whole_flight.metrics.as_ref().unwrap();
    assert!(whole.overall_rmse < 1e-6, "{whole}");
    // Without the latency (inputs as logged) the same model predicts worse.
    let mut no_latency = every_correction();
    no_latency.as_object_mut().unwrap().remove("latency");
    let e2 = evaluate(&with(toy(), no_latency), &[log], &options).unwrap();
    let next2 = e2.one_step_next.metrics.as_ref().unwrap();
    assert!(next2.overall_rmse > 100.0 * next.overall_rmse.max(1e-12), "{next2}");
}

#[test]
fn check_prints_the_corrections() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("corrected.json");
    let mut value = shipped("sindy_m100.json");
    value["corrections"] = every_correction();
    std::fs::write(&path, value.to_string()).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .args(["check", "--model", path.to_str().unwrap()])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("model 'sindy_m100' (sindy), 17 states, 4 inputs"), "{out}");
    assert!(
        out.contains("\n  corrections (source: test):\n    linear drag: xy 0.27 1/s, z 0.5 1/s\n"),
        "{out}"
    );
    assert!(
        out.contains(
            "    extra states: u_roll_lagged, u_pitch_lagged, vz_dot_lagged, yaw_rate_dot_lagged, flight_time\n"
        ),
        "{out}"
    );
    assert!(out.contains("RK4 at 30 Hz"), "{out}");
}

#[test]
fn mpc_weights_of_the_extra_states_default_to_zero() {
    use uavgen::mpc_options::{MpcOptions, MpcOptionsFile};
    let model = with(toy(), every_correction());
    let d = MpcOptions::defaults(&model);
    assert_eq!(d.q.len(), 17);
    assert_eq!(d.q[12..], [0.0; 5]);
    // An options file written for the 12 logged states: the extra states get 0.
    let file = MpcOptionsFile {
        q: Some(vec![1.0; 12]),
        ..MpcOptionsFile::default()
    };
    let o = MpcOptions::from_file(&model, file, "o.json").unwrap();
    assert_eq!(o.q[..12], [1.0; 12]);
    assert_eq!((o.q[12..].to_vec(), o.q_terminal.len()), (vec![0.0; 5], 17));
    let file = MpcOptionsFile {
        q: Some(vec![1.0; 13]),
        ..MpcOptionsFile::default()
    };
    let e = MpcOptions::from_file(&model, file, "o.json").unwrap_err();
    assert_eq!(
        e,
        "o.json: q: expected 17 values (or 12: the extra states of the corrections then weigh 0), found 13"
    );
}
