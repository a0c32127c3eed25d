//! CSV logs of another schema through an import profile (docs/import.md, "CSV of another schema"):
//! a motion-capture style CSV (ms, mm, degrees, nose-up pitch, `;` and CRLF) made from a simulated
//! flight imports to the same contract log as the flight itself (the hand conversion undone); two
//! files become two segments; a CSV of another schema without a profile says how to map it.

use std::path::Path;
use std::process::Command;
use uavgen::logs::{read_log, FlightLog};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_uavgen")
}

fn repo(rel: &str) -> String {
    format!("{}/../{rel}", env!("CARGO_MANIFEST_DIR"))
}

fn run(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("uavgen runs")
}

/// The flight as a motion-capture export would have it: the template's columns (`--print-profile
/// csv`), time in ms, lengths in mm, angles in degrees, pitch positive nose up.
fn mocap_csv(log: &FlightLog, time_offset_ms: f64) -> String {
    let deg = 180.0 / std::f64::consts::PI;
    let mut out = String::from(
        "# exported by a motion-capture system\r\ntime_ms;x_mm;y_mm;z_mm;vx_mm_s;vy_mm_s;vz_mm_s;roll_deg;pitch_deg;yaw_deg;roll_rate_dps;pitch_rate_dps;yaw_rate_dps;vz_setpoint;roll_setpoint_deg;pitch_setpoint_deg;yaw_rate_setpoint_dps;battery_v;marker_quality\r\n",
    );
    for seg in &log.segments {
        for i in 0..seg.t.len() {
            let (x, u) = (seg.x[i], seg.u[i]);
            let cells = [
                seg.t[i] * 1000.0 + time_offset_ms,
                x[0] * 1000.0,
                x[1] * 1000.0,
                x[2] * 1000.0,
                x[6] * 1000.0,
                x[7] * 1000.0,
                x[8] * 1000.0,
                x[3] * deg,
                -x[4] * deg,
                x[5] * deg,
                x[9] * deg,
                -x[10] * deg,
                x[11] * deg,
                u[0],
                u[1] * deg,
                -u[2] * deg,
                u[3] * deg,
                seg.battery_voltage.as_ref().map_or(0.0, |b| b[i]),
            ];
            let text: Vec<String> = cells.iter().map(|v| format!("{v:e}")).collect();
            out.push_str(&text.join(";"));
            out.push_str(";good\r\n");
        }
    }
    out
}

fn assert_same_flight(a: &FlightLog, b: &FlightLog, what: &str) {
    assert_eq!(a.segments.len(), b.segments.len(), "{what}: segments");
    for (sa, sb) in a.segments.iter().zip(&b.segments) {
        assert_eq!(sa.t.len(), sb.t.len(), "{what}: rows");
        for i in 0..sa.t.len() {
            for j in 0..12 {
                assert!(
                    (sa.x[i][j] - sb.x[i][j]).abs() < 1e-9,
                    "{what}: row {i} state {j}: {} vs {}",
                    sa.x[i][j],
                    sb.x[i][j]
                );
            }
            for j in 0..4 {
                assert!((sa.u[i][j] - sb.u[i][j]).abs() < 1e-9, "{what}: row {i} input {j}");
            }
        }
    }
}

