//! The aircraft bed in CI (issue 27; docs/identification.md#results-per-vehicle-class-issue-27): each vehicle
//! class on reduced data — default `identify --method sindy` and `--method pd` on a short training
//! flight, `evaluate` on a held-out flight at horizons of 0.3 s and 1 s against the predict-no-change
//! baseline `evaluate` reports. The full figures come from scripts/aircraft_bed_results.py.
//!
//! Classes: nano (plants/nano.json, 100 Hz), M100 class (plants/m100_like.json, 30 Hz), PX4 class
//! (plants/px4_quad.json, 50 Hz) and RotorPy's Crazyflie (tests/data/rotorpy_cf/, written by
//! scripts/rotorpy_crazyflie.py; no code of ours simulated it).
//!
//! The thresholds are issue 27's acceptance (≥ 20 % below predict-no-change, below another class's
//! model, no diverged run). The training flights mix heading-excited and heading-held segments; the
//! held-out flight is heading-held. `nano_heading_held_only_generalises_to_another_heading` trains on
//! heading-held flights only (the nano case) and holds out a flight at another heading:
//! SINDy's vx/vy rows are then fitted in the heading frame (docs/identification.md, "Heading frame").

mod common;

use common::{repo, stderr, uavgen};
use std::path::{Path, PathBuf};
use uavgen::evaluate::{evaluate, EvaluateOptions};
use uavgen::logs::parse_log;

/// The ratio model / predict-no-change each identified model must stay below at both horizons
/// (issue 27: ≥ 20 % below). Today's largest: 0.31 (nano PD, heading held only, at 0.3 s).
const MAX_RATIO_TO_NO_CHANGE: f64 = 0.8;
/// The largest fraction of diverged horizon runs allowed per model and horizon (issue 27: none).
const MAX_DIVERGED_FRACTION: f64 = 0.0;
/// Each identified model's horizon RMSE must stay below this factor times that of a model of another
/// class (the shipped models/sindy_m100.json; not checked on the M100 class). Today's largest
/// ratio: 0.79 (nano PD, heading held only, at 1 s).
const MAX_RATIO_TO_OTHER_CLASS: f64 = 1.0;

