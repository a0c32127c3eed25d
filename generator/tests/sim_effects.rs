//! The plant simulator (`uavgen::sim`, `uavgen simulate`): hand-checked responses of the nominal
//! plant, every effect measured against its set magnitude, determinism, bad plant files, the
//! CLI, logs that read back, and a SINDy model identified from a simulated log reproducing the
//! nominal plant. Run with `--nocapture` to see the measured figures (docs/simulate.md quotes them).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use uavgen::sim::outer_loop::{OuterLoop, Reference};
use uavgen::sim::plant_file::*;
use uavgen::sim::{simulate, Plant, PlantErrorKind, PlantFile, Profile, SimulateOptions};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_owned()
}

fn plant_file(rel: &str) -> PlantFile {
    PlantFile::load(&repo().join("plants").join(rel)).unwrap_or_else(|e| panic!("{e}"))
}

fn nominal() -> PlantFile {
    plant_file("nominal.json")
}

/// The nominal plant with its effects replaced by `set`.
fn with(set: impl FnOnce(&mut Effects)) -> PlantFile {
    let mut f = nominal();
    set(&mut f.effects);
    f.validate().unwrap_or_else(|e| panic!("{e}"));
    f
}

fn state(pos: [f64; 3], yaw: f64, vel: [f64; 3]) -> [f64; 12] {
    [
        pos[0], pos[1], pos[2], 0.0, 0.0, yaw, vel[0], vel[1], vel[2], 0.0, 0.0, 0.0,
    ]
}

const HOVER: [f64; 4] = [0.0; 4];

/// Run `n` samples with command `u(k)`, returning the true states after each step (index 0 = start).
fn run(p: &mut Plant, n: usize, mut u: impl FnMut(usize) -> [f64; 4]) -> Vec<[f64; 12]> {
    let mut out = vec![p.true_state()];
    for k in 0..n {
        p.step(&u(k));
        out.push(p.true_state());
    }
    out
}

/// Time (s) at which `y` first crosses `level`, linearly interpolated between samples.
fn crossing(y: &[f64], level: f64, dt: f64) -> f64 {
    for k in 1..y.len() {
        if (y[k - 1] - level) * (y[k] - level) <= 0.0 && y[k] != y[k - 1] {
            return (k as f64 - 1.0 + (level - y[k - 1]) / (y[k] - y[k - 1])) * dt;
        }
    }
    f64::NAN
}

fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    sxy / sxx
}

// ------------------------------------------------------------------------------------------
// The nominal plant, by hand.

#[test]
fn nominal_hover_holds_position() {
    let mut p = Plant::new(&nominal(), 1);
    let x0 = state([3.0, 3.0, 5.0], 0.7, [0.0; 3]);
    p.reset(&x0);
    let xs = run(&mut p, 600, |_| HOVER);
    let worst = xs
        .iter()
        .flat_map(|x| x.iter().zip(&x0).map(|(a, b)| (a - b).abs()))
        .fold(0.0, f64::max);
    println!("nominal hover, 20 s: largest state deviation {worst:.2e}");
    assert!(worst < 1e-9);
    assert_eq!(p.measured(), p.true_state(), "no noise without the effect");
    assert_eq!(p.battery_voltage(), 24.6);
    assert!((p.time() - 20.0).abs() < 1e-12 && (p.sample_period() - 1.0 / 30.0).abs() < 1e-15);
}

#[test]
fn vz_step_has_time_constant_one_over_k_vz() {
    let mut p = Plant::new(&nominal(), 1);
    p.reset(&state([0.0, 0.0, 5.0], 0.0, [0.0; 3]));
    let xs = run(&mut p, 90, |_| [1.0, 0.0, 0.0, 0.0]);
    let vz: Vec<f64> = xs.iter().map(|x| x[8]).collect();
    let tau = crossing(&vz, 1.0 - (-1.0f64).exp(), 1.0 / 30.0);
    println!(
        "u_vz step 1 m/s: 63.2 % after {tau:.4} s (1/k_vz = 0.4 s); vz(3 s) = {:.5}",
        vz[90]
    );
    assert!((tau - 0.4).abs() < 0.005, "tau {tau}");
    assert!((vz[90] - 1.0).abs() < 1e-3);
}

