//! Older PX4 logs (pyulog's `sample.ulg` era, PX4 v1.5–v1.9): the `px4` preset falls back topic
//! by topic and says which source it used.

use super::*;

/// What the older fixture leaves out.
#[derive(Default)]
struct Older {
    /// No rollspeed/pitchspeed/yawspeed in vehicle_attitude (only the gyro has body rates).
    no_attitude_rates: bool,
    /// No q_d in vehicle_attitude_setpoint (Euler angles only).
    no_q_d: bool,
    /// No vehicle_rates_setpoint.
    no_rates_setpoint: bool,
}

/// The flight as PX4 v1.6–v1.7 logged it: the topics and field names of that schema
/// (`vehicle_attitude` with body rates, `vehicle_local_position_setpoint` without `yawspeed`,
/// `vehicle_rates_setpoint`, `sensor_combined.gyro_rad`), no `vehicle_angular_velocity` and no
/// `trajectory_setpoint`.
fn older_px4_ulog(log: &FlightLog, o: &Older) -> Vec<u8> {
    let mut attitude: Vec<(&str, usize)> = vec![("q", 4)];
    if !o.no_attitude_rates {
        attitude = vec![("rollspeed", 0), ("pitchspeed", 0), ("yawspeed", 0), ("q", 4)];
    }
    let mut setpoint: Vec<(&str, usize)> = vec![
        ("roll_body", 0),
        ("pitch_body", 0),
        ("yaw_body", 0),
        ("yaw_sp_move_rate", 0),
    ];
    if !o.no_q_d {
        setpoint.push(("q_d", 4));
    }
    setpoint.push(("thrust", 0));
    let mut topics = vec![
        Topic::new(
            "vehicle_local_position",
            &[
                ("x", 0),
                ("y", 0),
                ("z", 0),
                ("vx", 0),
                ("vy", 0),
                ("vz", 0),
                ("yaw", 0),
            ],
        ),
        Topic::new("vehicle_attitude", &attitude),
        Topic::new("vehicle_attitude_setpoint", &setpoint),
        Topic::new(
            "vehicle_local_position_setpoint",
            &[
                ("x", 0),
                ("y", 0),
                ("z", 0),
                ("yaw", 0),
                ("vx", 0),
                ("vy", 0),
                ("vz", 0),
                ("acc_x", 0),
                ("acc_y", 0),
                ("acc_z", 0),
            ],
        ),
        Topic::new("sensor_combined", &[("gyro_rad", 3), ("accelerometer_m_s2", 3)]),
        Topic::new("battery_status", &[("voltage_v", 0)]),
    ];
    if !o.no_rates_setpoint {
        topics.push(Topic::new(
            "vehicle_rates_setpoint",
            &[("roll", 0), ("pitch", 0), ("yaw", 0), ("thrust", 0)],
        ));
    }
    let mut w = ULogWriter::new(topics);
    let nan = f64::NAN;
    for s in &log.segments {
        for k in 0..s.len() {
            let t_us = (s.t[k] * 1e6).round() as u64;
            let (x, u) = (s.x[k], s.u[k]);
            let e = [x[3], x[4], x[5]];
            let ned = ned_euler(e);
            w.data(
                "vehicle_local_position",
                t_us,
                &[x[1], x[0], -x[2], x[7], x[6], -x[8], ned[2]],
            );
            let rates = frd_rates([x[9], x[10], x[11]], e);
            let mut a = Vec::new();
            if !o.no_attitude_rates {
                a.extend(rates);
            }
            a.extend(quat(ned));
            w.data("vehicle_attitude", t_us, &a);
            let sp = ned_euler([u[1], u[2], x[5]]);
            let mut v = vec![sp[0], sp[1], sp[2], 0.0];
            if !o.no_q_d {
                v.extend(quat(sp));
            }
            v.push(0.5);
            w.data("vehicle_attitude_setpoint", t_us, &v);
            w.data(
                "vehicle_local_position_setpoint",
                t_us,
                &[nan, nan, nan, nan, nan, nan, -u[0], 0.0, 0.0, 0.0],
            );
            // The gyro: the same body rates, and the specific force of a hover.
            w.data(
                "sensor_combined",
                t_us,
                &[rates[0], rates[1], rates[2], 0.0, 0.0, -9.81],
            );
            if !o.no_rates_setpoint {
                w.data("vehicle_rates_setpoint", t_us, &[0.0, 0.0, -u[3], 0.5]);
            }
            w.data(
                "battery_status",
                t_us,
                &[s.battery_voltage.as_ref().map_or(16.0, |b| b[k])],
            );
        }
    }
    w.bytes
}

