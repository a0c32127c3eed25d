//! uavgen::evaluate: the three prediction kinds on synthetic logs with known answers,
//! divergence handling, plots, and the shared M100 run 7 (skipped when absent).

mod shared;
use std::path::PathBuf;
use uavgen::discretize::discrete_step;
use uavgen::evaluate::{evaluate, plot_states, wrap_angle, EvaluateOptions, Evaluation};
use uavgen::logs::{parse_log, read_log, FlightLog};
use uavgen::metrics::Metrics;
use uavgen::model::parse;
use uavgen::{load, Model, ModelIr};

/// The height (m) of the synthetic flights: well clear of the ground, whose samples (z ≤ 0.02 m)
/// evaluate's horizon runs leave out.
const FLYING: f64 = 10.0;

const HEADER: &str = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate";

/// A log in the LOG_FORMAT.md CSV format from time stamps (as written), states and inputs.
fn log_from(t: &[String], x: &[[f64; 12]], u: &[[f64; 4]], label: &str) -> FlightLog {
    let mut csv = format!("# rate_hz: 30\n{HEADER}\n");
    for k in 0..t.len() {
        let row: Vec<String> = std::iter::once(t[k].clone())
            .chain(x[k].iter().map(|v| format!("{v:e}")))
            .chain(u[k].iter().map(|v| format!("{v:e}")))
            .collect();
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    parse_log(&csv, label).expect("synthetic log parses")
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A SINDy model with the 12 default states: kinematic rows and the given coefficients.
fn sindy(name: &str, library: &[&str], coefficients: &[(&str, &str, f64)]) -> Model {
    let lib: Vec<String> = library.iter().map(|t| format!("\"{t}\"")).collect();
    let coef: Vec<String> = coefficients
        .iter()
        .map(|(s, t, c)| format!("{{\"state\": \"{s}\", \"term\": \"{t}\", \"coefficient\": {c:e}}}"))
        .collect();
    let text = format!(
        r#"{{"format": "uavgen-model/1", "kind": "sindy", "name": "{name}",
        "library": [{}],
        "kinematic": [["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
        "coefficients": [{}]}}"#,
        lib.join(","),
        coef.join(",")
    );
    parse(&text, &format!("{name}.json")).expect("test model parses")
}

fn all_finite(e: &Evaluation) {
    let check = |m: &Metrics| {
        for v in m.rmse.iter().chain(&m.mae).chain(&m.d1) {
            assert!(v.is_finite(), "{m:?}");
        }
        assert!(m.overall_rmse.is_finite() && m.overall_mae.is_finite() && m.overall_d1.is_finite());
    };
    for m in [
        &e.one_step_derivative.metrics,
        &e.one_step_next.metrics,
        &e.horizon.metrics,
        &e.horizon.end,
        &e.whole_flight.metrics,
    ]
    .into_iter()
    .flatten()
    {
        check(m);
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

/// pd_hover simulated with its own RK4 discretisation, under smooth inputs.
fn simulated_pd_log(model: &Model, substeps: usize, n: usize) -> FlightLog {
    let ir = ModelIr::new(model);
    let dt = 1.0 / 30.0;
    let mut t = Vec::new();
    let mut xs = Vec::new();
    let mut us = Vec::new();
    let mut x = vec![0.0; 12];
    x[2] = FLYING;
    for k in 0..n {
        let tk = k as f64 * dt;
        let u = [
            0.5 * (0.7 * tk).sin(),
            0.1 * (1.3 * tk).sin(),
            0.08 * (0.9 * tk).cos(),
            0.2 * (0.5 * tk).sin(),
        ];
        t.push(format!("{tk:e}"));
        xs.push(<[f64; 12]>::try_from(&x[..]).unwrap());
        us.push(u);
        x = discrete_step(&ir, &x, &u, dt, substeps);
    }
    log_from(&t, &xs, &us, "simulated.csv")
}

#[test]
fn model_on_its_own_simulation_predicts_the_next_sample_exactly() {
    let model = load(&repo().join("models/pd_hover.json")).unwrap();
    let log = simulated_pd_log(&model, 4, 300);
    let options = EvaluateOptions {
        horizon: 30,
        substeps: Some(4),
        ..Default::default()
    };
    let e = evaluate(&model, &[log], &options).unwrap();
    all_finite(&e);
    let next = e.one_step_next.metrics.as_ref().unwrap();
    assert_eq!(next.samples, 299);
    assert!(next.overall_rmse < 1e-9, "{next}");
    assert!(next.overall_d1 > 0.999_999, "{next}");
    // The free runs reproduce the simulation too (the same inputs, the same integrator).
    let h = e.horizon.metrics.as_ref().unwrap();
    assert_eq!(e.horizon.runs, 300 - 30);
    assert_eq!(h.samples, 270 * 30);
    assert!(h.overall_rmse < 1e-8, "{h}");
    let w = e.whole_flight.metrics.as_ref().unwrap();
    assert!(w.overall_rmse < 1e-8 && w.overall_d1 > 0.999_99, "{w}");
    assert_eq!(e.logs[0].segments[0].diverged_at, None);
    // Derivatives: f vs the Savitzky-Golay estimate of a smooth trajectory, close but not exact.
    let d = e.one_step_derivative.metrics.as_ref().unwrap();
    assert_eq!(d.names, ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]);
    assert_eq!(d.samples, 300 - 8);
    assert!(d.d1[0] > 0.99 && d.d1[1] > 0.99 && d.overall_d1 > 0.8, "{d}");
}

#[test]
fn constant_velocity_model_on_constant_acceleration_log_gives_the_hand_computed_errors() {
    // The log: x = a t²/2, vx = a t, everything else 0; dt = 0.1 s, 50 samples.
    // The model: kinematic rows only, so vx is constant in prediction.
    let (a, dt, n, h) = (2.0, 0.1, 50usize, 5usize);
    let t: Vec<String> = (0..n).map(|k| format!("{:.1}", k as f64 * dt)).collect();
    let x: Vec<[f64; 12]> = (0..n)
        .map(|k| {
            let tk = k as f64 * dt;
            let mut s = [0.0; 12];
            s[0] = 0.5 * a * tk * tk;
            s[2] = FLYING; // airborne: evaluate leaves out horizon runs on the ground
            s[6] = a * tk;
            s
        })
        .collect();
    let log = log_from(&t, &x, &vec![[0.0; 4]; n], "accel.csv");
    let model = sindy("constant_velocity", &["1"], &[]);
    let options = EvaluateOptions {
        horizon: h,
        substeps: Some(1),
        ..Default::default()
    };
    let e = evaluate(&model, &[log], &options).unwrap();
    all_finite(&e);
    let tol = 1e-9;

    // 1a. Derivative: f_vx = 0 against a (Savitzky-Golay of a line is exact): vx RMSE = MAE = a,
    // d₁ = 0 (constant observation, inexact); the other five rows are 0 = 0, d₁ = 1.
    let d = e.one_step_derivative.metrics.as_ref().unwrap();
    assert!(close(d.rmse[0], a, tol) && close(d.mae[0], a, tol), "{d}");
    assert!(d.d1[0] < 1e-9, "{d}");
    assert!(d.rmse[1..].iter().all(|&r| r < 1e-9));
    assert!(close(d.overall_rmse, (a * a / 6.0).sqrt(), tol));
    assert!(close(d.overall_mae, a / 6.0, tol));
    assert!(close(d.overall_d1, 5.0 / 6.0, tol));

    // 1b. Next sample: x error −a dt²/2, vx error −a dt, at every sample.
    let next = e.one_step_next.metrics.as_ref().unwrap();
    assert_eq!(next.samples, n - 1);
    assert!(close(next.rmse[0], 0.5 * a * dt * dt, tol), "{next}");
    assert!(close(next.rmse[6], a * dt, tol), "{next}");
    assert!(close(
        next.overall_rmse,
        ((0.25 * a * a * dt.powi(4) + a * a * dt * dt) / 12.0).sqrt(),
        tol
    ));

    // 2. Horizon: step j has x error a (j dt)²/2 and vx error a j dt.
    assert_eq!(e.horizon.runs, n - h);
    let hm = e.horizon.metrics.as_ref().unwrap();
    assert_eq!(hm.samples, (n - h) * h);
    let hf = h as f64;
    let vx_rmse = a * dt * ((hf + 1.0) * (2.0 * hf + 1.0) / 6.0).sqrt();
    let x_rmse = 0.5 * a * dt * dt * ((1..=h).map(|j| (j * j * j * j) as f64).sum::<f64>() / hf).sqrt();
    assert!(close(hm.rmse[6], vx_rmse, tol), "{hm}");
    assert!(close(hm.rmse[0], x_rmse, tol), "{hm}");
    let end = e.horizon.end.as_ref().unwrap();
    assert_eq!(end.samples, n - h);
    assert!(close(end.rmse[6], a * hf * dt, tol));
    assert!(close(end.rmse[0], 0.5 * a * (hf * dt).powi(2), tol));
    for (j, r) in e.horizon.rmse_by_step.iter().enumerate() {
        let jt = (j + 1) as f64 * dt;
        let expect = (((0.5 * a * jt * jt).powi(2) + (a * jt).powi(2)) / 12.0).sqrt();
        assert!(close(r.unwrap(), expect, tol), "step {}: {r:?} vs {expect}", j + 1);
    }

    // 3. Whole flight from rest: the prediction stays at 0; errors a t_k²/2 and a t_k, k = 1..n−1.
    let w = e.whole_flight.metrics.as_ref().unwrap();
    let m = (n - 1) as f64;
    let vx_rmse = a * dt * ((1..n).map(|k| (k * k) as f64).sum::<f64>() / m).sqrt();
    let vx_mae = a * dt * (1..n).map(|k| k as f64).sum::<f64>() / m;
    assert!(close(w.rmse[6], vx_rmse, tol) && close(w.mae[6], vx_mae, tol), "{w}");
    // d₁ for vx: P = 0 everywhere, so Σ|P − Ō| = (n − 1) Ō and the index is
    // 1 − Σ O / ((n − 1) Ō + Σ |O − Ō|).
    let obs: Vec<f64> = (1..n).map(|k| a * k as f64 * dt).collect();
    let mean = obs.iter().sum::<f64>() / m;
    let d1 = 1.0 - obs.iter().sum::<f64>() / (m * mean + obs.iter().map(|o| (o - mean).abs()).sum::<f64>());
    assert!(close(w.d1[6], d1, 1e-9), "{} vs {d1}", w.d1[6]);
}

#[test]
fn divergence_stops_the_run_and_keeps_finite_metrics() {
    // The log flies at a constant 1 m/s; the model has v̇x = vx², which blows up at t = 1 s.
    let (dt, n) = (0.05, 200usize);
    let t: Vec<String> = (0..n).map(|k| format!("{:.2}", k as f64 * dt)).collect();
    let x: Vec<[f64; 12]> = (0..n)
        .map(|k| {
            let mut s = [0.0; 12];
            s[0] = k as f64 * dt;
            s[2] = FLYING;
            s[6] = 1.0;
            s
        })
        .collect();
    let log = log_from(&t, &x, &vec![[0.0; 4]; n], "cruise.csv");
    let model = sindy("unstable", &["vx^2"], &[("vx", "vx^2", 1.0)]);
    let options = EvaluateOptions {
        horizon: 30,
        substeps: Some(2),
        ..Default::default()
    };
    let e = evaluate(&model, std::slice::from_ref(&log), &options).unwrap();
    all_finite(&e);
    let seg = &e.logs[0].segments[0];
    let k = seg.diverged_at.expect("the whole-flight run diverges");
    // vx = 1/(1 − t) passes 1e6 just before t = 1 s; RK4 with h = 0.025 lags a little.
    assert!((15..=40).contains(&k), "diverged at {k}");
    assert_eq!(seg.diverged_t, Some(log.segments[0].t[k]));
    assert_eq!(e.whole_flight.diverged, 1);
    let w = e.whole_flight.metrics.as_ref().unwrap();
    assert_eq!(w.samples, k - 1);
    // Every horizon run (1.5 s) diverges; their finite parts are still scored.
    assert_eq!(e.horizon.diverged, e.horizon.runs);
    assert!(e.horizon.end.is_none());
    assert!(e.horizon.metrics.as_ref().unwrap().samples > 0);
    assert!(e.horizon.rmse_by_step.last().unwrap().is_none());
    // JSON: no NaN, nulls where nothing could be scored.
    let json = serde_json::to_value(&e).unwrap();
    assert!(json["horizon"]["end"].is_null());
    assert_eq!(json["logs"][0]["segments"][0]["diverged_at"], k);
    let text = e.to_string();
    assert!(text.contains("diverged at sample"), "{text}");
}

#[test]
fn yaw_errors_are_wrapped() {
    assert!((wrap_angle(2.0 * std::f64::consts::PI + 0.1) - 0.1).abs() < 1e-12);
    assert!((wrap_angle(-2.0 * std::f64::consts::PI - 0.1) + 0.1).abs() < 1e-12);
    // The log keeps yaw at 0 while yaw_rate is 2π per sample (the heading repeats every
    // sample); a model with the kinematic row yaw' = yaw_rate turns by exactly 2π per sample,
    // so its yaw error is 2πk, which wraps to 0.
    let (dt, n) = (0.1, 30usize);
    let t: Vec<String> = (0..n).map(|k| format!("{:.1}", k as f64 * dt)).collect();
    let rate = 2.0 * std::f64::consts::PI / dt;
    let x: Vec<[f64; 12]> = (0..n)
        .map(|_| {
            let mut s = [0.0; 12];
            s[2] = FLYING;
            s[11] = rate;
            s
        })
        .collect();
    let log = log_from(&t, &x, &vec![[0.0; 4]; n], "spin.csv");
    let model = sindy("constant_rate", &["1"], &[]);
    let options = EvaluateOptions {
        horizon: 3,
        substeps: Some(1),
        ..Default::default()
    };
    let e = evaluate(&model, &[log], &options).unwrap();
    let next = e.one_step_next.metrics.as_ref().unwrap();
    assert!(next.rmse[5] < 1e-9, "yaw RMSE {}", next.rmse[5]);
    let w = e.whole_flight.metrics.as_ref().unwrap();
    assert!(w.rmse[5] < 1e-6, "yaw RMSE {}", w.rmse[5]);
    // Unwrapped, the error would grow to 2π (n − 1) ≈ 182 rad.
    assert!(w.mae[5] < 1e-6, "yaw MAE {}", w.mae[5]);
}

/// Horizon runs that touch the ground (z ≤ 0.02 m) are left out and counted, as diagnose does; a
/// log on the ground throughout is an error naming it.
#[test]
fn horizon_runs_on_the_ground_are_left_out() {
    let (dt, n, h) = (0.1, 40usize, 5usize);
    let t: Vec<String> = (0..n).map(|k| format!("{:.1}", k as f64 * dt)).collect();
    // On the ground for samples 0..10 (z = 0, then 0.02: still ground), then 1 m up.
    let x: Vec<[f64; 12]> = (0..n)
        .map(|k| {
            let mut s = [0.0; 12];
            s[2] = match k {
                0..=9 => 0.0,
                10 => 0.02,
                _ => 1.0,
            };
            s
        })
        .collect();
    let model = sindy("still", &["1"], &[]);
    let options = EvaluateOptions {
        horizon: h,
        substeps: Some(1),
        ..Default::default()
    };
    let e = evaluate(&model, &[log_from(&t, &x, &vec![[0.0; 4]; n], "takeoff.csv")], &options).unwrap();
    // Runs start at k = 0..n−h−1 and cover k..k+h: those with k ≤ 10 touch the ground.
    assert_eq!(e.horizon.on_ground, 11);
    assert_eq!(e.horizon.runs, n - h - 11);
    assert_eq!(e.horizon.metrics.as_ref().unwrap().samples, (n - h - 11) * h);
    let grounded = vec![[0.0; 12]; n];
    let err = evaluate(
        &model,
        &[log_from(&t, &grounded, &vec![[0.0; 4]; n], "parked.csv")],
        &options,
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(text.contains("parked.csv") && text.contains("ground"), "{text}");
}

#[test]
fn bad_options_are_errors() {
    let model = load(&repo().join("models/pd_hover.json")).unwrap();
    let log = simulated_pd_log(&model, 1, 20);
    let zero = EvaluateOptions {
        horizon: 0,
        ..Default::default()
    };
    assert!(evaluate(&model, std::slice::from_ref(&log), &zero).is_err());
    let zero = EvaluateOptions {
        substeps: Some(0),
        ..Default::default()
    };
    assert!(evaluate(&model, std::slice::from_ref(&log), &zero).is_err());
    assert!(evaluate(&model, &[], &EvaluateOptions::default()).is_err());
}

#[test]
fn plots_are_svg_with_the_state_names() {
    let model = load(&repo().join("models/pd_hover.json")).unwrap();
    let log = simulated_pd_log(&model, 2, 120);
    let dir = tempfile::tempdir().unwrap();
    let options = EvaluateOptions {
        horizon: 30,
        substeps: Some(2),
        ..Default::default()
    };
    let files = plot_states(&model, &log, &options, dir.path()).unwrap();
    assert_eq!(files.len(), 2);
    assert!(files[0].ends_with("simulated_free_run.svg") && files[1].ends_with("simulated_horizon.svg"));
    for f in &files {
        let svg = std::fs::read_to_string(f).unwrap();
        assert!(svg.starts_with("<svg") || svg.contains("<svg"), "{}", f.display());
        for name in model.states.iter() {
            assert!(svg.contains(&format!("\n{name} (")), "{} lacks {name}", f.display());
        }
    }
}

fn m100() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/flights/m100");
    if dir.join("m100_run7.csv").is_file() {
        Some(dir)
    } else {
        shared::skip(&dir.join("m100_run7.csv"));
        None
    }
}

fn row(label: &str, m: &Option<Metrics>) {
    match m {
        Some(m) => println!(
            "  {label:<28} RMSE {:>10.4}  MAE {:>10.4}  d1 {:.4}  (n = {})",
            m.overall_rmse, m.overall_mae, m.overall_d1, m.samples
        ),
        None => println!("  {label:<28} no finite predictions"),
    }
}

fn velocities(m: &Option<Metrics>) -> String {
    m.as_ref()
        .map(|m| format!("vx {:.4} vy {:.4} vz {:.4}", m.rmse[6], m.rmse[7], m.rmse[8]))
        .unwrap_or_default()
}

#[test]
fn m100_run7() {
    let Some(dir) = m100() else { return };
    let log = read_log(&dir.join("m100_run7.csv")).unwrap();
    let plots = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("evaluate");
    std::fs::create_dir_all(&plots).unwrap();
    for name in ["sindy_m100", "pd_hover"] {
        let model = load(&repo().join(format!("models/{name}.json"))).unwrap();
        let options = EvaluateOptions::default();
        let e = evaluate(&model, std::slice::from_ref(&log), &options).unwrap();
        all_finite(&e);
        let seg = &e.logs[0].segments[0];
        println!(
            "{name} on m100_run7.csv (dt {:.6} s, {} RK4 substeps, horizon {}):",
            seg.dt, seg.substeps, e.horizon.horizon
        );
        row("one-step derivative", &e.one_step_derivative.metrics);
        row("one-step next sample", &e.one_step_next.metrics);
        row("horizon free run (pooled)", &e.horizon.metrics);
        row("horizon free run (end)", &e.horizon.end);
        row("whole-flight free run", &e.whole_flight.metrics);
        println!(
            "  horizon runs {} (diverged {}), whole flight diverged at {:?}",
            e.horizon.runs, e.horizon.diverged, seg.diverged_at
        );
        println!("  horizon pooled velocity RMSE: {}", velocities(&e.horizon.metrics));
        println!("  horizon end velocity RMSE:    {}", velocities(&e.horizon.end));
        println!(
            "  whole-flight velocity RMSE:   {}",
            velocities(&e.whole_flight.metrics)
        );
        if let Some(d) = &e.one_step_derivative.metrics {
            println!(
                "  derivative RMSE per row: {:?}",
                d.rmse.iter().map(|r| (r * 1e4).round() / 1e4).collect::<Vec<_>>()
            );
        }
        let out = plots.join(name);
        std::fs::create_dir_all(&out).unwrap();
        let files = plot_states(&model, &log, &options, &out).unwrap();
        println!(
            "  plots: {}",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        std::fs::write(out.join("evaluation.json"), serde_json::to_string_pretty(&e).unwrap()).unwrap();
        assert_eq!(e.one_step_next.metrics.as_ref().unwrap().samples, 1800);
        assert_eq!(e.horizon.runs, 1801 - 30);
    }
}

/// `horizon_score` (the delay refinement's score) is `evaluate`'s horizon figures, the same numbers
/// at stride 1, and every `stride`-th run otherwise (here on a flight whose runs all diverge at a
/// known rate, and on one model that tracks a climbing, turning log).
#[test]
fn horizon_score_is_evaluates_horizon() {
    use uavgen::evaluate::horizon_score;
    let (dt, n) = (0.05, 200usize);
    let t: Vec<String> = (0..n).map(|k| format!("{:.2}", k as f64 * dt)).collect();
    let x: Vec<[f64; 12]> = (0..n)
        .map(|k| {
            let tk = k as f64 * dt;
            let mut s = [0.0; 12];
            s[0] = tk;
            s[2] = FLYING + 0.3 * tk;
            s[5] = 0.2 * tk;
            s[6] = 1.0 + 0.1 * tk.sin();
            s[8] = 0.3;
            s[11] = 0.2;
            s
        })
        .collect();
    let u: Vec<[f64; 4]> = (0..n).map(|k| [0.3, 0.0, 0.0, 0.1 * (k % 7) as f64]).collect();
    let log = log_from(&t, &x, &u, "turn.csv");
    let models = [
        sindy("unstable", &["vx^2"], &[("vx", "vx^2", 1.0)]),
        sindy(
            "loops",
            &["vx", "vz", "u_vz", "yaw_rate", "u_yaw_rate"],
            &[
                ("vx", "vx", -0.2),
                ("vz", "vz", -2.0),
                ("vz", "u_vz", 2.0),
                ("yaw_rate", "yaw_rate", -3.0),
                ("yaw_rate", "u_yaw_rate", 3.0),
            ],
        ),
    ];
    let options = EvaluateOptions {
        horizon: 30,
        ..Default::default()
    };
    for model in &models {
        let e = evaluate(model, std::slice::from_ref(&log), &options).unwrap();
        let s = horizon_score(model, std::slice::from_ref(&log), &options, 1).unwrap();
        assert_eq!(s.runs, e.horizon.runs, "{}", model.name);
        assert_eq!(s.diverged, e.horizon.diverged, "{}", model.name);
        assert_eq!(
            s.overall_rmse.map(f64::to_bits),
            e.horizon.metrics.as_ref().map(|m| m.overall_rmse.to_bits()),
            "{}",
            model.name
        );
        let every3 = horizon_score(model, std::slice::from_ref(&log), &options, 3).unwrap();
        assert_eq!(every3.runs, (n - 30).div_ceil(3), "{}", model.name);
        assert!(every3.overall_rmse.unwrap().is_finite());
    }
    let short = log_from(&t[..10], &x[..10], &u[..10], "short.csv");
    assert!(horizon_score(&models[1], &[short], &options, 1).is_err());
}