#[test]
fn attitude_step_reaches_the_command() {
    let mut p = Plant::new(&nominal(), 1);
    p.reset(&state([0.0, 0.0, 5.0], 0.0, [0.0; 3]));
    let xs = run(&mut p, 90, |_| [0.0, 0.2, -0.1, 0.0]);
    let roll: Vec<f64> = xs.iter().map(|x| x[3]).collect();
    // kp 144, kd 19.2: ωn = 12 rad/s, ζ = 0.8: overshoot e^(−πζ/√(1−ζ²)) = 1.5 %, 50 % at ≈ 0.14 s.
    let over = roll.iter().cloned().fold(f64::MIN, f64::max) / 0.2 - 1.0;
    let half = crossing(&roll, 0.1, 1.0 / 30.0);
    println!(
        "attitude step 0.2 rad: 50 % after {half:.3} s, overshoot {:.2} %, roll(3 s) {:.5}, pitch(3 s) {:.5}",
        100.0 * over,
        roll[90],
        xs[90][4]
    );
    assert!((roll[90] - 0.2).abs() < 1e-4 && (xs[90][4] + 0.1).abs() < 1e-4);
    assert!((0.005..0.03).contains(&over), "overshoot {over}");
    assert!((0.11..0.17).contains(&half), "{half}");
}

// ------------------------------------------------------------------------------------------
// Every effect, measured.

#[test]
fn linear_drag_decelerates_at_the_set_rate_in_body_axes() {
    let f = with(|e| {
        e.linear_drag = Some(LinearDrag {
            coefficients: [0.2, 0.4, 0.5],
        })
    });
    // Yawed by 90°: inertial y is body x, inertial x is body −y.
    for (yaw, vel, axis, d) in [
        (0.0, [3.0, 0.0, 0.0], 6, 0.2),
        (std::f64::consts::FRAC_PI_2, [0.0, 3.0, 0.0], 7, 0.2),
        (std::f64::consts::FRAC_PI_2, [3.0, 0.0, 0.0], 6, 0.4),
    ] {
        let mut p = Plant::new(&f, 1);
        p.reset(&state([0.0, 0.0, 50.0], yaw, vel));
        let xs = run(&mut p, 60, |_| HOVER);
        let t: Vec<f64> = (0..=60).map(|k| k as f64 / 30.0).collect();
        let lnv: Vec<f64> = xs.iter().map(|x| x[axis].ln()).collect();
        let measured = -slope(&t, &lnv);
        println!("linear drag: set {d} 1/s, measured deceleration / speed {measured:.4} 1/s (yaw {yaw:.2})");
        assert!((measured - d).abs() < 0.01 * d, "{measured} vs {d}");
    }
    // Vertically the vz loop adds its own k_vz: vz decays at k_vz + d_z = 3.0 1/s.
    let mut p = Plant::new(&f, 1);
    p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0, 0.0, 1.0]));
    let xs = run(&mut p, 15, |_| HOVER);
    let lnv: Vec<f64> = xs.iter().map(|x| x[8].ln()).collect();
    let t: Vec<f64> = (0..=15).map(|k| k as f64 / 30.0).collect();
    let rate = -slope(&t, &lnv);
    println!("linear drag z: vz decays at {rate:.4} 1/s (k_vz + d_z = 3.0)");
    assert!((rate - 3.0).abs() < 0.03);
}

#[test]
fn quadratic_drag_follows_one_over_v() {
    let c = 0.04;
    let f = with(|e| {
        e.quadratic_drag = Some(QuadraticDrag {
            coefficients: [c, c, 2.0 * c],
        })
    });
    let mut p = Plant::new(&f, 1);
    p.reset(&state(
        [0.0, 0.0, 50.0],
        0.3,
        [4.0 * 0.3f64.cos(), 4.0 * 0.3f64.sin(), 0.0],
    ));
    let xs = run(&mut p, 150, |_| HOVER);
    // v̇ = −c v² → 1/v = 1/v0 + c t.
    let t: Vec<f64> = (0..=150).map(|k| k as f64 / 30.0).collect();
    let inv: Vec<f64> = xs.iter().map(|x| 1.0 / x[6].hypot(x[7])).collect();
    let measured = slope(&t, &inv);
    println!("quadratic drag: set {c} 1/m, measured d(1/v)/dt {measured:.5} 1/m");
    assert!((measured - c).abs() < 0.01 * c);
}

/// The lag (samples) of the peak of the cross-correlation between u_roll and the roll response
/// under a random (white, ±0.1 rad, one value per sample) roll command at hover.
fn roll_xcorr_peak(f: &PlantFile) -> usize {
    let mut p = Plant::new(f, 3);
    p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0; 3]));
    let mut rng = uavgen::sim::rng::Random::new(11, uavgen::sim::rng::Stream::Profile, 0);
    let n = 1800;
    let u: Vec<f64> = (0..n).map(|_| rng.range(-0.1, 0.1)).collect();
    let xs = run(&mut p, n, |k| [0.0, u[k], 0.0, 0.0]);
    let roll: Vec<f64> = xs.iter().map(|x| x[3]).collect();
    let xc: Vec<f64> = (0..20)
        .map(|lag| (0..n - 20).map(|k| u[k] * roll[k + lag]).sum::<f64>())
        .collect();
    (0..20).max_by(|a, b| xc[*a].total_cmp(&xc[*b])).unwrap()
}