fn imported(bytes: &[u8]) -> Result<uavgen::import::Imported, uavgen::import::ImportError> {
    import_bytes("old.ulg", Some(Format::Ulog), bytes, &px4(), &ImportOptions::default())
}

#[test]
fn an_older_px4_log_imports_with_the_px4_preset_and_says_which_topics_it_used() {
    let (_, sim) = simulated();
    let i = imported(&older_px4_ulog(&sim, &Older::default())).unwrap();
    let log = parse_log(&i.to_csv(), "old.csv").unwrap();
    let (dt, dx, du) = max_diff(&sim, &log);
    eprintln!("older PX4 ULog: max |Δt| {dt:e} s, max |Δx| {dx:e}, max |Δu| {du:e}");
    assert!(dt <= 1e-9 && dx <= 1e-9 && du <= 1e-9, "{dt:e} {dx:e} {du:e}");
    let choices = i.choices.join("\n");
    eprintln!("{choices}");
    assert_eq!(i.choices.len(), 9, "{choices}");
    for want in [
        "x, y, z ← `vehicle_local_position` x, y, z",
        "roll_rate, pitch_rate, yaw_rate ← `vehicle_attitude` rollspeed, pitchspeed, yawspeed (source 2 of 3: PX4 v1.5-v1.9)",
        "u_vz ← `vehicle_local_position_setpoint` vz (source 3 of 3: PX4 v1.5-v1.9)",
        "u_roll ← `vehicle_attitude_setpoint` q_d[0], q_d[1], q_d[2], q_d[3] (source 1 of 2)",
        "u_yaw_rate ← `vehicle_rates_setpoint` yaw (source 3 of 3",
        "battery_voltage ← `battery_status` voltage_v",
    ] {
        assert!(choices.contains(want), "{want}\n{choices}");
    }

    // Older still: no rates in vehicle_attitude (the gyro), Euler attitude setpoints.
    let o = Older {
        no_attitude_rates: true,
        no_q_d: true,
        ..Older::default()
    };
    let i = imported(&older_px4_ulog(&sim, &o)).unwrap();
    let log = parse_log(&i.to_csv(), "old.csv").unwrap();
    let (dt, dx, du) = max_diff(&sim, &log);
    assert!(dt <= 1e-9 && dx <= 1e-9 && du <= 1e-9, "{dt:e} {dx:e} {du:e}");
    let choices = i.choices.join("\n");
    assert!(
        choices.contains("yaw_rate ← `sensor_combined` gyro_rad[0], gyro_rad[1], gyro_rad[2] (source 3 of 3"),
        "{choices}"
    );
    assert!(
        choices.contains("u_pitch ← `vehicle_attitude_setpoint` roll_body, pitch_body, yaw_body (source 2 of 2"),
        "{choices}"
    );

    // No source of u_yaw_rate at all: the error lists every one the preset tried.
    let o = Older {
        no_rates_setpoint: true,
        ..Older::default()
    };
    let e = imported(&older_px4_ulog(&sim, &o)).unwrap_err();
    assert_eq!(e.kind, ImportErrorKind::MissingField);
    assert!(
        e.message.starts_with("u_yaw_rate: none of profile `px4`'s sources for `inputs.u_yaw_rate` is in this file: `trajectory_setpoint` (yawspeed): no such topic; `vehicle_local_position_setpoint` has no numeric field `yawspeed` (its fields are `timestamp`, `x`, "),
        "{e}"
    );
    assert!(
        e.message
            .contains("; `vehicle_rates_setpoint` (yaw): no such topic; the file has the topics `battery_status`, "),
        "{e}"
    );

    // The current schema still takes the first source of every channel.
    let i = imported(&px4_ulog(&sim, &Px4Fixture::default()).bytes).unwrap();
    assert!(
        i.choices
            .iter()
            .all(|c| !c.contains("(source 2") && !c.contains("(source 3")),
        "{:?}",
        i.choices
    );
}

#[test]
fn the_cli_prints_the_chosen_sources_on_stderr() {
    let (_, sim) = simulated();
    let tmp = tempfile::tempdir().unwrap();
    let ulg = tmp.path().join("old.ulg");
    std::fs::write(&ulg, older_px4_ulog(&sim, &Older::default())).unwrap();
    let out = tmp.path().join("old.csv");
    let r = import_px4(&ulg, &out);
    assert!(r.status.success(), "{}", stderr(&r));
    let err = stderr(&r);
    assert!(
        err.contains("old.ulg: roll_rate, pitch_rate, yaw_rate ← `vehicle_attitude` rollspeed"),
        "{err}"
    );
    assert!(uavgen::logs::read_log(&out).is_ok());
}

