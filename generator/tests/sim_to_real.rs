//! The sim-to-real protocol of docs/diagnosis.md on a reduced set: a SINDy base model identified
//! (with identify's defaults, as the shipped sindy_m100, [`SETTINGS`]) from a 120 s flight of the nominal
//! simulator, diagnosed against the real M100
//! logs (runs 1–5, run 7 held out). Checks the acceptance of issue 13:
//!
//! - the verdict names the command channels' response: `loop_mismatch`, with the corrected model's
//!   roll and pitch answering in 0.10–0.30 s (63 % of a step);
//! - the corrected model closes at least half of the sim-to-real gap over the horizon,
//!   (B − C)/(B − R) ≥ 0.5, R the model identified on runs 1–5 with the same settings;
//! - `uavgen evaluate` of corrected.json on run 7 reproduces the reported figures to 4
//!   significant digits.
//!
//! Needs `../shared/flights/m100` (CI has it); without it the test says SKIPPED and returns.
//!
//! And the m100_like check of the same protocol (a nominal-plant model diagnosed against flights of
//! `plants/m100_like.json`, the delays and drag it must find), which needs no shared data.

mod common;
mod shared;

use common::{repo, uavgen};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The identification settings of the base model and of R: those of the shipped sindy_m100
/// (scripts/identify_m100.sh): identify's defaults (integral-form targets, input delays
/// estimated, stale rows interpolated, the default sweep with BIC, the ridge ladder).
const SETTINGS: [&str; 0] = [];