/// Overall horizon RMSE, its no-change baseline and the diverged runs of `model` on `log`.
fn horizon_figures(model: &Path, log: &Path, horizon: usize, json: &Path) -> (f64, f64, usize, usize) {
    let h = horizon.to_string();
    let o = uavgen(&[
        "evaluate",
        "--quiet",
        "--model",
        model.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
        "--horizon",
        &h,
        "--json",
        json.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    let hz = &v["horizon"];
    (
        hz["metrics"]["overall_rmse"].as_f64().unwrap(),
        hz["no_change"]["overall_rmse"].as_f64().unwrap(),
        hz["diverged"].as_u64().unwrap() as usize,
        hz["runs"].as_u64().unwrap() as usize,
    )
}

fn simulate(plant: &str, profile: &str, seconds: &str, seed: &str, out: &Path) {
    let plant = repo().join(plant);
    let o = uavgen(&[
        "simulate",
        "--quiet",
        "--plant",
        plant.to_str().unwrap(),
        "--profile",
        profile,
        "--duration",
        seconds,
        "--seed",
        seed,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Identify both methods with defaults on the `train` logs, evaluate on `test` at 0.3 s and 1 s (`rate_hz`
/// samples per second) and check the figures against predict-no-change.
fn check_class(class: &str, train: &[PathBuf], test: &Path, rate_hz: f64, dir: &Path) {
    let horizons = [(0.3 * rate_hz).round() as usize, rate_hz.round() as usize];
    for method in ["sindy", "pd"] {
        let model = dir.join(format!("{method}.json"));
        let mut args = vec![
            "identify",
            "--quiet",
            "--method",
            method,
            "--out",
            model.to_str().unwrap(),
        ];
        for t in train {
            args.extend(["--log", t.to_str().unwrap()]);
        }
        let o = uavgen(&args);
        assert!(o.status.success(), "{class} {method}: identify failed: {}", stderr(&o));
        for (h, seconds) in horizons.iter().zip(["0.3 s", "1 s"]) {
            let (rmse, no_change, diverged, runs) = horizon_figures(&model, test, *h, &dir.join("eval.json"));
            eprintln!(
                "{class} {method} {seconds} ({h} samples): RMSE {rmse:.4}, predict-no-change {no_change:.4} \
                 (ratio {:.2}), {diverged} of {runs} runs diverged",
                rmse / no_change
            );
            assert!(
                rmse < MAX_RATIO_TO_NO_CHANGE * no_change,
                "{class} {method} at {seconds}: horizon RMSE {rmse:.4} not below {MAX_RATIO_TO_NO_CHANGE} × \
                 predict-no-change {no_change:.4}"
            );
            assert!(
                diverged as f64 <= MAX_DIVERGED_FRACTION * runs as f64,
                "{class} {method} at {seconds}: {diverged} of {runs} runs diverged"
            );
            if class != "m100" {
                let other = repo().join("models/sindy_m100.json");
                let (other_rmse, ..) = horizon_figures(&other, test, *h, &dir.join("eval_other.json"));
                eprintln!("  against sindy_m100 (another class): {other_rmse:.4}");
                assert!(
                    rmse < MAX_RATIO_TO_OTHER_CLASS * other_rmse,
                    "{class} {method} at {seconds}: horizon RMSE {rmse:.4} not below {MAX_RATIO_TO_OTHER_CLASS} × \
                     another class's model (sindy_m100) {other_rmse:.4}"
                );
            }
        }
    }
}

/// A bed class of our own plants: training `excite` (heading excited) and held-out
/// `excite-hold-heading` (the heading held: the nano flights).
fn own_class(class: &str, plant: &str, rate_hz: f64, train_s: &str, test_s: &str, seed: u64) {
    let dir = tempfile::tempdir().unwrap();
    let train = dir.path().join("train.csv");
    let test = dir.path().join("test.csv");
    simulate(plant, "excite,excite-hold-heading", train_s, &seed.to_string(), &train);
    simulate(plant, "excite-hold-heading", test_s, &(seed + 1).to_string(), &test);
    check_class(class, &[train], &test, rate_hz, dir.path());
}

#[test]
fn nano_100_hz_beats_predict_no_change() {
    own_class("nano", "plants/nano.json", 100.0, "12,12", "10", 1101);
}

/// The nano case: training flights with the heading held (u_yaw_rate silent) only, the
/// held-out flight held at another heading. Before the heading-frame fit SINDy's 1 s horizon RMSE
/// was above the other class's model (0.140 against 0.113 on the bed's 60 s flights).
#[test]
fn nano_heading_held_only_generalises_to_another_heading() {
    let dir = tempfile::tempdir().unwrap();
    let train = dir.path().join("train.csv");
    let test = dir.path().join("test.csv");
    simulate("plants/nano.json", "excite-hold-heading", "20", "1201", &train);
    simulate("plants/nano.json", "excite-hold-heading", "10", "1204", &test);
    let heading = |p: &Path| {
        let log = parse_log(&std::fs::read_to_string(p).unwrap(), "log").unwrap();
        let x = &log.segments[0].x;
        x[x.len() / 2][5]
    };
    let apart = uavgen::evaluate::wrap_angle(heading(&train) - heading(&test)).abs();
    assert!(
        apart > 0.5,
        "the held-out heading is only {apart} rad from the training one"
    );
    check_class("nano", &[train], &test, 100.0, dir.path());
}

#[test]
fn m100_class_30_hz_beats_predict_no_change() {
    own_class("m100", "plants/m100_like.json", 30.0, "40,40", "30", 2101);
}

#[test]
fn px4_class_50_hz_beats_predict_no_change() {
    own_class("px4", "plants/px4_quad.json", 50.0, "25,25", "20", 3101);
}

#[test]
fn rotorpy_crazyflie_beats_predict_no_change() {
    // The committed RotorPy logs (scripts/rotorpy_crazyflie.py; tests/data/rotorpy_cf/rotorpy_cf_truth.json).
    let data = repo().join("tests/data/rotorpy_cf");
    let dir = tempfile::tempdir().unwrap();
    // Trained on both training flights (heading excited and held).
    let train = [data.join("train_excite.csv"), data.join("train_hold.csv")];
    check_class("rotorpy_cf", &train, &data.join("test_hold.csv"), 100.0, dir.path());
}

/// The committed RotorPy logs are what scripts/rotorpy_crazyflie.py says: 100 Hz, the durations and
/// seeds of the truth file, the heading held on the `hold` flights.
#[test]
fn rotorpy_crazyflie_logs_match_their_truth_file() {
    let data = repo().join("tests/data/rotorpy_cf");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("rotorpy_cf_truth.json")).unwrap()).unwrap();
    assert_eq!(truth["rate_hz"].as_f64(), Some(100.0));
    for name in ["train_excite", "train_hold", "test_excite", "test_hold"] {
        let f = &truth["files"][name];
        let log = parse_log(
            &std::fs::read_to_string(data.join(format!("{name}.csv"))).unwrap(),
            name,
        )
        .unwrap();
        let seg = &log.segments[0];
        assert_eq!(log.segments.len(), 1, "{name}");
        assert_eq!(seg.len() as u64, f["rows"].as_u64().unwrap(), "{name}");
        let dt = (seg.t[seg.len() - 1] - seg.t[0]) / (seg.len() - 1) as f64;
        assert!((dt - 0.01).abs() < 1e-9, "{name}: dt {dt}");
        let yaw: Vec<f64> = seg.x.iter().map(|x| x[5]).collect();
        let span = yaw
            .iter()
            .map(|y| uavgen::evaluate::wrap_angle(y - yaw[0]).abs())
            .fold(0.0, f64::max);
        let u_yaw_rms = (seg.u.iter().map(|u| u[3] * u[3]).sum::<f64>() / seg.len() as f64).sqrt();
        if name.ends_with("hold") {
            assert!(span < 0.2, "{name}: heading moved {span} rad");
            assert!(u_yaw_rms < 0.05, "{name}: u_yaw_rate RMS {u_yaw_rms}");
        } else {
            assert!(span > 0.5, "{name}: heading moved only {span} rad");
            assert!(u_yaw_rms > 0.1, "{name}: u_yaw_rate RMS {u_yaw_rms}");
        }
    }
}

/// Hand-checked: predict-no-change on a log where only x moves (0.1 m per sample). Over a horizon
/// of 2 every run has errors 0.1 and 0.2 m in x and none elsewhere: pooled over 12 states the
/// overall RMSE is √((0.1² + 0.2²) / 2 / 12) = 0.045644.
#[test]
fn predict_no_change_baseline_by_hand() {
    let mut csv =
        String::from("t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate\n");
    for k in 0..6 {
        csv.push_str(&format!(
            "{},{},0,5,0,0,0.3,3,0,0,0,0,0,0,0,0,0\n",
            k as f64 * 0.1,
            k as f64 * 0.1
        ));
    }
    let log = parse_log(&csv, "line.csv").unwrap();
    let model = uavgen::load(&repo().join("models/pd_hover.json")).unwrap();
    let options = EvaluateOptions {
        horizon: 2,
        ..EvaluateOptions::default()
    };
    let e = evaluate(&model, &[log], &options).unwrap();
    assert_eq!(e.horizon.runs, 4);
    let nc = e.horizon.no_change.as_ref().unwrap();
    assert!(
        (nc.overall_rmse - (0.05f64 / 2.0 / 12.0).sqrt()).abs() < 1e-12,
        "{}",
        nc.overall_rmse
    );
    assert!((nc.rmse[0] - (0.05f64 / 2.0).sqrt()).abs() < 1e-12);
    assert!(nc.rmse[1..].iter().all(|r| *r == 0.0), "{:?}", nc.rmse);
    assert_eq!(nc.samples, 8);
}