/// Byte offsets of topic `name`'s data records.
fn records(w: &ULogWriter, name: &str) -> Vec<usize> {
    w.data_offsets
        .iter()
        .filter(|(_, n)| n == name)
        .map(|(o, _)| *o)
        .collect()
}

#[test]
fn nan_in_a_state_field_names_topic_field_and_time() {
    let (_, sim) = simulated();
    let w = px4_ulog(&sim, &Px4Fixture::default());
    let t50 = sim.segments[0].t[50];
    // vehicle_local_position's vx (the 4th double after the msg_id and the time stamp).
    let mut bytes = w.bytes.clone();
    let at = records(&w, "vehicle_local_position")[50] + 3 + 2 + 8 + 3 * 8;
    bytes[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = imported(&bytes).unwrap_err();
    assert_eq!(e.kind, ImportErrorKind::BadValue);
    assert_eq!(
        e.message,
        format!("topic `vehicle_local_position`, field `vx` is NaN at t = {t50} s (sample 50 of the topic): the velocity must be a finite number (a state is never skipped or invented)")
    );
    // A NaN quaternion of the attitude is an error too (a setpoint's is skipped).
    let mut bytes = w.bytes.clone();
    let at = records(&w, "vehicle_attitude")[50] + 3 + 2 + 8 + 8;
    bytes[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = imported(&bytes).unwrap_err();
    assert!(
        e.message
            .starts_with(&format!("topic `vehicle_attitude`, field `q[1]` is NaN at t = {t50} s")),
        "{e}"
    );
    // Body rates: infinite.
    let mut bytes = w.bytes.clone();
    let at = records(&w, "vehicle_angular_velocity")[50] + 3 + 2 + 8 + 16;
    bytes[at..at + 8].copy_from_slice(&f64::INFINITY.to_le_bytes());
    let e = imported(&bytes).unwrap_err();
    assert!(
        e.message.starts_with(&format!(
            "topic `vehicle_angular_velocity`, field `xyz[2]` is inf at t = {t50} s"
        )),
        "{e}"
    );
    // The CLI says the same (not "the imported log is invalid").
    let tmp = tempfile::tempdir().unwrap();
    let ulg = tmp.path().join("nan.ulg");
    std::fs::write(&ulg, &bytes).unwrap();
    let out = tmp.path().join("nan.csv");
    let r = import_px4(&ulg, &out);
    assert!(!r.status.success());
    assert!(stderr(&r).contains("field `xyz[2]` is inf at t = "), "{}", stderr(&r));
    assert!(!out.exists());
}

#[test]
fn alternatives_are_validated_and_read_back() {
    // The preset prints and reads back with its `or` lists.
    let p = px4();
    assert_eq!(p.rates.alternatives.len(), 2);
    assert_eq!(Profile::parse(&p.to_json(), "printed").unwrap(), p);
    // Every (topic, field) of every alternative is read from the file.
    let needs = p.needs();
    for want in [
        ("vehicle_attitude", "rollspeed"),
        ("sensor_combined", "gyro_rad[2]"),
        ("vehicle_rates_setpoint", "yaw"),
    ] {
        assert!(needs.contains(&(want.0.to_string(), want.1.to_string())), "{want:?}");
    }
    // An alternative is checked as the channel itself would be, and named by its place.
    let mut v: serde_json::Value = serde_json::from_str(&p.to_json()).unwrap();
    v["rates"]["or"][0]["negate"] = serde_json::json!(["pitch"]);
    let e = Profile::parse(&v.to_string(), "p.json").unwrap_err();
    assert!(
        e.message
            .starts_with("`rates.or[0]`: `rates.negate` is for Euler-angle rates"),
        "{e}"
    );
    // No `or` inside an `or`.
    let mut v: serde_json::Value = serde_json::from_str(&p.to_json()).unwrap();
    let inner = v["rates"]["or"][1].clone();
    v["rates"]["or"][0]["or"] = serde_json::json!([inner]);
    let e = Profile::parse(&v.to_string(), "p.json").unwrap_err();
    assert!(e.message.contains("`rates.or[0]` has an `or` of its own"), "{e}");
}
