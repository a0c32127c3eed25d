//! The `envelope` block of a model file (docs/model-format.md#envelope): computed from flight logs
//! (by hand on a tiny log), written by `uavgen envelope` and `uavgen identify`, carried into the
//! generated crate, and bad blocks refused with the file, field and value.

mod common;

use common::{excite, repo, stderr, uavgen};
use std::fs;
use std::path::Path;

/// Five rows whose ranges are easy to widen by hand (the other states are 0).
const TINY: &str = "# rate_hz: 30
t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate
0.0,0,0,5,0.1,0,0,-1,0,0,0,0,0,0,0,0,0
0.0333333333,0,0,5,-0.1,0,0,0,0,0,1,0,0,0,0,0,0
0.0666666667,0,0,5,0.3,0,0,3,0,0,-1,0,0,0,0,0,0
0.1,0,0,5,0,0,0,1,0,0,0,0,0,0,0,0,0
0.1333333333,0,0,5,0,0,0,2,0,0,0,0,0,0,0,0,0
";

#[test]
fn the_envelope_of_a_tiny_log_is_the_hand_computed_one() {
    let tmp = tempfile::tempdir().unwrap();
    let log = tmp.path().join("tiny.csv");
    fs::write(&log, TINY).unwrap();
    let out = tmp.path().join("with_envelope.json");
    let o = uavgen(&[
        "envelope",
        "--model",
        "models/pd_hover.json",
        "--log",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let model = uavgen::load(&out).unwrap_or_else(|e| panic!("{e}"));
    let e = model.envelope.expect("written");
    // m = 2 · (max − min)/2 + floor; floors: angles 0.1 rad, speeds 0.5 m/s, rates 0.5 rad/s.
    let expected = [
        ("roll", -0.6, 0.8),  // [-0.1, 0.3]: m = 0.4 + 0.1
        ("pitch", -0.1, 0.1), // constant 0: the floor
        ("vx", -5.5, 7.5),    // [-1, 3]: m = 4 + 0.5
        ("vy", -0.5, 0.5),
        ("vz", -0.5, 0.5),
        ("roll_rate", -3.5, 3.5), // [-1, 1]: m = 2 + 0.5
        ("pitch_rate", -0.5, 0.5),
        ("yaw_rate", -0.5, 0.5),
    ];
    assert_eq!(e.bounds.len(), expected.len());
    for ((name, lo, hi), (got_name, got_lo, got_hi)) in expected.iter().zip(&e.bounds) {
        assert_eq!(name, got_name);
        assert!(
            (lo - got_lo).abs() < 1e-12 && (hi - got_hi).abs() < 1e-12,
            "{name}: [{got_lo}, {got_hi}]"
        );
    }
    // Positions and yaw are not bounded by the logs (translation and heading invariance).
    assert!(e.get("x").is_none() && e.get("z").is_none() && e.get("yaw").is_none());
    // The rest of the model file is copied unchanged.
    let before = uavgen::load(&repo().join("models/pd_hover.json")).unwrap();
    assert_eq!(format!("{:?}", model.dynamics), format!("{:?}", before.dynamics));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("vx") && stdout.contains("-5.500"), "{stdout}");
    // Without --out nothing is written; an existing --out needs --force.
    let o = uavgen(&[
        "envelope",
        "--model",
        "models/pd_hover.json",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = uavgen(&[
        "envelope",
        "--model",
        "models/pd_hover.json",
        "--log",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
}

fn check(path: &Path) -> std::process::Output {
    uavgen(&["check", "--model", path.to_str().unwrap()])
}

#[test]
fn bad_envelope_blocks_are_refused_with_file_field_and_value() {
    let tmp = tempfile::tempdir().unwrap();
    let base: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(repo().join("models/pd_hover.json")).unwrap()).unwrap();
    let cases: Vec<(serde_json::Value, &str)> = vec![
        (
            serde_json::json!({"vx": [2.0, 1.0]}),
            "envelope.vx: lo must be below hi, found [2, 1]",
        ),
        (
            serde_json::json!({"vx": [1.0, 1.0]}),
            "envelope.vx: lo must be below hi, found [1, 1]",
        ),
        (
            serde_json::json!({"speed": [0, 1]}),
            "envelope.speed: 'speed' is not a state of the model",
        ),
        (
            serde_json::json!({"vz": [-1e300, 1]}),
            "envelope.vz[0]: an envelope bound must be finite with magnitude at most 1000000, found -1e300",
        ),
        (
            serde_json::json!({"pitch": [-0.5, 2.0]}),
            "envelope.pitch: pitch must stay within ±π/2 rad",
        ),
        (
            serde_json::json!({"vx": [1, 2, 3]}),
            "envelope.vx: expected [lo, hi] (two numbers), found [1,2,3]",
        ),
        (
            serde_json::json!({"vx": [null, 2]}),
            "envelope.vx[0]: expected a number, found null",
        ),
        (serde_json::json!({"vx": "wide"}), "envelope.vx: expected [lo, hi]"),
        (serde_json::json!([[-1, 1]]), "envelope: expected an object"),
        (serde_json::json!({}), "envelope: an empty envelope declares nothing"),
    ];
    for (i, (block, message)) in cases.into_iter().enumerate() {
        let mut model = base.clone();
        model["envelope"] = block;
        let path = tmp.path().join(format!("bad{i}.json"));
        fs::write(&path, serde_json::to_string_pretty(&model).unwrap()).unwrap();
        let o = check(&path);
        assert_eq!(o.status.code(), Some(1), "{message}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains(&format!("bad{i}.json: {message}")),
            "expected '{message}' in: {err}"
        );
        // Generation refuses it too and writes nothing.
        let out = tmp.path().join(format!("crate{i}"));
        let o = uavgen(&["--model", path.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1));
        assert!(!out.exists());
    }
    // A good block is accepted.
    let mut model = base.clone();
    model["envelope"] = serde_json::json!({"vz": [-2, 2.5], "roll": [-1.5, 1.5]});
    let path = tmp.path().join("good.json");
    fs::write(&path, serde_json::to_string_pretty(&model).unwrap()).unwrap();
    let o = check(&path);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn the_generated_crate_carries_the_declared_envelope() {
    let tmp = tempfile::tempdir().unwrap();
    let mut model: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(repo().join("models/pd_hover.json")).unwrap()).unwrap();
    model["envelope"] = serde_json::json!({"vz": [-2, 2.5]});
    let path = tmp.path().join("m.json");
    fs::write(&path, serde_json::to_string_pretty(&model).unwrap()).unwrap();
    let out = tmp.path().join("crate");
    let o = uavgen(&["--model", path.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dims = fs::read_to_string(out.join("src/dims.rs")).unwrap();
    let array = |name: &str| -> String {
        let start = dims.find(&format!("pub const {name}")).unwrap();
        let rest = &dims[start..];
        rest[..rest.find("];").unwrap()]
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
    };
    // vz (index 8) is the declared [-2, 2.5]; x keeps the generic 1e4 m, yaw the plausible ±1e4 rad
    // (issue 28: a yaw of 1e12 is out of the envelope).
    let lo = array("ENVELOPE_LO");
    let hi = array("ENVELOPE_HI");
    assert!(lo.contains("-10000.0, -10000.0, -10000.0,"), "{lo}");
    assert!(lo.contains("-1.5, -10000.0, -50.0, -50.0, -2.0, -30.0"), "{lo}");
    assert!(hi.contains("1.5, 10000.0, 50.0, 50.0, 2.5, 30.0"), "{hi}");
    let readme = fs::read_to_string(out.join("README.md")).unwrap();
    assert!(readme.contains("the model file's envelope on vz"), "{readme}");
}

#[test]
fn evaluate_notes_a_log_that_leaves_the_envelope() {
    let tmp = tempfile::tempdir().unwrap();
    let log = tmp.path().join("flight.csv");
    excite("plants/nominal.json", "20", None, &log);
    let mut model: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(repo().join("models/pd_hover.json")).unwrap()).unwrap();
    let evaluate = |model: &serde_json::Value| {
        let path = tmp.path().join("m.json");
        fs::write(&path, serde_json::to_string_pretty(model).unwrap()).unwrap();
        let o = uavgen(&[
            "evaluate",
            "--model",
            path.to_str().unwrap(),
            "--log",
            log.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    // Without an envelope, or with one the flight stays in: no note.
    assert!(!evaluate(&model).contains("outside the model's envelope"));
    model["envelope"] = serde_json::json!({"vx": [-100, 100], "roll": [-1.5, 1.5]});
    assert!(!evaluate(&model).contains("outside the model's envelope"));
    // An excitation flight leaves a ±1 cm/s envelope on vx; roll stays inside.
    model["envelope"] = serde_json::json!({"vx": [-0.01, 0.01], "roll": [-1.5, 1.5]});
    let err = evaluate(&model);
    assert!(
        err.contains("flight.csv: ") && err.contains("rows outside the model's envelope (vx)"),
        "{err}"
    );
}