#[test]
fn latency_shifts_the_cross_correlation_peak() {
    let base = roll_xcorr_peak(&nominal());
    for delay in [0.1, 0.2] {
        let f = with(|e| {
            e.latency = Some(Latency {
                delay: Some(delay),
                per_channel: None,
            })
        });
        let peak = roll_xcorr_peak(&f);
        let shift = peak as f64 - base as f64;
        println!(
            "latency {delay} s: u_roll → roll cross-correlation peak at lag {peak} (nominal {base}), shift {shift} samples = {:.3} s",
            shift / 30.0
        );
        assert!((shift - delay * 30.0).abs() <= 1.0, "shift {shift}");
    }
    // Per channel: only u_vz delayed, so roll is not.
    let f = with(|e| {
        e.latency = Some(Latency {
            delay: None,
            per_channel: Some([0.2, 0.0, 0.0, 0.0]),
        })
    });
    assert_eq!(roll_xcorr_peak(&f), base);
}

#[test]
fn payload_makes_the_vehicle_sink_in_proportion_to_the_mass_error() {
    for extra in [0.3, 0.6, -0.3] {
        let f = with(|e| e.payload = Some(Payload { mass: extra }));
        let mut p = Plant::new(&f, 1);
        p.reset(&state([0.0, 0.0, 100.0], 0.0, [0.0; 3]));
        let xs = run(&mut p, 150, |_| HOVER);
        // m̂ (g − k_vz vz) = (m̂ + Δm) g  →  vz = −g Δm / (m̂ k_vz).
        let expected = -9.81 * extra / (2.9 * 2.5);
        let vz = xs[150][8];
        println!("payload {extra:+} kg: steady vz {vz:.5} m/s at u_vz = 0 (expected {expected:.5})");
        assert!((vz - expected).abs() < 0.005 * expected.abs());
    }
}

#[test]
fn battery_sag_lowers_the_voltage_and_the_thrust() {
    let f = plant_file("effects/battery_sag.json");
    let mut p = Plant::new(&f, 1);
    p.reset(&state([0.0, 0.0, 500.0], 0.0, [0.0; 3]));
    let mut volts = vec![p.battery_voltage()];
    let xs = run(&mut p, 5400, |_| HOVER);
    volts.push(p.battery_voltage());
    let (v0, rate): (f64, f64) = (24.6, 0.006);
    for (k, t) in [(900, 30.0), (5400, 180.0)] {
        let factor = ((v0 - rate * t) / v0).powi(2);
        // f m̂ (g − k_vz vz) = m̂ g  →  vz = −g (1/f − 1) / k_vz (quasi-steady).
        let expected = -9.81 * (1.0 / factor - 1.0) / 2.5;
        println!(
            "battery sag: t = {t} s: V = {:.3} V, thrust factor {factor:.4}, vz {:.4} m/s (quasi-steady {expected:.4})",
            v0 - rate * t,
            xs[k][8]
        );
        assert!((xs[k][8] - expected).abs() < 0.02 * expected.abs() + 1e-3);
    }
    assert!((volts[0] - 24.6).abs() < 1e-12 && (volts[1] - (24.6 - 0.006 * 180.0)).abs() < 1e-9);
    // The logged column falls at the set rate.
    let log = simulate(&f, &SimulateOptions::new(vec![Profile::Hover], vec![60.0], 1)).unwrap();
    let t: Vec<f64> = log.rows.iter().map(|r| r.t).collect();
    let v: Vec<f64> = log.rows.iter().map(|r| r.battery_voltage).collect();
    let s = slope(&t, &v);
    println!("battery sag: logged voltage slope {s:.6} V/s (set −0.006)");
    assert!((s + 0.006).abs() < 1e-9);
}

#[test]
fn ground_effect_increases_climb_near_the_ground() {
    let f = plant_file("effects/ground_effect.json");
    let climb = |f: &PlantFile, z: f64| {
        let mut p = Plant::new(f, 1);
        p.reset(&state([0.0, 0.0, z], 0.0, [0.0; 3]));
        p.step(&HOVER);
        p.true_state()[8] * 30.0 // mean vertical acceleration over the first sample
    };
    let r: f64 = 0.1651;
    for z in [0.15, 0.3, 0.6] {
        let ratio = 1.0 / (1.0 - (r / (4.0 * z)).powi(2));
        // With the vz loop: a = (ratio − 1) g at first, reduced by k_vz ratio vz over the sample.
        let expected = (ratio - 1.0) * 9.81;
        let a = climb(&f, z);
        println!("ground effect at z = {z} m: ratio {ratio:.4}, first-sample climb acceleration {a:.4} m/s² ((ratio − 1) g = {expected:.4})");
        assert!(a > 0.9 * expected && a < expected, "{a} vs {expected}");
        assert_eq!(climb(&nominal(), z), 0.0);
    }
    // Hovering at u_vz = 0 from z = 0.15 m the vehicle climbs out of ground effect.
    let mut p = Plant::new(&f, 1);
    p.reset(&state([0.0, 0.0, 0.15], 0.0, [0.0; 3]));
    let xs = run(&mut p, 150, |_| HOVER);
    println!(
        "ground effect: from z = 0.15 m at u_vz = 0, z after 5 s = {:.3} m",
        xs[150][2]
    );
    assert!(xs[150][2] > 0.25);
}

