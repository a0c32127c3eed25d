//! `uavgen track` as a user runs it: the generated solver through the runtime harness and the
//! generic solver fly the paper's trajectories on the simulator; bad input is refused.

use std::fs;

mod common;

use common::{stderr, uavgen};

fn report(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

#[test]
fn generated_solver_tracks_the_circle_through_the_runtime() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("circle");
    let work = tmp.path().join("work");
    let o = uavgen(&[
        "track",
        "--model",
        "models/sindy_m100.json",
        "--plant",
        "plants/nominal.json",
        "--trajectory",
        "circle",
        "--duration",
        "12",
        "--out",
        out.to_str().unwrap(),
        "--work-dir",
        work.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "report.md",
        "report.json",
        "samples.csv",
        "path_3d.svg",
        "position_errors.svg",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let r = report(&out);
    assert_eq!(r["samples"], 360);
    assert_eq!(r["inputs_out_of_bounds"], 0);
    assert!(r["solver"].as_str().unwrap().contains("uavgen-runtime"));
    // From (3, 3, 5) onto a circle of radius 5 through (5, 0, 6): after the approach, the true
    // position stays within decimetres of the reference.
    let late = r["overall_second_half"]["rmse"].as_f64().unwrap();
    assert!(late < 0.3, "second-half RMSE {late}");
    assert!(r["statuses"]["Solved"].as_u64().unwrap() > 340, "{}", r["statuses"]);
    let csv = fs::read_to_string(out.join("samples.csv")).unwrap();
    assert_eq!(csv.lines().count(), 361);
}

#[test]
fn generic_solver_flies_all_three_trajectories() {
    let tmp = tempfile::tempdir().unwrap();
    let generic = tmp.path().join("generic");
    let o = uavgen(&[
        "track",
        "--model",
        "models/pd_m100.json",
        "--plant",
        "plants/nominal.json",
        "--trajectory",
        "circle,sinusoid,spiral",
        "--duration",
        "4",
        "--generic",
        "--out",
        generic.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(generic.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary.as_array().unwrap().len(), 3);
    for name in ["circle", "sinusoid", "spiral"] {
        let r = report(&generic.join(name));
        assert_eq!(r["inputs_out_of_bounds"], 0, "{name}");
        assert!(r["overall"]["rmse"].as_f64().unwrap().is_finite());
        assert!(r["solver"].as_str().unwrap().contains("generic"));
    }
}

/// The inputs column block (u_vz..u_yaw_rate) of samples.csv.
fn inputs(dir: &std::path::Path) -> Vec<Vec<f64>> {
    fs::read_to_string(dir.join("samples.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(10).take(4).map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn generated_and_generic_solvers_fly_the_same_closed_loop() {
    // Noise-free nominal plant: both solvers see the same states as long as they agree, and the
    // generated solver matches the generic one to ~1e-11 per RTI step (tests/generated_vs_generic.rs).
    let tmp = tempfile::tempdir().unwrap();
    let mut runs = Vec::new();
    for generic in [false, true] {
        let out = tmp.path().join(if generic { "generic" } else { "generated" });
        let work = tmp.path().join("work");
        let mut args = vec![
            "track",
            "--model",
            "models/sindy_m100.json",
            "--plant",
            "plants/nominal.json",
            "--trajectory",
            "sinusoid",
            "--duration",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--work-dir",
            work.to_str().unwrap(),
        ];
        if generic {
            args.push("--generic");
        }
        let o = uavgen(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        runs.push(inputs(&out));
    }
    assert_eq!(runs[0].len(), 120);
    let worst = runs[0]
        .iter()
        .flatten()
        .zip(runs[1].iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    eprintln!("generated vs generic closed loop: max input difference {worst:e}");
    assert!(worst < 1e-6, "inputs differ by {worst}");
}

#[test]
fn bad_input_is_refused_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let bad_plant = tmp.path().join("bad.json");
    fs::write(&bad_plant, "{ not json").unwrap();
    let out = tmp.path().join("never");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "--model",
                "models/sindy_m100.json",
                "--plant",
                bad_plant.to_str().unwrap(),
            ],
            "bad.json",
        ),
        (
            vec!["--model", "models/missing.json", "--plant", "plants/nominal.json"],
            "missing.json",
        ),
        (
            vec![
                "--model",
                "models/sindy_m100.json",
                "--plant",
                "plants/nominal.json",
                "--duration",
                "0",
            ],
            "--duration",
        ),
    ];
    for (args, named) in cases {
        let mut full = vec![
            "track",
            "--trajectory",
            "circle",
            "--generic",
            "--out",
            out.to_str().unwrap(),
        ];
        full.extend(args);
        let o = uavgen(&full);
        assert!(!o.status.success());
        assert!(stderr(&o).contains(named), "{named}: {}", stderr(&o));
        assert!(!out.exists());
    }
    // An unknown trajectory is a usage error.
    let o = uavgen(&[
        "track",
        "--model",
        "models/sindy_m100.json",
        "--plant",
        "plants/nominal.json",
        "--trajectory",
        "square",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(!out.exists());
}

#[test]
fn models_identified_on_m100_like_track_every_trajectory_within_the_bounds() {
    // docs/validation.md in small: excitation logs of plants/m100_like.json, a PD and a SINDy model
    // identified from them with the M100's measured command delays, and the generated MPC of each
    // flying the three trajectories (15 s each) with examples/mpc_validation.json.
    let tmp = tempfile::tempdir().unwrap();
    let log = tmp.path().join("excite.csv");
    let o = uavgen(&[
        "simulate",
        "--plant",
        "plants/m100_like.json",
        "--profile",
        "excite",
        "--duration",
        "240",
        "--seed",
        "11",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let delay = "--input-delay=u_vz=0.133,u_roll=0.076,u_pitch=0.09,u_yaw_rate=0.176";
    let work = tmp.path().join("work");
    for (method, extra) in [
        ("pd", vec!["--mass", "2.9"]),
        (
            "sindy",
            vec![
                "--sweep",
                "--sweep-values",
                "16,20,24,32,40,48,64",
                "--criterion",
                "bic",
            ],
        ),
    ] {
        let model = tmp.path().join(format!("{method}.json"));
        let mut args = vec![
            "identify",
            "--method",
            method,
            "--log",
            log.to_str().unwrap(),
            delay,
            "--out",
            model.to_str().unwrap(),
        ];
        args.extend(extra);
        let o = uavgen(&args);
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        let out = tmp.path().join(format!("track_{method}"));
        let o = uavgen(&[
            "track",
            "--model",
            model.to_str().unwrap(),
            "--plant",
            "plants/m100_like.json",
            "--trajectory",
            "sinusoid,circle,spiral",
            "--duration",
            "15",
            "--mpc",
            "examples/mpc_validation.json",
            "--out",
            out.to_str().unwrap(),
            "--work-dir",
            work.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        for name in ["sinusoid", "circle", "spiral"] {
            let r = report(&out.join(name));
            eprintln!(
                "{method} {name}: RMSE {:.3} m, second half {:.3} m, statuses {}",
                r["overall"]["rmse"], r["overall_second_half"]["rmse"], r["statuses"]
            );
            assert_eq!(r["inputs_out_of_bounds"], 0, "{method} {name}");
            // Tracking, not oscillating: the full-length runs of docs/validation.md give 0.22–0.29 m.
            let late = r["overall_second_half"]["rmse"].as_f64().unwrap();
            assert!(late < 0.3, "{method} {name}: second-half RMSE {late}");
        }
    }
}