#[test]
fn a_mocap_csv_imports_to_the_flight_it_was_made_from() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        &[
            "simulate",
            "--plant",
            &repo("plants/nano.json"),
            "--duration",
            "6",
            "--seed",
            "4",
            "--out",
            "flight.csv",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let flight = read_log(&dir.path().join("flight.csv")).unwrap();
    std::fs::write(dir.path().join("mocap.csv"), mocap_csv(&flight, 0.0)).unwrap();
    // The template, printed and used as a file (as a user starts from it).
    let template = run(dir.path(), &["import", "--print-profile", "csv"]);
    assert!(template.status.success());
    std::fs::write(dir.path().join("mine.json"), &template.stdout).unwrap();
    let out = run(
        dir.path(),
        &["import", "mocap.csv", "--profile", "mine.json", "--out", "imported.csv"],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let imported = read_log(&dir.path().join("imported.csv")).unwrap();
    assert_same_flight(&flight, &imported, "imported");
    // identify and evaluate read it directly with the profile.
    let out = run(
        dir.path(),
        &[
            "evaluate",
            "--model",
            &repo("models/pd_hover.json"),
            "--log",
            "mocap.csv",
            "--profile",
            "mine.json",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    // Two files (each clock from 0) are two segments, the second shifted after the first.
    std::fs::write(dir.path().join("mocap2.csv"), mocap_csv(&flight, 0.0)).unwrap();
    let out = run(
        dir.path(),
        &[
            "import",
            "mocap.csv",
            "mocap2.csv",
            "--profile",
            "csv",
            "--out",
            "both.csv",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let both = read_log(&dir.path().join("both.csv")).unwrap();
    assert_eq!(both.segments.len(), 2);
    assert!(both.segments[1].t[0] >= flight.segments[0].t.last().unwrap() + 2.0 - 1e-9);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("mocap2.csv: segments 1…1 (times shifted by"),
        "{stdout}"
    );
}

#[test]
fn a_foreign_csv_without_a_profile_says_how_to_map_it() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.csv"), "time_ms,x_mm,y_mm\n0,1,2\n10,1,2\n").unwrap();
    let out = run(
        dir.path(),
        &["evaluate", "--model", &repo("models/pd_hover.json"), "--log", "m.csv"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("missing required columns"), "{err}");
    assert!(err.contains("uavgen import --print-profile csv > my.json"), "{err}");
    // A flight-stack preset on a CSV names the way too.
    let out = run(dir.path(), &["import", "m.csv", "--profile", "px4", "--out", "o.csv"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--print-profile csv"), "{err}");
    // A bad cell of a mapped column names line, column and time.
    let mut text = String::new();
    let header = "time_ms,x_mm,y_mm,z_mm,vx_mm_s,vy_mm_s,vz_mm_s,roll_deg,pitch_deg,yaw_deg,roll_rate_dps,pitch_rate_dps,yaw_rate_dps,vz_setpoint,roll_setpoint_deg,pitch_setpoint_deg,yaw_rate_setpoint_dps,battery_v";
    text.push_str(header);
    text.push('\n');
    text.push_str(&vec!["0"; 18].join(","));
    text.push('\n');
    let mut bad = vec!["10"; 18];
    bad[8] = "";
    text.push_str(&bad.join(","));
    text.push('\n');
    std::fs::write(dir.path().join("bad.csv"), text).unwrap();
    let out = run(dir.path(), &["import", "bad.csv", "--profile", "csv", "--out", "o.csv"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.csv: line 3, column `pitch_deg`: `` is not a finite number (time `time_ms` = 10)"),
        "{err}"
    );
    assert!(!dir.path().join("o.csv").exists());
}

#[test]
fn a_contract_csv_with_cr_line_ends_reads() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        &[
            "simulate",
            "--plant",
            &repo("plants/nominal.json"),
            "--duration",
            "2",
            "--out",
            "f.csv",
        ],
    );
    assert!(out.status.success());
    let text = std::fs::read_to_string(dir.path().join("f.csv")).unwrap();
    std::fs::write(dir.path().join("cr.csv"), text.replace('\n', "\r")).unwrap();
    let a = read_log(&dir.path().join("f.csv")).unwrap();
    let b = read_log(&dir.path().join("cr.csv")).unwrap_or_else(|e| panic!("{e}"));
    assert_same_flight(&a, &b, "CR line ends");
}

/// A contract CSV whose angles are in degrees is refused by the commands that fit or score
/// models, naming the column, the time and the fix; a `# rate_hz` that contradicts the time
/// column is warned about and does not split the log into one-row segments.
#[test]
fn degrees_are_refused_and_a_wrong_rate_is_survived() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        &[
            "simulate",
            "--plant",
            &repo("plants/nominal.json"),
            "--duration",
            "20",
            "--seed",
            "3",
            "--out",
            "f.csv",
        ],
    );
    assert!(out.status.success());
    let flight = read_log(&dir.path().join("f.csv")).unwrap();
    let text = std::fs::read_to_string(dir.path().join("f.csv")).unwrap();
    // The same flight with roll, pitch, yaw and their rates in degrees.
    let deg = 180.0 / std::f64::consts::PI;
    let mut lines = text.lines();
    let mut degrees = String::new();
    let header: Vec<&str> = loop {
        let l = lines.next().unwrap();
        degrees.push_str(l);
        degrees.push('\n');
        if !l.starts_with('#') {
            break l.split(',').collect();
        }
    };
    let angle_cols: Vec<usize> = ["roll", "pitch", "yaw", "roll_rate", "pitch_rate", "yaw_rate"]
        .iter()
        .map(|c| header.iter().position(|h| h == c).unwrap())
        .collect();
    for l in lines {
        let mut cells: Vec<String> = l.split(',').map(str::to_owned).collect();
        for &c in &angle_cols {
            cells[c] = (cells[c].parse::<f64>().unwrap() * deg).to_string();
        }
        degrees.push_str(&cells.join(","));
        degrees.push('\n');
    }
    std::fs::write(dir.path().join("deg.csv"), degrees).unwrap();
    let out = run(
        dir.path(),
        &["evaluate", "--model", &repo("models/pd_hover.json"), "--log", "deg.csv"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("deg.csv: `") && err.contains("the angles look like degrees"),
        "{err}"
    );
    assert!(err.contains("scale` is 0.017453292519943295"), "{err}");
    // The radian flight itself passes the same check (max tilt of `excite` ≈ 0.35 rad).
    uavgen::logs::refuse_degrees(&flight).unwrap();

    // `# rate_hz: 300` on a 30 Hz log: a warning, the segments found from the time column.
    std::fs::write(
        dir.path().join("rate.csv"),
        text.replace("# rate_hz: 30", "# rate_hz: 300"),
    )
    .unwrap();
    let wrong = read_log(&dir.path().join("rate.csv")).unwrap();
    assert_eq!(wrong.segments.len(), flight.segments.len());
    let warnings = wrong.report.warnings().join("\n");
    assert!(
        warnings.contains("gaps and segments are found from the time column"),
        "{warnings}"
    );
    let out = run(
        dir.path(),
        &[
            "evaluate",
            "--model",
            &repo("models/pd_hover.json"),
            "--log",
            "rate.csv",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}