fn m100() -> Option<PathBuf> {
    let dir = repo().join("../shared/flights/m100");
    if dir.join("m100_run7.csv").exists() {
        Some(dir)
    } else {
        shared::skip(&dir.join("m100_run7.csv"));
        None
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(args: &[&str]) -> String {
    let o = uavgen(args);
    assert!(
        o.status.success(),
        "uavgen {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn read(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Overall horizon RMSE of `model` on `log` by `uavgen evaluate` (default options).
fn horizon_rmse(model: &Path, log: &Path, json: &Path) -> f64 {
    ok(&[
        "evaluate",
        "--model",
        s(model),
        "--log",
        s(log),
        "--json",
        s(json),
        "--force",
    ]);
    read(json)["horizon"]["metrics"]["overall_rmse"].as_f64().unwrap()
}

fn same4(a: f64, b: f64) -> bool {
    (a - b).abs() <= 5e-5 * a.abs().max(b.abs())
}

#[test]
fn simulator_model_on_the_m100() {
    let Some(m100) = m100() else { return };
    let dir = tempfile_dir("sim_to_real");
    let nominal = dir.join("nominal.csv");
    ok(&[
        "simulate",
        "--plant",
        "plants/nominal.json",
        "--profile",
        "excite",
        "--duration",
        "120",
        "--seed",
        "11",
        "--out",
        s(&nominal),
        "--force",
    ]);
    let base = dir.join("base.json");
    ok(&[
        "identify",
        "--method",
        "sindy",
        "--log",
        s(&nominal),
        "--out",
        s(&base),
        "--force",
    ]);
    let runs: Vec<PathBuf> = (1..=5).map(|r| m100.join(format!("m100_run{r}.csv"))).collect();
    let run7 = m100.join("m100_run7.csv");
    let out = dir.join("diag");
    let mut args = vec![
        "diagnose",
        "--model",
        s(&base),
        "--holdout",
        s(&run7),
        "--out",
        s(&out),
        "--force",
    ];
    for r in &runs {
        args.extend(["--log", s(r)]);
    }
    ok(&args);
    let report = read(&out.join("report.json"));
    let verdict: Vec<&str> = report["verdict"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(verdict.contains(&"loop_mismatch"), "verdict {verdict:?}");
    for input in ["u_roll", "u_pitch"] {
        let t = report["response_times"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["input"] == input)
            .unwrap();
        let t63 = t["corrected"]["t63"].as_f64().unwrap();
        assert!((0.10..=0.30).contains(&t63), "{input}: {t}");
    }
    // B, C as reported; evaluate reproduces them on run 7.
    let b = report["shrink"]["before"]["horizon"]["overall_rmse"].as_f64().unwrap();
    let c = report["shrink"]["after"]["horizon"]["overall_rmse"].as_f64().unwrap();
    let b_eval = horizon_rmse(&base, &run7, &dir.join("eval_base.json"));
    let c_eval = horizon_rmse(&out.join("corrected.json"), &run7, &dir.join("eval_corrected.json"));
    assert!(same4(b, b_eval), "before: report {b}, evaluate {b_eval}");
    assert!(same4(c, c_eval), "after: report {c}, evaluate {c_eval}");
    // R: identified on runs 1–5 with the same settings.
    let r_model = dir.join("r.json");
    let mut args = vec!["identify", "--method", "sindy", "--out", s(&r_model), "--force"];
    args.extend(SETTINGS);
    for r in &runs {
        args.extend(["--log", s(r)]);
    }
    ok(&args);
    let r = horizon_rmse(&r_model, &run7, &dir.join("eval_r.json"));
    let closed = (b - c) / (b - r);
    eprintln!("sim-to-real: B {b:.4}, C {c:.4}, R {r:.4}: (B − C)/(B − R) = {closed:.2}");
    assert!(
        b > r,
        "the simulator's model must be worse than the aircraft's own (B {b}, R {r})"
    );
    assert!(closed >= 0.5, "(B − C)/(B − R) = {closed:.2}");
}

/// `plants/m100_like.json` (the nominal plant with the delays, drag, noise and stale rows measured
/// on the M100) diagnosed with a base model identified on nominal-plant flights, as
/// scripts/sim_to_real.sh: every channel's fitted delay (plus lag) within 20 % of the plant file's,
/// and the drag named within 30 %. Needs no shared data.
#[test]
fn nominal_model_on_the_m100_like_plant() {
    let dir = tempfile_dir("sim_to_real_m100_like");
    let log = |plant: &str, duration: &str, seed: &str, name: &str| {
        let path = dir.join(name);
        ok(&[
            "simulate",
            "--plant",
            plant,
            "--profile",
            "excite",
            "--duration",
            duration,
            "--seed",
            seed,
            "--out",
            s(&path),
            "--force",
        ]);
        path
    };
    let nominal = log("plants/nominal.json", "180", "11", "nominal.csv");
    let train = log("plants/m100_like.json", "180", "21", "train.csv");
    let test = log("plants/m100_like.json", "90", "22", "test.csv");
    let base = dir.join("base.json");
    ok(&[
        "identify",
        "--method",
        "sindy",
        "--log",
        s(&nominal),
        "--out",
        s(&base),
        "--force",
    ]);
    let out = dir.join("diag");
    ok(&[
        "diagnose",
        "--model",
        s(&base),
        "--log",
        s(&train),
        "--holdout",
        s(&test),
        "--out",
        s(&out),
        "--force",
    ]);
    let corrected = read(&out.join("corrected.json"));
    let c = &corrected["corrections"];
    let plant = read(&repo().join("plants/m100_like.json"));
    let truth = plant["effects"]["latency"]["per_channel"].as_array().unwrap();
    for (j, input) in ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"].iter().enumerate() {
        let d = c["latency"][input].as_f64().unwrap_or(0.0) + c["actuator_lag"][input].as_f64().unwrap_or(0.0);
        let t = truth[j].as_f64().unwrap();
        eprintln!("{input}: delay + lag {d:.3} s against the plant's {t} s");
        assert!(
            (d / t - 1.0).abs() <= 0.2,
            "{input}: {d:.3} s against {t} s; corrections {c}"
        );
    }
    // The report's before/after horizon figures are what `uavgen evaluate` gives for the files
    // (delays in whole samples, runs on the ground left out by both).
    let report = read(&out.join("report.json"));
    let b = report["shrink"]["before"]["horizon"]["overall_rmse"].as_f64().unwrap();
    let a = report["shrink"]["after"]["horizon"]["overall_rmse"].as_f64().unwrap();
    let b_eval = horizon_rmse(&base, &test, &dir.join("eval_base.json"));
    let a_eval = horizon_rmse(&out.join("corrected.json"), &test, &dir.join("eval_corrected.json"));
    assert!(same4(b, b_eval), "before: report {b}, evaluate {b_eval}");
    assert!(same4(a, a_eval), "after: report {a}, evaluate {a_eval}");
    let drag = c["linear_drag"]["xy"].as_f64().unwrap_or(0.0);
    for t in plant["effects"]["linear_drag"]["coefficients"].as_array().unwrap()[..2].iter() {
        let t = t.as_f64().unwrap();
        assert!(
            (drag / t - 1.0).abs() <= 0.3,
            "drag {drag} against {t}; corrections {c}"
        );
    }
}

fn tempfile_dir(name: &str) -> PathBuf {
    let dir = repo().join("target/test-tmp").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
