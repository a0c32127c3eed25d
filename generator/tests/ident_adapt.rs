//! `uavgen identify` adapts to the data (docs/identification.md, "Unexcited directions"): on short
//! flights of the bed's nano (100 Hz) and PX4-class (50 Hz) plants with the heading held
//! (`simulate --profile excite-hold-heading`: yaw still, u_yaw_rate silent), both methods with
//! default options write a model; the still heading and the silent channel are said on stderr and
//! in the provenance; SINDy has no heading or u_yaw_rate term, PD holds the yaw gain at the unit
//! static gain, and no delay is written for the silent channel.

mod common;

use common::{identify, repo, stderr, uavgen};
use std::fs;
use std::path::{Path, PathBuf};

/// A heading-held excitation flight of `plants/<plant>.json`, `seconds` long.
fn hold_heading(dir: &Path, plant: &str, seconds: &str) -> PathBuf {
    let log = dir.join(format!("{plant}.csv"));
    let plant = repo().join(format!("plants/{plant}.json"));
    let o = uavgen(&[
        "simulate",
        "--plant",
        plant.to_str().unwrap(),
        "--profile",
        "excite-hold-heading",
        "--duration",
        seconds,
        "--seed",
        "3",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    log
}

/// Identify with defaults; the model must be written (no horizon-check refusal). Returns the
/// model JSON and stderr.
fn identify_defaults(method: &str, log: &Path, dir: &Path) -> (serde_json::Value, String) {
    let out = dir.join(format!("{method}.json"));
    let o = identify(method, log, &out, &[]);
    let err = stderr(&o);
    assert!(o.status.success(), "{method}: {err}");
    assert!(err.contains("stayed bounded"), "{method}: {err}");
    let v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&out).unwrap()).unwrap();
    (v, err)
}

/// What both methods share on a still-heading flight with a silent yaw channel.
fn assert_unexcited_said(v: &serde_json::Value, err: &str) {
    assert!(err.contains("warning: the heading did not move"), "{err}");
    assert!(err.contains("warning: u_yaw_rate carries no signal"), "{err}");
    // PD keeps identify's record under provenance.data, SINDy at the top of its provenance.
    let p = if v["kind"] == "pd" {
        &v["provenance"]["data"]
    } else {
        &v["provenance"]
    };
    assert_eq!(p["excitation"]["heading"]["still"], true, "{p}");
    assert_eq!(p["excitation"]["channels"]["u_yaw_rate"]["silent"], true, "{p}");
    for input in ["u_vz", "u_roll", "u_pitch"] {
        assert_eq!(p["excitation"]["channels"][input]["silent"], false, "{input}: {p}");
    }
    let warnings = v["provenance"]["warnings"].as_array().expect("provenance.warnings");
    assert!(warnings
        .iter()
        .any(|w| w.as_str().unwrap().contains("heading did not move")));
    // No delay or lag without evidence: the silent channel's is neither scanned nor written.
    let ch = &p["input_response"]["channels"]["u_yaw_rate"];
    assert_eq!(ch["silent"], true, "{ch}");
    assert!(
        v["corrections"]["latency"].get("u_yaw_rate").is_none(),
        "{}",
        v["corrections"]
    );
    assert!(
        v["corrections"]["actuator_lag"].get("u_yaw_rate").is_none(),
        "{}",
        v["corrections"]
    );
    // No delay at the scan's edge on any channel.
    if let Some(latency) = v["corrections"]["latency"].as_object() {
        for (k, d) in latency {
            assert!(d.as_f64().unwrap() < 0.45, "{k}: {d}");
        }
    }
}

fn assert_sindy_adapted(v: &serde_json::Value, err: &str) {
    assert_unexcited_said(v, err);
    // Heading terms only in the vx and vy rows, fitted in the heading frame (rotated by the
    // heading as structure, docs/identification.md "Heading frame"); none of the silent input.
    let coefs = v["coefficients"].as_array().unwrap();
    for c in coefs {
        let (state, term) = (c["state"].as_str().unwrap(), c["term"].as_str().unwrap());
        assert!(!term.contains("u_yaw_rate"), "{state}: {term}");
        assert!(
            !term.contains("yaw)") || state == "vx" || state == "vy",
            "{state}: {term}"
        );
    }
    assert_eq!(
        v["provenance"]["heading_frame"]["rows"],
        serde_json::json!(["vx", "vy"]),
        "{}",
        v["provenance"]
    );
    // The thrust direction rotates with the heading: the vx row holds a tilt term times cos or
    // sin of the heading.
    assert!(
        coefs.iter().any(|c| c["state"] == "vx"
            && c["term"].as_str().unwrap().contains("yaw)")
            && (c["term"].as_str().unwrap().contains("pitch") || c["term"].as_str().unwrap().contains("roll"))),
        "{coefs:?}"
    );
    let excluded = v["provenance"]["excluded_unexcited_terms"].as_array().unwrap();
    assert!(excluded.iter().any(|t| t == "u_roll*cos(yaw)"), "{excluded:?}");
    assert!(excluded.iter().any(|t| t == "u_yaw_rate"), "{excluded:?}");
    // The model cannot act on the silent channel: said, not hidden.
    assert!(
        err.contains("warning: u_yaw_rate: the model does not act on it"),
        "{err}"
    );
}

