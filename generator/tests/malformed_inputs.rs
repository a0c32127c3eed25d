//! The figures of docs/testing.md's table "inputs tried per kind, clear errors, panics, hangs,
//! partial files": the `uavgen` binary on a generated set of malformed inputs of every kind
//! (model files, flight logs, plant files, MPC option files, PySINDy exports, CLI values).
//!
//! Each input is written to its own scratch directory, the command's outputs point into it, and
//! the run is classified:
//!
//! - **clear error**: exit status 1 (2 for clap's usage errors), no panic, and stderr names the
//!   input file (for file inputs) and the place: a field (JSON path), a line or a column, or the
//!   option (for CLI values);
//! - **accepted**: exit 0 (a malformed input that went through);
//! - **unclear**: any other failure (wrong status, a message naming neither file nor place);
//! - **panic**: exit 101 or `panicked` on stderr;
//! - **hang**: still running after [`TIMEOUT`] (killed);
//! - **partial file**: anything left in the scratch directory besides the input.
//!
//! The test prints the table (`cargo test --release -p uavgen --test malformed_inputs -- --nocapture`)
//! and fails unless every input is a clear error with no panic, hang or partial file.

mod common;

use common::repo;
use serde_json::{json, Value};
use std::collections::BTreeSet;
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A run still going after this is a hang.
const TIMEOUT: Duration = Duration::from_secs(60);

#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Kind {
    Model,
    Log,
    Plant,
    Mpc,
    Pysindy,
    Cli,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Model => "model files (check and generation)",
            Kind::Log => "flight logs (evaluate, identify)",
            Kind::Plant => "plant files (simulate)",
            Kind::Mpc => "MPC option files (check, generation)",
            Kind::Pysindy => "PySINDy exports (import-pysindy)",
            Kind::Cli => "CLI values (every command)",
        }
    }
}

/// One malformed input: the bytes of its file (`None` for CLI values), the command line
/// (`{in}` is the input's path, `{dir}` the scratch directory) and the places the message must
/// name (any one of them).
struct Case {
    kind: Kind,
    label: String,
    file: Option<(String, Vec<u8>)>,
    args: Vec<String>,
    places: Vec<String>,
}

#[derive(Debug, PartialEq)]
enum Outcome {
    Clear,
    Accepted,
    Unclear(String),
    Panic(String),
    Hang,
}

fn case(kind: Kind, label: impl Into<String>, file: Option<(&str, Vec<u8>)>, args: &[&str], places: &[&str]) -> Case {
    Case {
        kind,
        label: label.into(),
        file: file.map(|(n, b)| (n.to_string(), b)),
        args: args.iter().map(|s| s.to_string()).collect(),
        places: places.iter().map(|s| s.to_string()).collect(),
    }
}

fn read(path: &str) -> String {
    fs::read_to_string(repo().join(path)).unwrap()
}

fn pretty(v: &Value) -> Vec<u8> {
    serde_json::to_vec_pretty(v).unwrap()
}

/// Every numeric leaf of `v` as (JSON path, pointer), skipping the keys in `skip`.
fn numeric_leaves(v: &Value, skip: &[&str]) -> Vec<(String, String)> {
    fn walk(v: &Value, path: String, pointer: String, skip: &[&str], out: &mut Vec<(String, String)>) {
        match v {
            Value::Number(_) => out.push((path, pointer)),
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    walk(x, format!("{path}[{i}]"), format!("{pointer}/{i}"), skip, out);
                }
            }
            Value::Object(m) => {
                for (k, x) in m {
                    if skip.contains(&k.as_str()) {
                        continue;
                    }
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(x, p, format!("{pointer}/{k}"), skip, out);
                }
            }
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk(v, String::new(), String::new(), skip, &mut out);
    out
}

fn with(v: &Value, pointer: &str, new: Value) -> Value {
    let mut v = v.clone();
    *v.pointer_mut(pointer).unwrap() = new;
    v
}

/// Truncations of `text` at a few fractions of its length (syntax errors with a line).
fn truncations(text: &str) -> Vec<(String, Vec<u8>)> {
    [0.1, 0.35, 0.6, 0.9]
        .iter()
        .map(|f| {
            let mut cut = (text.len() as f64 * f) as usize;
            while !text.is_char_boundary(cut) {
                cut -= 1;
            }
            (format!("cut at {:.0} %", f * 100.0), text.as_bytes()[..cut].to_vec())
        })
        .collect()
}