/// Time to 50 % of a unit step of the linearised loop with the motor lag τ on its output:
/// attitude φ⁽³⁾τ + φ̈ = kp (1 − φ) − kd φ̇ (`kd = Some`), or vertical τ v̈ + v̇ = k (1 − v).
fn linear_half_time(kp: f64, kd: Option<f64>, tau: f64) -> f64 {
    let h = 1e-5;
    let (mut y, mut yd, mut act, mut t) = (0.0, 0.0, 0.0, 0.0);
    loop {
        let cmd = match kd {
            Some(kd) => kp * (1.0 - y) - kd * yd,
            None => kp * (1.0 - y),
        };
        act = if tau > 0.0 { act + h * (cmd - act) / tau } else { cmd };
        match kd {
            Some(_) => {
                yd += h * act;
                y += h * yd;
            }
            None => y += h * act,
        }
        t += h;
        if y >= 0.5 {
            return t;
        }
    }
}

#[test]
fn motor_lag_slows_the_response() {
    let tau = 0.04;
    let lag = with(|e| e.motor_lag = Some(MotorLag { time_constant: tau }));
    let half = |f: &PlantFile, u: [f64; 4], i: usize, level: f64| {
        let mut p = Plant::new(f, 1);
        p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0; 3]));
        let xs = run(&mut p, 60, |_| u);
        let y: Vec<f64> = xs.iter().map(|x| x[i]).collect();
        crossing(&y, level, 1.0 / 30.0)
    };
    for (name, u, i, level, kp, kd) in [
        ("roll", [0.0, 0.2, 0.0, 0.0], 3, 0.1, 144.0, Some(19.2)),
        ("vz", [1.0, 0.0, 0.0, 0.0], 8, 0.5, 2.5, None),
    ] {
        let (a, b) = (half(&nominal(), u, i, level), half(&lag, u, i, level));
        let expected = linear_half_time(kp, kd, tau) - linear_half_time(kp, kd, 0.0);
        println!(
            "motor lag {tau} s: {name} step 50 % after {b:.4} s (nominal {a:.4} s): slower by {:.4} s (linearised loop: {expected:.4} s)",
            b - a
        );
        assert!(
            b - a > 0.0 && (b - a - expected).abs() < 0.003,
            "{name}: {a} {b} {expected}"
        );
    }
}

#[test]
fn wind_with_drag_gives_a_steady_drift_and_tilt() {
    let (d, w) = (0.27, 3.0);
    let f = with(|e| {
        e.linear_drag = Some(LinearDrag {
            coefficients: [d, d, 0.53],
        });
        e.wind = Some(Wind {
            velocity: [w, 0.0, 0.0],
            turbulence: None,
            direct_coefficient: [0.0; 3],
        });
    });
    // Open loop (level, u = 0): the vehicle drifts with the wind, time constant 1/d.
    let mut p = Plant::new(&f, 1);
    p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0; 3]));
    let xs = run(&mut p, 450, |_| HOVER);
    let expected = w * (1.0 - (-d * 15.0f64).exp());
    println!(
        "wind 3 m/s + drag 0.27: open-loop drift vx(15 s) = {:.4} m/s (expected {expected:.4})",
        xs[450][6]
    );
    assert!((xs[450][6] - expected).abs() < 0.01);
    // Position hold: the vehicle leans into the wind, tan θ = d w / g, and sits d w / kp downwind.
    let hold = OuterLoop::tracking(9.81);
    let r = Reference {
        p: [0.0, 0.0, 50.0],
        ..Reference::default()
    };
    let mut p = Plant::new(&f, 1);
    p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0; 3]));
    for _ in 0..900 {
        let y = p.measured();
        p.step(&hold.command(&y, &r));
    }
    let x = p.true_state();
    let tilt = -(d * w / 9.81).atan();
    println!(
        "wind + drag, position hold: pitch {:.5} rad (atan(d w / g) = {:.5}), offset {:.4} m downwind (d w / kp = {:.4})",
        x[4],
        -tilt,
        x[0],
        d * w / hold.kp
    );
    assert!((x[4] - tilt).abs() < 0.02 * tilt.abs());
    assert!((x[0] - d * w / hold.kp).abs() < 0.02);
    // Wind without drag acts through the direct coefficient only (plants/effects/wind.json).
    let f = plant_file("effects/wind.json");
    let mut p = Plant::new(&f, 5);
    p.reset(&state([0.0, 0.0, 50.0], 0.0, [0.0; 3]));
    let xs = run(&mut p, 300, |_| HOVER);
    println!(
        "wind.json (direct force, turbulence): vx(10 s) = {:.3}, vy(10 s) = {:.3} m/s",
        xs[300][6], xs[300][7]
    );
    assert!(xs[300][6] > 3.0 && xs[300][7] > 1.0);
}

