//! Issue 15, "never a panic, never a silent wrong answer": one test per failure class a tester
//! found. Each runs the `uavgen` binary on a malformed or degenerate input and checks a clear
//! error (the file, the field and the value named; huge values in short form), a non-zero exit
//! that is not a panic, and that nothing was written.

mod common;

use common::{repo, stderr, uavgen};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A clean failure: exit 1, no panic, and `needles` in stderr.
fn fails_with(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "expected exit 1, got {:?}:\n{err}", o.status);
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "expected {n:?} in:\n{err}");
    }
    // No 300-digit numbers.
    assert!(!err.contains("00000000000000000000"), "{err}");
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn write_json(path: &Path, v: &serde_json::Value) {
    std::fs::write(path, serde_json::to_string_pretty(v).unwrap()).unwrap();
}

/// A model with one field changed.
fn model_with(dir: &Path, base: &str, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let mut v = json(&repo().join("models").join(base));
    edit(&mut v);
    let path = dir.join(name);
    write_json(&path, &v);
    path
}

#[test]
fn absurd_model_parameters_are_named_errors_in_generate_and_check() {
    let tmp = tempfile::tempdir().unwrap();
    let gravity = model_with(tmp.path(), "pd_hover.json", "gravity.json", |v| {
        v["gravity"] = 1e308.into()
    });
    let mass = model_with(tmp.path(), "pd_hover.json", "mass.json", |v| v["mass"] = 1e308.into());
    let coefficient = model_with(tmp.path(), "sindy_m100.json", "coef.json", |v| {
        v["coefficients"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({"state": "vx", "term": "vx^2", "coefficient": 1e308}))
    });
    let xi = model_with(tmp.path(), "pd_hover.json", "xi.json", |v| v["xi"]["xi4"] = 1e12.into());
    let correction = model_with(tmp.path(), "sindy_m100.json", "corr.json", |v| {
        v["corrections"] = serde_json::json!({"force_bias": [1e300, 0, 0]})
    });
    for (path, field, value) in [
        (&gravity, "gravity", "1e308"),
        (&mass, "mass", "1e308"),
        (&coefficient, "coefficients[", "1e308"),
        (&xi, "xi.xi4", "1e12"),
        (&correction, "corrections.force_bias[0]", "1e300"),
    ] {
        let out = tmp.path().join("out");
        for args in [
            vec!["--model", s(path), "--substeps", "1", "--out", s(&out)],
            vec!["--model", s(path), "--out", s(&out)],
            vec!["check", "--model", s(path)],
            vec!["check", "--model", s(path), "--substeps", "1"],
        ] {
            let o = uavgen(&args);
            fails_with(&o, &[s(path), field, value]);
            assert!(!out.exists(), "{args:?} wrote {}", out.display());
        }
    }
}

#[test]
fn an_absurdly_unstable_model_is_refused_by_the_substep_rule() {
    // Within the coefficient range, but vx' = 1e6 vx: e-folding in a microsecond.
    let tmp = tempfile::tempdir().unwrap();
    let path = model_with(tmp.path(), "sindy_m100.json", "unstable.json", |v| {
        for c in v["coefficients"].as_array_mut().unwrap() {
            if c["state"] == "vx" && c["term"] == "vx" {
                c["coefficient"] = 1e6.into();
            }
        }
    });
    let out = tmp.path().join("out");
    for args in [
        vec!["--model", s(&path), "--out", s(&out)],
        vec!["check", "--model", s(&path)],
    ] {
        let o = uavgen(&args);
        fails_with(&o, &[s(&path), "grows by", "1.0000e6"]);
        assert!(!out.exists());
    }
}