/// Malformed bytes every JSON reader must refuse: empty, not UTF-8, not an object, NaN.
/// The place: a line, or the field (`format`) whose value is NaN; the whole-file problems (not
/// UTF-8, not an object) have no place beyond the file.
fn garbage() -> Vec<(&'static str, Vec<u8>, &'static [&'static str])> {
    vec![
        ("empty file", Vec::new(), &["line"]),
        ("not UTF-8", vec![0xff, 0xfe, b'{', 0x80, b'}'], &["UTF-8", "line"]),
        ("a JSON array", b"[1, 2, 3]".to_vec(), &["object", "line", "expected"]),
        ("NaN literal", b"{\"format\": NaN}".to_vec(), &["line", "format"]),
        ("binary zeros", vec![0u8; 64], &["line"]),
    ]
}

fn model_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let pd: Value = serde_json::from_str(&read("models/pd_hover.json")).unwrap();
    let sindy: Value = serde_json::from_str(&read("models/sindy_m100.json")).unwrap();
    let mut add = |label: String, v: Vec<u8>, places: &[&str]| {
        for (how, args) in [
            ("check", vec!["check", "--model", "{in}"]),
            ("generate", vec!["--model", "{in}", "--out", "{dir}/crate"]),
        ] {
            cases.push(case(
                Kind::Model,
                format!("{label} ({how})"),
                Some(("m.json", v.clone())),
                &args,
                places,
            ));
        }
    };
    // PD: every parameter with values out of range or of the wrong type.
    for (path, pointer) in numeric_leaves(&pd, &["provenance"]) {
        for bad in [json!(1e308), json!(-1e308), json!("x"), json!(null), json!([1])] {
            add(
                format!("pd {path} = {bad}"),
                pretty(&with(&pd, &pointer, bad)),
                &[&path],
            );
        }
    }
    for (path, bad, place) in [
        ("/mass", json!(0), "mass"),
        ("/mass", json!(-2.4), "mass"),
        ("/mass", json!(2e4), "mass"),
        ("/gravity", json!(-9.81), "gravity"),
        ("/gravity", json!(101), "gravity"),
        ("/xi/xi14", json!(0), "xi.xi14"),
        ("/xi/xi15", json!(-0.05), "xi.xi15"),
        ("/xi/xi11", json!(3.0), "xi.xi11"),
        ("/xi/xi12", json!(-1), "xi.xi12"),
        ("/xi/xi4", json!(1e12), "xi.xi4"),
        ("/format", json!("uavgen-model/2"), "format"),
        ("/kind", json!("koopman"), "kind"),
        ("/name", json!("  "), "name"),
        ("/xi", json!([1, 2, 3]), "xi"),
        ("/xi", json!("sixteen"), "xi"),
    ] {
        add(format!("pd {path} = {bad}"), pretty(&with(&pd, path, bad)), &[place]);
    }
    let mut states = pd.clone();
    states["states"] = json!(["x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "p", "q"]);
    add("pd 11 states".into(), pretty(&states), &["states"]);
    states["states"] = json!(["x", "x", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "p", "q", "r"]);
    add("pd duplicate state".into(), pretty(&states), &["states[1]"]);
    let mut unknown = pd.clone();
    unknown["masss"] = json!(2.4);
    add("pd unknown field".into(), pretty(&unknown), &["masss"]);
    let mut missing = pd.clone();
    missing.as_object_mut().unwrap().remove("format");
    add("pd no format".into(), pretty(&missing), &["format"]);
    // SINDy: coefficients, terms, rows.
    for (i, (bad, place)) in [
        (
            json!({"state": "vx", "term": "vx", "coefficient": 1e308}),
            "coefficients[20]",
        ),
        (
            json!({"state": "vq", "term": "vx", "coefficient": 1.0}),
            "coefficients[20].state",
        ),
        (
            json!({"state": "vx", "term": "vx**2", "coefficient": 1.0}),
            "coefficients[20].term",
        ),
        (
            json!({"state": "vx", "term": "tan(vx)", "coefficient": 1.0}),
            "coefficients[20].term",
        ),
        (
            json!({"state": "vx", "term": "vx", "coefficient": "big"}),
            "coefficients[20].coefficient",
        ),
        (
            json!({"state": "x", "term": "vx", "coefficient": 1.0}),
            "coefficients[20]",
        ),
        (json!({"state": "vx", "term": "1"}), "coefficients[20]"),
        (
            json!({"state": "u_vz", "term": "vx", "coefficient": 1.0}),
            "coefficients[20].state",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let mut v = sindy.clone();
        v["coefficients"].as_array_mut().unwrap().push(bad);
        add(format!("sindy bad coefficient {i}"), pretty(&v), &[place]);
    }
    for (i, (term, place)) in [
        ("vx*", "library[47]"),
        ("sin(", "library[47]"),
        ("vx^0", "library[47]"),
        ("1", "library[47]"),
    ]
    .into_iter()
    .enumerate()
    {
        let mut v = sindy.clone();
        let lib = v["library"].as_array_mut().unwrap();
        while lib.len() < 47 {
            lib.push(json!(format!("vx^{}", lib.len() + 100)));
        }
        lib.truncate(47);
        lib.push(json!(term));
        add(format!("sindy bad library term {i}"), pretty(&v), &[place]);
    }
    let mut kin = sindy.clone();
    kin["kinematic"].as_array_mut().unwrap().push(json!(["x", "speed"]));
    add("sindy kinematic to a non-state".into(), pretty(&kin), &["kinematic["]);
    // corrections and envelope.
    for (block, place) in [
        (json!({"linear_drag": {"xy": -0.1}}), "corrections.linear_drag.xy"),
        (json!({"force_bias": [1e300, 0, 0]}), "corrections.force_bias[0]"),
        (json!({"thrust_gain": -1}), "corrections.thrust_gain"),
        (json!({"latency": {"u_thrust": 0.1}}), "corrections.latency.u_thrust"),
        (
            json!({"actuator_lag": {"u_roll": 0}}),
            "corrections.actuator_lag.u_roll",
        ),
        (json!({"wind": 1}), "corrections.wind"),
        (json!([1, 2]), "corrections"),
    ] {
        let mut v = sindy.clone();
        v["corrections"] = block.clone();
        add(format!("corrections {block}"), pretty(&v), &[place]);
    }
    for (block, place) in [
        (json!({"vx": [2, 1]}), "envelope.vx"),
        (json!({"speed": [0, 1]}), "envelope.speed"),
        (json!({"vz": [-1e300, 1]}), "envelope.vz[0]"),
        (json!({"pitch": [-0.5, 2]}), "envelope.pitch"),
        (json!({"vx": [1]}), "envelope.vx"),
        (json!({}), "envelope"),
    ] {
        let mut v = sindy.clone();
        v["envelope"] = block.clone();
        add(format!("envelope {block}"), pretty(&v), &[place]);
    }
    // Syntax: truncated files, garbage, a 1000-state model.
    for (how, bytes) in truncations(&read("models/sindy_m100.json")) {
        add(format!("sindy {how}"), bytes, &["line"]);
    }
    for (how, bytes, place) in garbage() {
        add(how.to_string(), bytes, place);
    }
    let mut big = sindy.clone();
    big["states"] = json!((0..1000).map(|i| format!("s{i}")).collect::<Vec<_>>());
    big["library"] = json!(["1"]);
    big["kinematic"] = json!([]);
    big["coefficients"] = json!([]);
    big.as_object_mut().unwrap().remove("corrections");
    big.as_object_mut().unwrap().remove("envelope");
    add("1000 states".into(), pretty(&big), &["states"]);
    cases
}

/// A valid 150-row log (smooth, varied), as text; `mutate` edits its lines (0: the metadata, 1:
/// the header).
fn log_text() -> Vec<String> {
    let mut lines = vec![
        "# rate_hz: 30".to_string(),
        "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate".to_string(),
    ];
    for k in 0..150 {
        let t = k as f64 / 30.0;
        let row: Vec<String> = (0..17)
            .map(|c| {
                if c == 0 {
                    t
                } else {
                    0.1 * ((c as f64) * 0.37 * t + c as f64).sin() + if c == 3 { 5.0 } else { 0.0 }
                }
            })
            .map(|v| format!("{v:.6}"))
            .collect();
        lines.push(row.join(","));
    }
    lines
}

fn log_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let base = log_text();
    let columns: Vec<&str> = base[1].split(',').collect();
    let mut add = |label: String, lines: Vec<String>, places: &[&str], identify: bool| {
        let bytes = (lines.join("\n") + "\n").into_bytes();
        cases.push(case(
            Kind::Log,
            format!("{label} (evaluate)"),
            Some(("flight.csv", bytes.clone())),
            &[
                "evaluate",
                "--model",
                &repo().join("models/pd_hover.json").display().to_string(),
                "--log",
                "{in}",
                "--json",
                "{dir}/eval.json",
            ],
            places,
        ));
        if identify {
            cases.push(case(
                Kind::Log,
                format!("{label} (identify)"),
                Some(("flight.csv", bytes)),
                &[
                    "identify",
                    "--method",
                    "sindy",
                    "--threshold",
                    "1",
                    "--input-delay",
                    "none",
                    "--log",
                    "{in}",
                    "--out",
                    "{dir}/m.json",
                ],
                places,
            ));
        }
    };
    // A bad value in every column, at line 40 (file line 42).
    for (c, name) in columns.iter().enumerate() {
        for bad in ["abc", "NaN", "inf", "1e300", ""] {
            if c == 0 && bad == "1e300" {
                continue; // a huge time stamp is a time-order error: below
            }
            let mut lines = base.clone();
            let mut fields: Vec<String> = lines[42].split(',').map(String::from).collect();
            fields[c] = bad.to_string();
            lines[42] = fields.join(",");
            add(
                format!("{name} = {bad:?}"),
                lines,
                &["flight.csv:43", name],
                c % 4 == 1 && bad == "abc",
            );
        }
    }
    // Structure.
    for name in ["yaw", "t", "u_vz", "vz"] {
        let mut lines = base.clone();
        lines[1] = lines[1]
            .replacen(&format!(",{name},"), ",other,", 1)
            .replacen(&format!("{name},"), "other,", 1);
        add(format!("column {name} renamed"), lines, &[name], name == "yaw");
    }
    let mut lines = base.clone();
    lines[60] = lines[60].rsplit_once(',').unwrap().0.to_string();
    add("a short row".into(), lines, &["flight.csv:61"], true);
    let mut lines = base.clone();
    lines[61].push_str(",1.0");
    add("a long row".into(), lines, &["flight.csv:62"], false);
    let mut lines = base.clone();
    let t50 = lines[52].split(',').next().unwrap().to_string();
    lines[80] = format!("{t50},{}", lines[80].split_once(',').unwrap().1);
    add("time goes backwards".into(), lines, &["flight.csv:81"], true);
    let mut lines = base.clone();
    lines.truncate(3);
    add("one row".into(), lines, &["flight.csv"], true);
    let mut lines = base.clone();
    lines.truncate(2);
    add("header only".into(), lines, &["flight.csv"], true);
    add("empty".into(), vec![], &["flight.csv"], true);
    let mut lines = base.clone();
    lines[1] = lines[1].replace(',', ";");
    add("semicolons".into(), lines, &["flight.csv"], false);
    let mut lines = base.clone();
    lines[0] = "# rate_hz: fast".into();
    add("bad rate metadata".into(), lines, &["rate_hz"], false);
    let mut lines = base.clone();
    for l in lines.iter_mut().skip(2) {
        let t = l.split(',').next().unwrap().to_string();
        *l = format!("{t}{}", ",0".repeat(16));
    }
    // Degenerate for identify (nothing to fit); evaluate may score a model on it.
    cases.push(case(
        Kind::Log,
        "all-zero states and inputs (identify)",
        Some(("flight.csv", (lines.join("\n") + "\n").into_bytes())),
        &[
            "identify",
            "--method",
            "sindy",
            "--threshold",
            "1",
            "--input-delay",
            "none",
            "--log",
            "{in}",
            "--out",
            "{dir}/m.json",
        ],
        &["flight.csv"],
    ));
    let mut bytes = (base.join("\n") + "\n").into_bytes();
    bytes[300] = 0xff;
    cases.push(case(
        Kind::Log,
        "not UTF-8 (evaluate)",
        Some(("flight.csv", bytes)),
        &[
            "evaluate",
            "--model",
            &repo().join("models/pd_hover.json").display().to_string(),
            "--log",
            "{in}",
        ],
        &["flight.csv"],
    ));
    cases
}

fn plant_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let text = read("plants/m100_like.json");
    let plant: Value = serde_json::from_str(&text).unwrap();
    let args = [
        "simulate",
        "--plant",
        "{in}",
        "--duration",
        "1",
        "--out",
        "{dir}/log.csv",
    ];
    for (path, pointer) in numeric_leaves(&plant, &["provenance"]) {
        for bad in [json!(1e300), json!(-1e300), json!("x")] {
            let v = with(&plant, &pointer, bad.clone());
            cases.push(case(
                Kind::Plant,
                format!("{path} = {bad}"),
                Some(("plant.json", pretty(&v))),
                &args,
                &[&path],
            ));
        }
    }
    for (pointer, bad, place) in [
        ("/vehicle/mass", json!(0), "vehicle.mass"),
        ("/vehicle/mass", json!(-1), "vehicle.mass"),
        ("/integration/rate_hz", json!(0), "integration.rate_hz"),
        ("/integration/substeps", json!(0), "integration.substeps"),
        (
            "/effects/sample_hold/probability",
            json!(1.5),
            "effects.sample_hold.probability",
        ),
        (
            "/effects/latency/per_channel",
            json!([0.1, 0.1]),
            "effects.latency.per_channel",
        ),
        ("/format", json!("uavgen-plant/9"), "format"),
        ("/vehicle/inertia", json!([0.05, 0.05]), "vehicle.inertia"),
    ] {
        let v = with(&plant, pointer, bad.clone());
        cases.push(case(
            Kind::Plant,
            format!("{pointer} = {bad}"),
            Some(("plant.json", pretty(&v))),
            &args,
            &[place],
        ));
    }
    let mut unknown = plant.clone();
    unknown["effects"]["gremlins"] = json!({});
    cases.push(case(
        Kind::Plant,
        "unknown effect",
        Some(("plant.json", pretty(&unknown))),
        &args,
        &["gremlins"],
    ));
    for (how, bytes) in truncations(&text) {
        cases.push(case(Kind::Plant, how, Some(("plant.json", bytes)), &args, &["line"]));
    }
    for (how, bytes, place) in garbage() {
        cases.push(case(Kind::Plant, how, Some(("plant.json", bytes)), &args, place));
    }
    cases
}

fn mpc_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let model = repo().join("models/pd_hover.json").display().to_string();
    let full = json!({
        "q": [2, 2, 2, 0, 0, 1, 0, 0, 0, 0, 0, 0], "q_terminal": [2, 2, 2, 0, 0, 1, 0, 0, 0, 0, 0, 0],
        "r": [0.1, 0.1, 0.1, 10], "u_min": [-5, -0.6, -0.6, -2.6], "u_max": [5, 0.6, 0.6, 2.6],
        "max_qp_iterations": 200, "max_qp_work": 1728000, "max_ipm_iterations": 30, "regularisation": 1e-9
    });
    let mut add = |label: String, bytes: Vec<u8>, places: &[&str], generate: bool| {
        cases.push(case(
            Kind::Mpc,
            format!("{label} (check)"),
            Some(("mpc.json", bytes.clone())),
            &["check", "--model", &model, "--mpc", "{in}"],
            places,
        ));
        if generate {
            cases.push(case(
                Kind::Mpc,
                format!("{label} (generate)"),
                Some(("mpc.json", bytes)),
                &["--model", &model, "--mpc", "{in}", "--out", "{dir}/crate"],
                places,
            ));
        }
    };
    for (path, pointer) in numeric_leaves(&full, &[]) {
        for bad in [json!(1e308), json!("x"), json!(null)] {
            // A null scalar is an absent option (its default), not a malformed one.
            if bad.is_null() && !pointer.chars().last().is_some_and(|c| c.is_ascii_digit()) {
                continue;
            }
            let generate = pointer.ends_with("/0") && bad == json!(1e308);
            add(
                format!("{path} = {bad}"),
                pretty(&with(&full, &pointer, bad)),
                &[&path],
                generate,
            );
        }
    }
    for (pointer, bad, place) in [
        ("/q/0", json!(-1), "q[0]"),
        ("/r/3", json!(-0.1), "r[3]"),
        ("/u_min/0", json!(10), "u_min[0]"),
        ("/q", json!([1, 2, 3]), "q"),
        ("/r", json!([0.1]), "r"),
        ("/max_qp_iterations", json!(0), "max_qp_iterations"),
        ("/max_qp_iterations", json!(-5), "max_qp_iterations"),
        ("/max_qp_iterations", json!(1e9), "max_qp_iterations"),
        ("/max_qp_work", json!(0), "max_qp_work"),
        ("/max_qp_work", json!(-5), "max_qp_work"),
        ("/max_qp_work", json!(4_294_967_296u64), "max_qp_work"),
        ("/regularisation", json!(-1e-9), "regularisation"),
        ("/regularisation", json!(2), "regularisation"),
        ("/u_max", json!("wide"), "u_max"),
    ] {
        add(
            format!("{pointer} = {bad}"),
            pretty(&with(&full, pointer, bad)),
            &[place],
            false,
        );
    }
    let mut unknown = full.clone();
    unknown["horizon"] = json!(30);
    add("unknown field".into(), pretty(&unknown), &["horizon"], true);
    for (how, bytes) in truncations(&serde_json::to_string_pretty(&full).unwrap()) {
        add(how, bytes, &["line"], false);
    }
    for (how, bytes, place) in garbage() {
        add(how.to_string(), bytes, place, false);
    }
    cases
}

