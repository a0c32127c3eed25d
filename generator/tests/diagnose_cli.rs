//! The `uavgen diagnose` command: what it writes, and bad inputs (clear error, non-zero exit,
//! nothing left behind). The logs are fabricated: `models/pd_hover.json` simulated under a random
//! velocity-hold pilot with a linear drag added, plus small sensor noise.

use serde_json::Value;
use std::fs;
use std::path::Path;
use std::process::Output;

mod common;

use common::{repo, stderr, uavgen};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const DRAG: [f64; 2] = [0.35, 0.5];

/// `pd_hover` with Δv̇ = −diag(d, d, d_z) v, 30 Hz, 4 RK4 substeps per sample.
fn simulated_log(path: &Path, seconds: f64, seed: u64) {
    let m = uavgen::load(&repo().join("models/pd_hover.json")).unwrap();
    let ir = uavgen::ModelIr::new(&m);
    let dt = 1.0 / 30.0;
    let mut state = seed.wrapping_mul(0x9E3779B97F4A7C15) | 1;
    let mut rnd = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let f = |x: &[f64; 12], u: &[f64; 4]| -> [f64; 12] {
        let mut d: [f64; 12] = ir.eval_f(x, u).try_into().unwrap();
        d[6] -= DRAG[0] * x[6];
        d[7] -= DRAG[0] * x[7];
        d[8] -= DRAG[1] * x[8];
        d
    };
    let mut x = [0.0; 12];
    x[2] = 5.0;
    let mut text = String::from(
        "# rate_hz: 30\nt,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate\n",
    );
    let (mut vsp, mut zsp, mut r, mut jitter) = ([0.0; 2], 5.0, 0.0, [0.0; 4]);
    let n = (seconds / dt) as usize;
    for k in 0..n {
        if k % 60 == 0 {
            vsp = [6.0 * rnd(), 6.0 * rnd()];
            zsp = 5.0 + 6.0 * rnd();
            r = rnd();
        }
        if k % 5 == 0 {
            jitter = [rnd(), 0.1 * rnd(), 0.1 * rnd(), 0.5 * rnd()];
        }
        let a = [0.8 * (vsp[0] - x[6]), 0.8 * (vsp[1] - x[7])];
        let (c, sn) = (x[5].cos(), x[5].sin());
        let u = [
            (1.2 * (zsp - x[2]) + jitter[0]).clamp(-2.0, 2.0),
            ((a[0] * sn - a[1] * c) / 9.81 + jitter[1]).clamp(-0.3, 0.3),
            ((a[0] * c + a[1] * sn) / 9.81 + jitter[2]).clamp(-0.3, 0.3),
            r + jitter[3],
        ];
        let y: Vec<f64> = x.iter().map(|v| v + 0.002 * rnd()).collect();
        let row: Vec<String> = std::iter::once(k as f64 * dt)
            .chain(y)
            .chain(u)
            .map(|v| format!("{v}"))
            .collect();
        text.push_str(&row.join(","));
        text.push('\n');
        let h = dt / 4.0;
        for _ in 0..4 {
            let add = |a: &[f64; 12], s: f64, b: &[f64; 12]| -> [f64; 12] { std::array::from_fn(|i| a[i] + s * b[i]) };
            let k1 = f(&x, &u);
            let k2 = f(&add(&x, h / 2.0, &k1), &u);
            let k3 = f(&add(&x, h / 2.0, &k2), &u);
            let k4 = f(&add(&x, h, &k3), &u);
            x = std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        }
    }
    fs::write(path, text).unwrap();
}