#[test]
fn sensor_noise_has_the_set_sigma_on_high_pass_residuals() {
    let f = plant_file("effects/sensor_noise.json");
    let mut p = Plant::new(&f, 9);
    p.reset(&state([0.0, 0.0, 5.0], 0.0, [0.0; 3]));
    let mut ys = Vec::new();
    let mut volts = Vec::new();
    for _ in 0..6000 {
        p.step(&HOVER);
        ys.push(p.measured());
        volts.push(p.battery_voltage());
    }
    // Second differences of white noise have variance 6 σ².
    let sigma_of = |y: &[f64]| {
        let d2: Vec<f64> = y.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
        (d2.iter().map(|v| v * v).sum::<f64>() / d2.len() as f64 / 6.0).sqrt()
    };
    let groups = [
        ("pos", 0..3, 0.02),
        ("att", 3..6, 0.003),
        ("vel", 6..9, 0.02),
        ("rate", 9..12, 0.01),
    ];
    for (name, range, set) in groups {
        for i in range {
            let y: Vec<f64> = ys.iter().map(|x| x[i]).collect();
            let s = sigma_of(&y);
            println!("sensor noise {name} state {i}: set {set}, high-pass sigma {s:.5}");
            assert!((s / set - 1.0).abs() < 0.05, "{name} {i}: {s}");
        }
    }
    let s = sigma_of(&volts);
    println!("sensor noise volt: set 0.02, high-pass sigma {s:.5}");
    assert!((s / 0.02 - 1.0).abs() < 0.05);
    // The autopilot flies the true state: it did not move.
    assert!((p.true_state()[2] - 5.0).abs() < 1e-9);
}

#[test]
fn sample_hold_repeats_the_set_fraction_of_rows() {
    for (p, max_run, expected) in [(0.43, Some(1), 0.43 / 1.43), (0.3, None, 0.3)] {
        let f = with(|e| {
            e.sample_hold = Some(SampleHold {
                probability: p,
                max_run,
            })
        });
        let log = simulate(&f, &SimulateOptions::new(vec![Profile::Excite], vec![120.0], 4)).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("held.csv");
        log.write(&path).unwrap();
        let read = uavgen::logs::read_log(&path).unwrap();
        let fraction = read.report.stale_fraction();
        let longest = read.report.longest_stale_run();
        println!(
            "sample hold p = {p}, max_run {max_run:?}: {:.4} of the rows repeat (expected {expected:.4}), longest run {longest}",
            fraction
        );
        assert!((fraction - expected).abs() < 0.03, "{fraction}");
        if max_run == Some(1) {
            assert_eq!(longest, 1);
        }
        assert_eq!(read.report.stale_states(), log.rows.iter().filter(|r| r.held).count());
    }
}

// ------------------------------------------------------------------------------------------
// Files, determinism, logs.

#[test]
fn shipped_effect_files_are_nominal_plus_one_effect() {
    let base = nominal();
    assert!(base.effects.active().is_empty());
    for name in EFFECT_NAMES {
        let f = plant_file(&format!("effects/{name}.json"));
        assert_eq!(f.effects.active(), vec![name], "{name}");
        assert_eq!(
            (&f.vehicle, &f.autopilot, &f.integration),
            (&base.vehicle, &base.autopilot, &base.integration),
            "{name}"
        );
    }
    let m = plant_file("m100_like.json");
    println!("m100_like effects: {:?}", m.effects.active());
    assert!(m.effects.latency.is_some() && m.effects.sample_hold.is_some() && m.effects.sensor_noise.is_some());
}