fn pysindy_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    let text = read("tests/fixtures/pysindy_export.json");
    let export: Value = serde_json::from_str(&text).unwrap();
    let args = [
        "import-pysindy",
        "--input",
        "{in}",
        "--name",
        "m",
        "--out",
        "{dir}/m.json",
    ];
    let mut add = |label: String, bytes: Vec<u8>, places: &[&str]| {
        cases.push(case(Kind::Pysindy, label, Some(("export.json", bytes)), &args, places));
    };
    for key in ["feature_names", "coefficients", "targets"] {
        let mut v = export.clone();
        v.as_object_mut().unwrap().remove(key);
        add(format!("no {key}"), pretty(&v), &[key]);
        for bad in [json!("x"), json!(null), json!(1)] {
            // serde reports a wrong type at its line and column.
            add(
                format!("{key} = {bad}"),
                pretty(&with(&export, &format!("/{key}"), bad)),
                &[key, "line"],
            );
        }
    }
    for (pointer, bad, place) in [
        // The converted model's place and the value (the export's coefficients[0][1] is the
        // model's first coefficient); wrong types at their line and column.
        ("/coefficients/0/1", json!(1e308), "found 1e308"),
        ("/coefficients/0/1", json!("x"), "line 5, column"),
        ("/coefficients/1/3", json!(null), "line 23, column"),
        ("/coefficients/0", json!([1, 2]), "coefficients[0]"),
        ("/coefficients", json!([vec![0.0; 14]]), "coefficients"),
        // Feature names become the model's library in the same order: library[i] and the term.
        ("/feature_names/4", json!("vx^^2"), "library[4]: bad term syntax"),
        (
            "/feature_names/4",
            json!("tan(vx)"),
            "library[4]: unknown variable 'tan'",
        ),
        ("/feature_names/5", json!("vx"), "library[5]: term 'vx' duplicates"),
        (
            "/feature_names/3",
            json!("u_thrust"),
            "library[3]: unknown variable 'u_thrust'",
        ),
        ("/targets/0", json!("speed"), "'speed' is not a state"),
        ("/targets/1", json!("vx"), "targets[1]"),
        ("/inputs/0", json!("vx"), "inputs"),
        ("/inputs", json!("u"), "line"),
    ] {
        add(
            format!("{pointer} = {bad}"),
            pretty(&with(&export, pointer, bad)),
            &[place],
        );
    }
    for (how, bytes) in truncations(&text) {
        add(how, bytes, &["line"]);
    }
    for (how, bytes, place) in garbage() {
        add(how.to_string(), bytes, place);
    }
    cases
}