#[test]
fn the_emitter_returns_an_error_for_non_finite_constants() {
    use uavgen::symbolic::{float_literal, Float};
    assert!(float_literal(f64::NAN, Float::F64).is_err());
    assert!(float_literal(f64::INFINITY, Float::F64).is_err());
    // Finite in f64, infinite in f32.
    assert!(float_literal(1e300, Float::F64).is_ok());
    let e = float_literal(1e300, Float::F32).unwrap_err();
    assert!(e.to_string().contains("1e300"), "{e}");
}

#[test]
fn check_runs_what_generation_runs_and_takes_substeps() {
    let m = repo().join("models/pd_paper.json");
    let o = uavgen(&["check", "--model", s(&m), "--substeps", "4"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("4 substeps (given)") && text.contains("generation: ok"),
        "{text}"
    );
    // Whatever generation refuses, check refuses: an MPC option out of range.
    let tmp = tempfile::tempdir().unwrap();
    let mpc = tmp.path().join("mpc.json");
    std::fs::write(&mpc, r#"{"q": [1e308, 2, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0]}"#).unwrap();
    let o = uavgen(&["check", "--model", s(&m), "--mpc", s(&mpc)]);
    fails_with(&o, &[s(&mpc), "q[0]", "1e308"]);
}

#[test]
fn a_model_too_large_for_the_substep_rule_is_refused_at_once() {
    // 1000 states: the automatic substep rule would take minutes; the limit is documented.
    let names: Vec<String> = (0..1000).map(|i| format!("s{i}")).collect();
    let v = serde_json::json!({
        "format": "uavgen-model/1", "kind": "sindy", "name": "big",
        "states": names, "inputs": ["u"],
        "library": ["1"], "kinematic": [], "coefficients": [],
    });
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("big.json");
    write_json(&path, &v);
    let start = std::time::Instant::now();
    let o = uavgen(&["check", "--model", s(&path)]);
    fails_with(&o, &[s(&path), "1000 states", "at most 64"]);
    assert!(start.elapsed().as_secs() < 10);
}

#[test]
fn a_byte_order_mark_is_accepted() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bom.json");
    let text = std::fs::read_to_string(repo().join("models/pd_hover.json")).unwrap();
    std::fs::write(&path, format!("\u{feff}{text}")).unwrap();
    let o = uavgen(&["check", "--model", s(&path), "--substeps", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn absurd_mpc_options_and_plants_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let m = repo().join("models/pd_hover.json");
    let out = tmp.path().join("crate");
    for (text, field, value) in [
        (r#"{"q": [1e308, 2, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0]}"#, "q[0]", "1e308"),
        (r#"{"r": [0.1, 0.1, 0.1, 2e6]}"#, "r[3]", "2000000"),
        (r#"{"u_min": [-1e308, -1, -1, -1]}"#, "u_min[0]", "-1e308"),
        (r#"{"u_max": [1, 1, 1, 1e308]}"#, "u_max[3]", "1e308"),
        (r#"{"regularisation": 1e300}"#, "regularisation", "1e300"),
        (r#"{"disturbance_gain": 1.5}"#, "disturbance_gain", "1.5"),
        (r#"{"disturbance_gain": -0.1}"#, "disturbance_gain", "-0.1"),
        (
            r#"{"disturbance_max_acceleration": 1e9}"#,
            "disturbance_max_acceleration",
            "1e9",
        ),
    ] {
        let mpc = tmp.path().join("mpc.json");
        std::fs::write(&mpc, text).unwrap();
        let o = uavgen(&["--model", s(&m), "--mpc", s(&mpc), "--substeps", "1", "--out", s(&out)]);
        fails_with(&o, &[s(&mpc), field, value]);
        assert!(!out.exists());
    }
    let mut plant = json(&repo().join("plants/m100_like.json"));
    plant["effects"]["sensor_noise"]["pos"] = 1e200.into();
    let path = tmp.path().join("plant.json");
    write_json(&path, &plant);
    let log = tmp.path().join("log.csv");
    let o = uavgen(&[
        "simulate",
        "--plant",
        s(&path),
        "--profile",
        "hover",
        "--duration",
        "1",
        "--out",
        s(&log),
    ]);
    fails_with(&o, &[s(&path), "effects.sensor_noise.pos", "1e200"]);
    assert!(!log.exists());
}

/// A short log in LOG_FORMAT.md: `rows` samples at 30 Hz of `f(k)` for each of the 16 values.
fn log_file(dir: &Path, name: &str, rows: usize, f: impl Fn(usize, usize) -> f64) -> PathBuf {
    let mut text = String::from(
        "# rate_hz: 30\nt,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate\n",
    );
    for k in 0..rows {
        text.push_str(&format!("{}", k as f64 / 30.0));
        for c in 0..16 {
            text.push_str(&format!(",{}", f(k, c)));
        }
        text.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// A small wave on every column, z lifted to 5 m: a flight (evaluate leaves out horizon runs on
/// the ground, z ≤ 0.02 m).
fn wavy(k: usize, c: usize) -> f64 {
    let lift = if c == 2 { 5.0 } else { 0.0 };
    lift + 0.1 * ((k as f64) * 0.05 * (c + 1) as f64).sin()
}

#[test]
fn degenerate_logs_are_errors_not_exit_0() {
    let tmp = tempfile::tempdir().unwrap();
    let m = repo().join("models/sindy_m100.json");
    let one = log_file(tmp.path(), "one.csv", 1, wavy);
    let o = uavgen(&["evaluate", "--model", s(&m), "--log", s(&one)]);
    fails_with(&o, &[s(&one), "no segment has two samples"]);
    let short = log_file(tmp.path(), "short.csv", 60, wavy);
    let o = uavgen(&["evaluate", "--model", s(&m), "--log", s(&short), "--horizon", "100000"]);
    fails_with(&o, &[s(&short), "horizon of 100000 samples", "60 samples"]);
    let zero = log_file(tmp.path(), "zero.csv", 300, |_, _| 0.0);
    let out = tmp.path().join("zero.json");
    for method in ["sindy", "pd"] {
        let o = uavgen(&["identify", "--method", method, "--log", s(&zero), "--out", s(&out)]);
        fails_with(&o, &[s(&zero), "constant"]);
        assert!(!out.exists());
    }
    // Too short for the Savitzky-Golay window: the message names the file.
    let tiny = log_file(tmp.path(), "tiny.csv", 5, wavy);
    let o = uavgen(&[
        "identify",
        "--method",
        "sindy",
        "--input-delay",
        "none",
        "--log",
        s(&tiny),
        "--out",
        s(&out),
    ]);
    fails_with(&o, &[s(&tiny), "Savitzky-Golay window 9"]);
    let o = uavgen(&[
        "identify",
        "--method",
        "sindy",
        "--input-delay",
        "1000",
        "--log",
        s(&short),
        "--out",
        s(&out),
    ]);
    fails_with(&o, &["--input-delay", "within [0, 10] s", "1000"]);
    assert!(!out.exists());
}

#[test]
fn huge_log_values_name_the_file_line_and_column() {
    let tmp = tempfile::tempdir().unwrap();
    let big = log_file(tmp.path(), "big.csv", 100, |k, c| {
        if k == 7 && c == 7 {
            1e300
        } else {
            wavy(k, c)
        }
    });
    let out = tmp.path().join("m.json");
    let o = uavgen(&["identify", "--method", "sindy", "--log", s(&big), "--out", s(&out)]);
    // Line 10: two header lines, then sample 7.
    fails_with(&o, &[&format!("{}:10", s(&big)), "column `vy`", "1e300"]);
    assert!(!out.exists());
}

#[test]
fn outputs_follow_one_force_rule_and_nothing_is_left_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let m = repo().join("models/sindy_m100.json");
    let log = log_file(tmp.path(), "log.csv", 120, wavy);
    // --plots is a file: fails before writing --json.
    let new = tmp.path().join("new.json");
    let plots = tmp.path().join("plots");
    std::fs::write(&plots, "a file").unwrap();
    let o = uavgen(&[
        "evaluate",
        "--model",
        s(&m),
        "--log",
        s(&log),
        "--json",
        s(&new),
        "--plots",
        s(&plots),
    ]);
    fails_with(&o, &["--plots", s(&plots)]);
    assert!(!new.exists());
    // An existing --json is replaced only with --force.
    std::fs::write(&new, "keep").unwrap();
    let o = uavgen(&["evaluate", "--model", s(&m), "--log", s(&log), "--json", s(&new)]);
    fails_with(&o, &[s(&new), "--force"]);
    assert_eq!(std::fs::read_to_string(&new).unwrap(), "keep");
    let o = uavgen(&[
        "evaluate",
        "--model",
        s(&m),
        "--log",
        s(&log),
        "--json",
        s(&new),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(std::fs::read_to_string(&new).unwrap(), "keep");
}

#[test]
fn regenerating_refuses_files_the_user_added() {
    let tmp = tempfile::tempdir().unwrap();
    let m = repo().join("models/pd_hover.json");
    let out = tmp.path().join("crate");
    let generate = |force: bool| {
        let mut args = vec!["--model", s(&m), "--substeps", "1", "--out", s(&out)];
        if force {
            args.push("--force");
        }
        uavgen(&args)
    };
    assert!(generate(false).status.success());
    std::fs::create_dir_all(out.join("tests")).unwrap();
    std::fs::write(out.join("tests/mine.rs"), "// mine").unwrap();
    std::fs::write(out.join("NOTES.md"), "mine").unwrap();
    let o = generate(false);
    fails_with(&o, &[s(&out), "NOTES.md", "tests/mine.rs", "--force"]);
    assert!(out.join("tests/mine.rs").exists() && out.join("NOTES.md").exists());
    // Build products stay without --force.
    std::fs::remove_file(out.join("NOTES.md")).unwrap();
    std::fs::remove_dir_all(out.join("tests")).unwrap();
    std::fs::create_dir_all(out.join("target")).unwrap();
    assert!(generate(false).status.success());
    std::fs::write(out.join("NOTES.md"), "mine").unwrap();
    let o = generate(true);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("NOTES.md").exists() && out.join("target").exists());
}

#[test]
fn an_unwritable_out_names_the_target_not_a_staging_path() {
    let o = uavgen(&[
        "--model",
        "models/pd_hover.json",
        "--substeps",
        "1",
        "--out",
        "/proc/uavgen-x",
    ]);
    fails_with(&o, &["/proc/uavgen-x"]);
    assert!(!stderr(&o).contains("staging"), "{}", stderr(&o));
}

#[test]
fn a_closed_stdout_ends_the_program_quietly() {
    // `uavgen check ... | head -0`: the reader is gone before the first line.
    let mut child = Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .args(["check", "--model", "models/pd_paper.json", "--substeps", "3"])
        .current_dir(repo())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(
        !err.contains("panicked") && o.status.code() != Some(101),
        "{:?}: {err}",
        o.status
    );
}

#[test]
fn unbounded_durations_are_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("track");
    let o = uavgen(&[
        "track",
        "--model",
        "models/sindy_m100.json",
        "--plant",
        "plants/m100_like.json",
        "--trajectory",
        "circle",
        "--duration",
        "1e9",
        "--out",
        s(&out),
    ]);
    fails_with(&o, &["--duration", "1e9"]);
    assert!(!out.exists());
    let log = tmp.path().join("log.csv");
    let o = uavgen(&[
        "simulate",
        "--plant",
        "plants/m100_like.json",
        "--profile",
        "hover",
        "--duration",
        "1e9",
        "--out",
        s(&log),
    ]);
    fails_with(&o, &["--duration", "1000000000"]);
    assert!(!log.exists());
}