fn assert_pd_adapted(v: &serde_json::Value, err: &str) {
    assert_unexcited_said(v, err);
    // ξ4 (yaw gain) held at ξ10 (yaw damping): unit static gain, not a fitted 0.
    let xi: Vec<f64> = v["xi"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(xi[3] == xi[9], "{xi:?}");
    // The yaw damping has nothing to be fitted on (the yaw rate is gyro noise): it is held at its
    // physical bound Iz / τ (1 s; docs/pd-fit.md), not fitted to 0, so the yaw channel is alive.
    assert!(
        xi[9] >= xi[15] / uavgen::identify::pd::MAX_RATE_TIME_CONSTANT - 1e-9,
        "{xi:?}"
    );
    // Were the yaw damping 0, the yaw channel would be dead in the model: said, not hidden.
    if xi[9] == 0.0 {
        assert!(
            err.contains("warning: u_yaw_rate: the model does not act on it"),
            "{err}"
        );
    }
    assert_eq!(
        v["provenance"]["options"]["unit_gain"],
        serde_json::json!([false, false, false, true])
    );
    assert!(!err.contains("static gain is ~0"), "{err}");
}

#[test]
fn nano_still_heading_both_methods_write_an_adapted_model() {
    let dir = tempfile::tempdir().unwrap();
    let log = hold_heading(dir.path(), "nano", "20");
    let (v, err) = identify_defaults("sindy", &log, dir.path());
    assert_sindy_adapted(&v, &err);
    // The Savitzky-Golay window is 0.3 s at the log's 100 Hz.
    assert_eq!(v["provenance"]["savitzky_golay"]["window"], 31, "{}", v["provenance"]);
    let (v, err) = identify_defaults("pd", &log, dir.path());
    assert_pd_adapted(&v, &err);
}

#[test]
fn px4_still_heading_both_methods_write_an_adapted_model() {
    let dir = tempfile::tempdir().unwrap();
    let log = hold_heading(dir.path(), "px4_quad", "15");
    let (v, err) = identify_defaults("sindy", &log, dir.path());
    assert_sindy_adapted(&v, &err);
    assert_eq!(v["provenance"]["savitzky_golay"]["window"], 15, "{}", v["provenance"]);
    let (v, err) = identify_defaults("pd", &log, dir.path());
    assert_pd_adapted(&v, &err);
}

/// A commanded channel the model ignores is warned about: PD without its yaw row's gain
/// estimate (`--input-delay none` on the heading-held flight, with the yaw command's signal
/// restored so that the channel counts as commanded, but the yaw rate answering nothing).
#[test]
fn a_commanded_channel_with_zero_gain_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let log = hold_heading(dir.path(), "px4_quad", "10");
    // Replace u_yaw_rate by a signal the yaw rate does not follow (a square wave of ±0.5 rad/s):
    // the channel carries a signal, the fitted gain is ~0.
    let text = fs::read_to_string(&log).unwrap();
    let mut lines = text.lines();
    let mut out = String::new();
    let mut col = None;
    let mut row = 0usize;
    for line in &mut lines {
        if line.starts_with('#') {
            out += line;
            out += "\n";
            continue;
        }
        if col.is_none() {
            col = line.split(',').position(|c| c.trim() == "u_yaw_rate");
            out += line;
            out += "\n";
            continue;
        }
        let c = col.unwrap();
        let mut fields: Vec<String> = line.split(',').map(str::to_string).collect();
        fields[c] = if (row / 50) % 2 == 0 {
            "0.5".into()
        } else {
            "-0.5".into()
        };
        row += 1;
        out += &fields.join(",");
        out += "\n";
    }
    let edited = dir.path().join("edited.csv");
    fs::write(&edited, out).unwrap();
    let model = dir.path().join("pd.json");
    let o = identify("pd", &edited, &model, &["--input-delay", "none"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("u_yaw_rate carries no signal"), "{err}");
    assert!(
        err.contains("warning: u_yaw_rate: the identified static gain is ~0"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&model).unwrap()).unwrap();
    let warnings = v["provenance"]["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w
        .as_str()
        .unwrap()
        .contains("u_yaw_rate: the identified static gain is ~0")));
}