fn cli_cases() -> Vec<Case> {
    let model = repo().join("models/pd_hover.json").display().to_string();
    let plant = repo().join("plants/nominal.json").display().to_string();
    let log = "{dir}/../../log.csv"; // written once by the test, beside the scratch directories
    let mut cases = Vec::new();
    let mut add = |label: &str, args: &[&str], place: &str| {
        cases.push(case(Kind::Cli, label, None, args, &[place]));
    };
    for (flag, value) in [
        ("--horizon", "0"),
        ("--horizon", "-1"),
        ("--horizon", "ten"),
        ("--horizon", "100000000"),
        ("--rate", "0"),
        ("--rate", "-30"),
        ("--rate", "NaN"),
        ("--rate", "inf"),
        ("--rate", "1e308"),
        ("--substeps", "0"),
        ("--substeps", "1000000000"),
        ("--float", "f16"),
        ("--qp", "magic"),
        ("--crate-name", "bad name"),
        ("--crate-name", "1abc"),
    ] {
        add(
            &format!("generate {flag} {value}"),
            &["--model", &model, flag, value, "--out", "{dir}/crate"],
            flag,
        );
        if !matches!(flag, "--qp" | "--crate-name") {
            add(
                &format!("check {flag} {value}"),
                &["check", "--model", &model, flag, value],
                flag,
            );
        }
    }
    add("generate without --model", &["--out", "{dir}/crate"], "--model");
    add(
        "generate --out /proc",
        &["--model", &model, "--out", "/proc/uavgen-x"],
        "/proc/uavgen-x",
    );
    add(
        "model file missing",
        &["check", "--model", "{dir}/nope.json"],
        "nope.json",
    );
    for (flag, value) in [
        ("--threshold", "-1"),
        ("--threshold", "NaN"),
        ("--alpha", "1e9"),
        ("--alpha", "-1"),
        ("--savgol-window", "4"),
        ("--savgol-window", "1"),
        ("--savgol-order", "20"),
        ("--input-delay", "1000"),
        ("--input-delay", "abc"),
        ("--input-delay", "u_thrust=0.1"),
        ("--input-delay", "-0.1"),
        ("--method", "neural"),
        ("--mass", "0"),
        ("--mass", "-2"),
        ("--lowpass", "0"),
        ("--sweep-values", "1,-2"),
    ] {
        let method = if matches!(flag, "--mass" | "--lowpass") {
            "pd"
        } else {
            "sindy"
        };
        let mut args = vec!["identify", "--log", log, "--out", "{dir}/m.json"];
        if flag != "--method" {
            args.extend(["--method", method]);
        }
        args.extend([flag, value]);
        add(&format!("identify {flag} {value}"), &args, flag);
    }
    add(
        "identify without --log",
        &["identify", "--method", "sindy", "--out", "{dir}/m.json"],
        "--log",
    );
    add(
        "identify log missing",
        &[
            "identify",
            "--method",
            "sindy",
            "--log",
            "{dir}/nope.csv",
            "--out",
            "{dir}/m.json",
        ],
        "nope.csv",
    );
    for (flag, value) in [
        ("--horizon", "100000"),
        ("--horizon", "0"),
        ("--substeps", "0"),
        ("--stale", "drop"),
    ] {
        add(
            &format!("evaluate {flag} {value}"),
            &[
                "evaluate",
                "--model",
                &model,
                "--log",
                log,
                flag,
                value,
                "--json",
                "{dir}/e.json",
            ],
            flag,
        );
    }
    for (flag, value) in [
        ("--duration", "1e9"),
        ("--duration", "-1"),
        ("--duration", "0"),
        ("--duration", "NaN"),
        ("--profile", "loop-the-loop"),
        ("--seed", "-1"),
    ] {
        let mut args = vec!["simulate", "--plant", &plant, "--out", "{dir}/s.csv", flag, value];
        if flag != "--duration" {
            args.extend(["--duration", "1"]);
        }
        add(&format!("simulate {flag} {value}"), &args, flag);
    }
    for (flag, value) in [
        ("--duration", "0"),
        ("--duration", "1e9"),
        ("--trajectory", "figure8"),
        ("--max-rmse", "-1"),
        ("--max-distance", "0"),
    ] {
        add(
            &format!("track {flag} {value}"),
            &[
                "track", "--model", &model, "--plant", &plant, "--out", "{dir}/t", flag, value,
            ],
            flag,
        );
    }
    add(
        "import --rate 0",
        &[
            "import",
            "{dir}/../../log.csv",
            "--profile",
            "px4",
            "--out",
            "{dir}/i.csv",
            "--rate",
            "0",
        ],
        "--rate",
    );
    add(
        "import unknown preset",
        &[
            "import",
            "{dir}/../../log.csv",
            "--profile",
            "nope",
            "--out",
            "{dir}/i.csv",
        ],
        "nope",
    );
    add(
        "import-pysindy missing input",
        &[
            "import-pysindy",
            "--input",
            "{dir}/nope.json",
            "--name",
            "m",
            "--out",
            "{dir}/m.json",
        ],
        "nope.json",
    );
    add(
        "bench --steps 0",
        &["bench", "--crate", "{dir}/nope", "--steps", "0"],
        "--steps",
    );
    add("envelope without --log", &["envelope", "--model", &model], "--log");
    add("unknown subcommand", &["fly", "--model", &model], "fly");
    cases
}