/// The entries of a directory (names), sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn diagnose_writes_the_report_and_a_loadable_corrected_model() {
    let tmp = tempfile::tempdir().unwrap();
    let (train, test) = (tmp.path().join("train.csv"), tmp.path().join("test.csv"));
    simulated_log(&train, 60.0, 1);
    simulated_log(&test, 30.0, 2);
    let out = tmp.path().join("diag");
    let model = repo().join("models/pd_hover.json");
    let o = uavgen(&[
        "diagnose",
        "--model",
        s(&model),
        "--log",
        s(&train),
        "--holdout",
        s(&test),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("verdict: linear_drag"), "{stdout}");
    let files = entries(&out);
    for f in ["report.md", "report.json", "corrected.json", "rmse_before_after.svg"] {
        assert!(files.contains(&f.to_string()), "{f} missing: {files:?}");
    }
    assert!(files.iter().any(|f| f.starts_with("where_")), "{files:?}");
    // Nothing else next to the output (no temporary directory left).
    assert_eq!(entries(tmp.path()), vec!["diag", "test.csv", "train.csv"]);

    let report: Value = serde_json::from_str(&fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for key in ["model", "logs", "holdout", "effects", "verdict", "shrink", "where"] {
        assert!(report.get(key).is_some(), "report.json lacks {key}");
    }
    assert_eq!(report["verdict"], serde_json::json!(["linear_drag"]));
    let effects = report["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 11, "every catalogued effect is reported");
    for e in effects {
        for key in [
            "name",
            "parameters",
            "uncertainty",
            "heldout_rmse_before",
            "heldout_rmse_after",
            "score",
        ] {
            assert!(e.get(key).is_some(), "effect {} lacks {key}", e["name"]);
        }
    }
    let drag = &effects[0];
    assert_eq!(drag["name"], "linear_drag");
    let (xy, z) = (
        drag["parameters"]["xy"].as_f64().unwrap(),
        drag["parameters"]["z"].as_f64().unwrap(),
    );
    assert!((xy - DRAG[0]).abs() < 0.03 && (z - DRAG[1]).abs() < 0.05, "{xy} {z}");
    let sh = &report["shrink"];
    let before = sh["before"]["horizon"]["overall_rmse"].as_f64().unwrap();
    let after = sh["after"]["horizon"]["overall_rmse"].as_f64().unwrap();
    assert!(after < 0.7 * before, "horizon RMSE {before} → {after}");
    // No --plant: the closed-loop comparison is not run.
    assert_eq!(sh["closed_loop"]["status"], "not run");
    assert_eq!(sh["closed_loop"]["runs"].as_array().map(Vec::len), Some(0));

    // corrected.json: the model file as it was plus the block; it loads and checks.
    let corrected_text = fs::read_to_string(out.join("corrected.json")).unwrap();
    let corrected: Value = serde_json::from_str(&corrected_text).unwrap();
    let original: Value = serde_json::from_str(&fs::read_to_string(&model).unwrap()).unwrap();
    for (k, v) in original.as_object().unwrap() {
        assert_eq!(&corrected[k], v, "{k} changed");
    }
    assert_eq!(corrected["corrections"]["linear_drag"]["xy"].as_f64().unwrap(), xy);
    let m = uavgen::model::parse(&corrected_text, "corrected.json").unwrap();
    assert!(m.corrections.unwrap().linear_drag.is_some());
    let o = uavgen(&["check", "--model", s(&out.join("corrected.json"))]);
    assert!(o.status.success(), "{}", stderr(&o));

    // A model that already has corrections other than an input response is refused.
    let o = uavgen(&[
        "diagnose",
        "--model",
        s(&out.join("corrected.json")),
        "--log",
        s(&train),
        "--out",
        s(&tmp.path().join("again")),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("has a `corrections` block with more than an input response"),
        "{}",
        stderr(&o)
    );
    assert!(!tmp.path().join("again").exists());

    // One with only an input response (what `identify --input-delay auto` writes) is diagnosed
    // with it as part of the base, and corrected.json keeps it.
    let mut delayed = original.clone();
    delayed["corrections"] = serde_json::json!({"latency": {"u_vz": 0.1}});
    let delayed_path = tmp.path().join("delayed.json");
    fs::write(&delayed_path, serde_json::to_string_pretty(&delayed).unwrap()).unwrap();
    let o = uavgen(&[
        "diagnose",
        "--model",
        s(&delayed_path),
        "--log",
        s(&train),
        "--out",
        s(&tmp.path().join("delayed")),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let c: Value =
        serde_json::from_str(&fs::read_to_string(tmp.path().join("delayed/corrected.json")).unwrap()).unwrap();
    assert!(c["corrections"]["latency"]["u_vz"].as_f64().unwrap() >= 0.1, "{c}");
    let r = fs::read_to_string(tmp.path().join("delayed/report.md")).unwrap();
    assert!(r.contains("input response of its own (u_vz delay 0.1000 s)"), "{r}");
}

#[test]
fn cross_validation_without_a_holdout() {
    let tmp = tempfile::tempdir().unwrap();
    let train = tmp.path().join("train.csv");
    simulated_log(&train, 60.0, 3);
    let out = tmp.path().join("cv");
    let o = uavgen(&[
        "diagnose",
        "--model",
        "models/pd_hover.json",
        "--log",
        s(&train),
        "--out",
        s(&out),
        "--no-where",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: Value = serde_json::from_str(&fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["holdout"]["mode"], "cross-validation");
    assert_eq!(report["holdout"]["folds"], 4);
    assert_eq!(report["verdict"], serde_json::json!(["linear_drag"]));
    assert!(report["where"].is_null());
}

#[test]
fn bad_inputs_are_errors_and_leave_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let train = tmp.path().join("train.csv");
    simulated_log(&train, 20.0, 4);
    let out = tmp.path().join("out");
    let run = |extra: &[&str]| -> Output {
        let mut args = vec!["diagnose"];
        args.extend(extra);
        uavgen(&args)
    };
    let failed = |o: &Output, needle: &str| {
        assert!(!o.status.success(), "should fail");
        assert!(stderr(o).contains(needle), "expected `{needle}` in: {}", stderr(o));
        assert!(!out.exists(), "--out was created");
        assert_eq!(entries(tmp.path()), vec!["train.csv"], "something was left behind");
    };
    // Missing model.
    let missing = tmp.path().join("nope.json");
    let o = run(&["--model", s(&missing), "--log", s(&train), "--out", s(&out)]);
    failed(&o, "nope.json");
    // A log that is not a log.
    let bad = tmp.path().join("bad.csv");
    fs::write(&bad, "t,x\n1,2\n").unwrap();
    let o = run(&["--model", "models/pd_hover.json", "--log", s(&bad), "--out", s(&out)]);
    fs::remove_file(&bad).unwrap();
    failed(&o, "bad.csv:1: missing required columns");
    // An empty held-out log (fewer rows than the derivative window needs).
    let short = tmp.path().join("short.csv");
    let text = fs::read_to_string(&train).unwrap();
    fs::write(&short, text.lines().take(8).collect::<Vec<_>>().join("\n") + "\n").unwrap();
    let o = run(&[
        "--model",
        "models/pd_hover.json",
        "--log",
        s(&train),
        "--holdout",
        s(&short),
        "--out",
        s(&out),
    ]);
    fs::remove_file(&short).unwrap();
    failed(&o, "the held-out logs: no segment has at least 11 rows");
    // An unknown effect.
    let o = run(&[
        "--model",
        "models/pd_hover.json",
        "--log",
        s(&train),
        "--out",
        s(&out),
        "--effects",
        "linear_drag,wind",
    ]);
    failed(&o, "unknown effect `wind`");
    // --out exists: refused without --force, untouched; replaced with it.
    fs::create_dir(&out).unwrap();
    fs::write(out.join("keep.txt"), "mine").unwrap();
    let args = [
        "--model",
        "models/pd_hover.json",
        "--log",
        s(&train),
        "--out",
        s(&out),
        "--no-where",
    ];
    let o = run(&args);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("exists; pass --force"), "{}", stderr(&o));
    assert_eq!(entries(&out), vec!["keep.txt"]);
    let mut forced = args.to_vec();
    forced.push("--force");
    let o = run(&forced);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("keep.txt").exists() && out.join("report.json").exists());
    assert_eq!(entries(tmp.path()), vec!["out", "train.csv"]);
}