#[test]
fn same_seed_same_bytes_different_seed_differs() {
    for rel in ["m100_like.json", "effects/wind.json", "nominal.json"] {
        let f = plant_file(rel);
        let opts = |seed| SimulateOptions::new(vec![Profile::Excite, Profile::Circle], vec![20.0, 10.0], seed);
        let a = simulate(&f, &opts(5)).unwrap().to_csv();
        let b = simulate(&f, &opts(5)).unwrap().to_csv();
        let c = simulate(&f, &opts(6)).unwrap().to_csv();
        assert_eq!(a, b, "{rel}");
        assert_ne!(a, c, "{rel}");
        // Only the excite segment is random in the nominal plant: the circle rows agree.
        if rel == "nominal.json" {
            let circle = |s: &str| {
                s.lines()
                    .filter(|l| l.ends_with(",1"))
                    .map(str::to_owned)
                    .collect::<Vec<_>>()
            };
            assert_eq!(circle(&a), circle(&c));
        }
    }
    // The plant alone, too.
    let f = plant_file("m100_like.json");
    let go = |seed| {
        let mut p = Plant::new(&f, seed);
        p.reset(&state([0.0, 0.0, 5.0], 0.0, [0.0; 3]));
        (0..100)
            .map(|_| {
                p.step(&[0.1, 0.05, 0.0, 0.1]);
                p.measured()
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(go(1), go(1));
    assert_ne!(go(1), go(2));
}

#[test]
fn simulated_logs_read_back() {
    let f = plant_file("m100_like.json");
    let opts = SimulateOptions::new(Profile::ALL.to_vec(), vec![30.0, 10.0, 10.0, 10.0, 10.0, 10.0], 3);
    let log = simulate(&f, &opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.csv");
    log.write(&path).unwrap();
    let read = uavgen::logs::read_log(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(read.segments.len(), 6);
    assert_eq!(read.rows(), log.rows.len());
    assert_eq!(read.meta("format"), Some("uavgen flight log v1"));
    assert_eq!(read.meta("rate_hz"), Some("30"));
    assert_eq!(
        read.meta("profile"),
        Some("excite,excite-hold-heading,hover,circle,sinusoid,spiral")
    );
    assert_eq!(read.meta("seed"), Some("3"));
    assert!(read.meta("plant").unwrap().ends_with("m100_like.json"));
    assert!(read.segments.iter().all(|s| s.battery_voltage.is_some()));
    assert!(
        read.report.warnings().iter().all(|w| !w.contains("irregular")),
        "{:?}",
        read.report.warnings()
    );
    // Yaw is written wrapped and read back unwrapped: it matches the simulator's continuous yaw
    // up to whole turns per segment.
    for (seg, rows) in read.segments.iter().zip(log.segments.iter().scan(0, |start, s| {
        let r = &log.rows[*start..*start + s.rows];
        *start += s.rows;
        Some(r)
    })) {
        let turns = ((rows[0].x[5] - seg.x[0][5]) / std::f64::consts::TAU).round();
        for (a, b) in seg.x.iter().zip(rows) {
            assert!((a[5] + turns * std::f64::consts::TAU - b.x[5]).abs() < 2e-6);
        }
    }
    // Every profile flies where the docs say.
    for s in &log.segments {
        println!(
            "{:<8} z {:.2}..{:.2} m, max |x|,|y| {:.2} m, tilt ≤ {:.3} rad, speed ≤ {:.2} m/s",
            s.profile, s.min_z, s.max_z, s.max_abs_xy, s.max_tilt_rad, s.max_speed
        );
        assert!(s.max_abs_xy < 9.0 && s.min_z > 0.1 && s.max_z < 12.0, "{s:?}");
    }
}

#[test]
fn excite_stays_in_its_box_and_visits_the_ground() {
    let f = nominal();
    for seed in [1, 2, 3] {
        let log = simulate(&f, &SimulateOptions::new(vec![Profile::Excite], vec![180.0], seed)).unwrap();
        let s = &log.segments[0];
        let low = log.rows.iter().filter(|r| r.true_x[2] < 1.0).count() as f64 / log.rows.len() as f64;
        println!(
            "excite seed {seed}: z {:.2}..{:.2} m, max |x|,|y| {:.2} m, tilt ≤ {:.3} rad, speed ≤ {:.2} m/s, {:.1} % below 1 m",
            s.min_z,
            s.max_z,
            s.max_abs_xy,
            s.max_tilt_rad,
            s.max_speed,
            100.0 * low
        );
        assert!(s.max_abs_xy < 8.0 && s.min_z > 0.02 && s.max_z < 12.0 && s.max_tilt_rad < 0.42 && s.max_speed < 5.0);
        assert!(low > 0.01, "no low-altitude time");
    }
}

// ------------------------------------------------------------------------------------------
// Bad input.

#[test]
fn bad_plant_files_name_the_field() {
    let text = std::fs::read_to_string(repo().join("plants/nominal.json")).unwrap();
    let cases = [
        (
            "\"mass\": 2.9",
            "\"mass\": -2.9",
            "vehicle.mass",
            PlantErrorKind::OutOfRange,
        ),
        (
            "\"mass\": 2.9",
            "\"mass\": NaN",
            "vehicle.mass",
            PlantErrorKind::NonFinite,
        ),
        (
            "\"k_vz\": 2.5",
            "\"k_vz\": Infinity",
            "autopilot.k_vz",
            PlantErrorKind::NonFinite,
        ),
        (
            "\"effects\": {}",
            "\"effects\": { \"turbulence\": { \"sigma\": 1 } }",
            "effects.turbulence",
            PlantErrorKind::UnknownEffect,
        ),
        (
            "\"gravity\": 9.81,",
            "\"gravity\": 9.81, \"colour\": \"red\",",
            "vehicle.colour",
            PlantErrorKind::UnknownField,
        ),
        (
            "\"rate_hz\": 30.0",
            "\"rate_hz\": 0",
            "integration.rate_hz",
            PlantErrorKind::OutOfRange,
        ),
        (
            "\"effects\": {}",
            "\"effects\": { \"sample_hold\": { \"probability\": -0.1 } }",
            "effects.sample_hold.probability",
            PlantErrorKind::OutOfRange,
        ),
    ];
    for (from, to, field, kind) in cases {
        assert!(text.contains(from), "{from}");
        let e = PlantFile::parse(&text.replacen(from, to, 1), "bad.json").unwrap_err();
        println!("{e}");
        assert_eq!((e.field.as_str(), e.kind), (field, kind));
        assert!(e.to_string().starts_with("bad.json: ") && e.to_string().contains(field));
    }
    let e = PlantFile::load(Path::new("/nonexistent/plant.json")).unwrap_err();
    assert_eq!(e.kind, PlantErrorKind::Io);
}

fn uavgen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("runs uavgen")
}

#[test]
fn cli_simulates_and_refuses_bad_input_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("log.csv");
    let o = uavgen(&[
        "simulate",
        "--plant",
        "plants/effects/latency.json",
        "--profile",
        "excite,circle",
        "--duration",
        "10,5",
        "--seed",
        "7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("450 rows in 2 segments"), "{stdout}");
    let first = std::fs::read(&out).unwrap();
    let log = uavgen::logs::read_log(&out).unwrap();
    assert_eq!((log.segments.len(), log.rows()), (2, 450));
    // An existing file is refused without --force, and kept.
    let again = |extra: &[&str]| {
        let mut args = vec![
            "simulate",
            "--plant",
            "plants/effects/latency.json",
            "--profile",
            "excite,circle",
            "--duration",
            "10,5",
            "--seed",
            "7",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        uavgen(&args)
    };
    let o = again(&[]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--force"));
    assert!(again(&["--force"]).status.success());
    assert_eq!(std::fs::read(&out).unwrap(), first, "deterministic");

    let bad_plant = dir.path().join("bad.json");
    std::fs::write(
        &bad_plant,
        std::fs::read_to_string(repo().join("plants/nominal.json"))
            .unwrap()
            .replacen("\"mass\": 2.9", "\"mass\": -1", 1),
    )
    .unwrap();
    let never = dir.path().join("never.csv");
    let plant = bad_plant.to_str().unwrap();
    for (args, needle) in [
        (vec!["--plant", plant], "vehicle.mass"),
        (
            vec![
                "--plant",
                "plants/nominal.json",
                "--profile",
                "excite,loop",
                "--duration",
                "1,1",
            ],
            "unknown profile `loop`",
        ),
        (
            vec![
                "--plant",
                "plants/nominal.json",
                "--profile",
                "excite,circle",
                "--duration",
                "10",
            ],
            "1 durations for 2 profiles",
        ),
        (
            vec!["--plant", "plants/nominal.json", "--duration", "0"],
            "must be positive",
        ),
        (
            vec!["--plant", "plants/nominal.json", "--duration=-5"],
            "must be positive",
        ),
        (vec!["--plant", "plants/no_such_plant.json"], "cannot read"),
    ] {
        let mut full = vec!["simulate"];
        full.extend(args);
        full.extend(["--out", never.to_str().unwrap()]);
        let o = uavgen(&full);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{full:?}");
        assert!(err.contains(needle), "{full:?}: {err}");
        assert!(!never.exists());
    }
    // Only log.csv and bad.json: no temporary files left.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

// ------------------------------------------------------------------------------------------
// Identification reproduces the nominal plant.

#[test]
fn nominal_plant_is_reproduced_by_a_model_identified_from_it() {
    use uavgen::evaluate::{evaluate, EvaluateOptions};
    use uavgen::identify::dataset::{build, DatasetOptions};
    use uavgen::identify::sindy::{self, Optimizer, SindyOptions};

    let dir = tempfile::tempdir().unwrap();
    // Training: nominal + sensor noise (the RotorPy sigmas), excite, 180 s.
    let noisy = plant_file("effects/sensor_noise.json");
    let train_path = dir.path().join("train.csv");
    simulate(&noisy, &SimulateOptions::new(vec![Profile::Excite], vec![180.0], 101))
        .unwrap()
        .write(&train_path)
        .unwrap();
    // Test: the nominal plant without noise, another seed.
    let test_path = dir.path().join("test.csv");
    simulate(
        &nominal(),
        &SimulateOptions::new(vec![Profile::Excite], vec![60.0], 202),
    )
    .unwrap()
    .write(&test_path)
    .unwrap();
    let train = uavgen::logs::read_log(&train_path).unwrap();
    let test = uavgen::logs::read_log(&test_path).unwrap();

    // SINDy, physics library (exact kinematic rows), STLSQ with threshold 10 on normalised columns
    // (the setting docs/identification.md uses on the M100 logs).
    let dataset = build(std::slice::from_ref(&train), &DatasetOptions::default()).unwrap();
    let options = SindyOptions {
        optimizer: Optimizer::Stlsq {
            threshold: 10.0,
            alpha: 1e-3,
            max_iter: 20,
            unbias: true,
        },
        ..SindyOptions::default()
    };
    let fit = sindy::fit(&dataset, &options, "sim_nominal", serde_json::json!({"data": "sim"})).unwrap();
    for row in &fit.rows {
        println!(
            "identified {:<10} {:>2} terms, training RMSE {:.4}",
            row.state, row.terms, row.rmse
        );
    }
    let model = uavgen::model::parse(&fit.to_json(), "sim_nominal.json").unwrap();
    let eval = evaluate(&model, &[test], &EvaluateOptions::default()).unwrap();
    let m = eval.one_step_next.metrics.unwrap();
    let sigma_vel = 0.02;
    for (name, rmse) in m.names.iter().zip(&m.rmse) {
        println!("one-step next-sample RMSE {name:<10} {rmse:.5}");
    }
    for v in ["vx", "vy", "vz"] {
        let i = m.names.iter().position(|n| n == v).unwrap();
        assert!(
            m.rmse[i] < sigma_vel,
            "{v}: one-step RMSE {} is not below the velocity noise sigma {sigma_vel}",
            m.rmse[i]
        );
    }
}

/// The noise-free copy of a log (the self-check's reference): the true states row for row, the
/// held rows still repeating the row before, everything else as flown.
#[test]
fn noise_free_copy_keeps_the_flight_and_its_held_rows() {
    let mut p = plant_file("effects/sample_hold.json");
    p.effects.sensor_noise = plant_file("effects/sensor_noise.json").effects.sensor_noise;
    let log = simulate(&p, &SimulateOptions::new(vec![Profile::Excite], vec![10.0], 4)).unwrap();
    let clean = log.noise_free();
    assert_eq!(clean.rows.len(), log.rows.len());
    let held = log.rows.iter().filter(|r| r.held).count();
    assert!(held > 50, "{held} held rows");
    for (k, (a, b)) in log.rows.iter().zip(&clean.rows).enumerate() {
        assert_eq!((a.t, a.u, a.held, a.true_x), (b.t, b.u, b.held, b.true_x), "row {k}");
        if b.held && k > 0 {
            assert_eq!(b.x, clean.rows[k - 1].x, "row {k}: held");
        } else {
            assert_eq!(b.x, b.true_x, "row {k}: true states");
            assert_ne!(a.x, b.x, "row {k}: the log as flown has noise");
        }
    }
}

/// `excite-hold-heading` keeps the heading where it started and leaves the yaw channel silent, while
/// the other channels are excited as by `excite` (the unexcited-direction case of identification).
#[test]
fn excite_hold_heading_keeps_the_heading() {
    let plant = PlantFile::load(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../plants/nano.json")))
        .expect("plants/nano.json");
    let opts = SimulateOptions::new(vec![Profile::ExciteHoldHeading, Profile::Excite], vec![30.0, 30.0], 3);
    let log = simulate(&plant, &opts).expect("simulate");
    let rows = |k: usize| log.rows.iter().filter(move |r| r.segment == k);
    let range = |k: usize, col: usize| {
        let v: Vec<f64> = rows(k).map(|r| r.x[col]).collect();
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - v.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    let u_range = |k: usize, j: usize| rows(k).map(|r| r.u[j].abs()).fold(0.0, f64::max);
    assert!(range(0, 5) < 0.1, "held heading moved {} rad", range(0, 5));
    assert!(u_range(0, 3) < 0.02, "u_yaw_rate up to {}", u_range(0, 3));
    // The other channels carry their excitation in both; `excite` turns.
    assert!(u_range(0, 1) > 0.1 && u_range(0, 0) > 0.5);
    assert!(range(1, 5) > 1.0, "excite turned only {} rad", range(1, 5));
}