fn run(case: &Case, dir: &Path) -> (Outcome, Vec<String>) {
    let input = case.file.as_ref().map(|(name, bytes)| {
        let p = dir.join(name);
        fs::write(&p, bytes).unwrap();
        p
    });
    let subst = |a: &str| {
        let a = a.replace("{dir}", &dir.display().to_string());
        match &input {
            Some(p) => a.replace("{in}", &p.display().to_string()),
            None => a,
        }
    };
    let args: Vec<String> = case.args.iter().map(|a| subst(a)).collect();
    let mut child = Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .args(&args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = pipe.read_to_end(&mut s);
        String::from_utf8_lossy(&s).into_owned()
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let err = reader.join().unwrap();
    let left: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| Some(n) != case.file.as_ref().map(|f| &f.0))
        .collect();
    let outcome = match status {
        None => Outcome::Hang,
        Some(s) if s.code() == Some(101) || err.contains("panicked") => Outcome::Panic(err),
        Some(s) if s.success() => Outcome::Accepted,
        Some(s) => {
            let file_named = match &case.file {
                Some((name, _)) => err.contains(name.as_str()),
                None => true,
            };
            let place_named = case.places.iter().any(|p| err.contains(p.as_str()));
            if matches!(s.code(), Some(1) | Some(2)) && file_named && place_named {
                Outcome::Clear
            } else {
                Outcome::Unclear(format!("{:?}: {err}", s.code()))
            }
        }
    };
    (outcome, left)
}

#[test]
fn malformed_inputs_give_clear_errors_and_leave_nothing() {
    let root = tempfile::tempdir().unwrap();
    // A valid log for the CLI-value cases.
    fs::write(root.path().join("log.csv"), log_text().join("\n") + "\n").unwrap();
    let mut cases = model_cases();
    cases.extend(log_cases());
    cases.extend(plant_cases());
    cases.extend(mpc_cases());
    cases.extend(pysindy_cases());
    cases.extend(cli_cases());
    let kinds: BTreeSet<Kind> = cases.iter().map(|c| c.kind).collect();
    let mut rows = Vec::new();
    let mut problems = Vec::new();
    for kind in kinds {
        let (mut tried, mut clear, mut accepted, mut unclear, mut panics, mut hangs, mut partial) =
            (0, 0, 0, 0, 0, 0, 0);
        for (i, c) in cases.iter().filter(|c| c.kind == kind).enumerate() {
            let dir: PathBuf = root.path().join(format!("{kind:?}")).join(format!("{i}"));
            fs::create_dir_all(&dir).unwrap();
            let (outcome, left) = run(c, &dir);
            tried += 1;
            match &outcome {
                Outcome::Clear => clear += 1,
                Outcome::Accepted => accepted += 1,
                Outcome::Unclear(_) => unclear += 1,
                Outcome::Panic(_) => panics += 1,
                Outcome::Hang => hangs += 1,
            }
            if outcome != Outcome::Clear {
                problems.push(format!("{kind:?} '{}': {outcome:?}", c.label));
            }
            if !left.is_empty() {
                partial += 1;
                problems.push(format!("{kind:?} '{}': left {left:?}", c.label));
            }
        }
        rows.push(format!(
            "| {} | {tried} | {clear} | {accepted} | {unclear} | {panics} | {hangs} | {partial} |",
            kind.name()
        ));
    }
    eprintln!("| Input kind | Tried | Clear errors | Accepted (exit 0) | Unclear | Panics | Hangs | Partial files |");
    eprintln!("|---|---|---|---|---|---|---|---|");
    for r in &rows {
        eprintln!("{r}");
    }
    eprintln!("total: {} inputs", cases.len());
    assert!(
        problems.is_empty(),
        "{} problems:\n{}",
        problems.len(),
        problems.join("\n")
    );
}
