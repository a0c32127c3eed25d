//! The controller around real generated crates when the flight computer misbehaves (issue 28):
//! missed deadlines, a stale estimator, Unix start times. The model itself is the plant.

use uavgen_runtime::{mpc_adapter, ControlErrorKind, Controller, MpcSolver, Trajectory};

mpc_adapter!(struct SindyMpc(sindy_m100));
mpc_adapter!(struct PdHoverF32Mpc(pd_hover_f32));

/// What a flight of the circle through the controller did.
struct Flight {
    /// Position after each sample, and the reference there.
    positions: Vec<[f64; 3]>,
    references: Vec<[f64; 3]>,
    kinds: Vec<Option<ControlErrorKind>>,
    deadline_misses: u32,
}

/// How the flight computer misbehaves at sample i.
#[derive(Clone, Copy, Default)]
struct Faults {
    /// `prepare_next` skipped after every `skip_every`-th sample (0: never).
    skip_every: usize,
    /// `start(t)` instead of `prepare_next` every sample.
    restart: bool,
    /// The measurement held (the one of sample `hold.0`) for samples hold.0..hold.1.
    hold: (usize, usize),
}

/// sindy_m100 (f64) on the circle from rest at its start point, `steps` samples, measured times
/// t₀ + i·DT.
fn sindy_flight(steps: usize, t0: f64, faults: Faults) -> Flight {
    use sindy_m100::*;
    let mut solver = Box::new(SindyMpc::new());
    let start = Trajectory::Circular.position::<f64>(t0);
    let mut x = [0.0; NX];
    x[..3].copy_from_slice(&start);
    solver.initialize(&x, &[0.0; NU]);
    let mut c = Controller::new(&mut *solver, Trajectory::Circular);
    c.start(t0).unwrap();
    let mut flight = Flight {
        positions: Vec::new(),
        references: Vec::new(),
        kinds: Vec::new(),
        deadline_misses: 0,
    };
    let mut held = x;
    for i in 0..steps {
        let t = t0 + i as f64 * DT;
        if !(faults.hold.0 < i && i < faults.hold.1) {
            held = x;
        }
        let result = c.feedback_at(t, &held);
        let u = match result {
            Ok(s) => s.u0,
            Err(e) => e.solution.u0,
        };
        flight.kinds.push(result.err().map(|e| e.kind));
        x = discrete_dynamics(&x, &u);
        flight.positions.push([x[0], x[1], x[2]]);
        flight.references.push(Trajectory::Circular.position::<f64>(t + DT));
        if faults.restart {
            c.start(t + DT).unwrap();
        } else if faults.skip_every == 0 || i % faults.skip_every != faults.skip_every - 1 {
            c.prepare_next().unwrap();
        }
    }
    flight.deadline_misses = c.supervision().deadline_misses;
    flight
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum::<f64>().sqrt()
}

fn max_difference(a: &Flight, b: &Flight) -> f64 {
    a.positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| distance(p, q))
        .fold(0.0, f64::max)
}

/// Skipping `prepare_next` on 1 sample in 10 (the next feedback catches up) flies within 0.1 m of
/// the undisturbed flight; each miss is counted and reported. `start(t)` every sample is
/// `prepare_next`.
#[test]
fn missed_preparations_are_caught_up() {
    let steps = 600;
    let clean = sindy_flight(steps, 0.0, Faults::default());
    assert!(
        clean.kinds.iter().all(|k| k.is_none()),
        "undisturbed flight reports nothing"
    );
    let skipping = sindy_flight(
        steps,
        0.0,
        Faults {
            skip_every: 10,
            ..Faults::default()
        },
    );
    let diff = max_difference(&clean, &skipping);
    eprintln!("skip 1 in 10: max position difference {diff:.2e} m");
    assert!(diff < 0.1, "{diff}");
    // Skipped after samples 9, 19, …; the last one is never followed by a feedback.
    assert_eq!(skipping.deadline_misses as usize, (steps - 1) / 10);
    for (i, kind) in skipping.kinds.iter().enumerate() {
        let caught_up = i > 0 && i % 10 == 0;
        assert_eq!(
            *kind == Some(ControlErrorKind::DeadlineMissed),
            caught_up,
            "sample {i}: {kind:?}"
        );
    }
    let restarting = sindy_flight(
        steps,
        0.0,
        Faults {
            restart: true,
            ..Faults::default()
        },
    );
    let diff = max_difference(&clean, &restarting);
    assert!(diff < 1e-6, "start(t) every sample: {diff}");
    assert_eq!(restarting.deadline_misses, 0);
}

/// A measurement held for 2 s (a stalled estimator) while flying the circle: reported as stale
/// from 0.5 s on, never plain `Ok`; once fresh measurements come back the aircraft is back within
/// 0.5 m within 30 s.
#[test]
fn a_stale_measurement_is_reported_and_recovered_from() {
    let dt = sindy_m100::DT;
    let (from, to) = (150, 150 + (2.0 / dt).round() as usize);
    let flight = sindy_flight(
        to + (32.0 / dt) as usize,
        0.0,
        Faults {
            hold: (from, to),
            ..Faults::default()
        },
    );
    let stale_from = from + (0.5 / dt).ceil() as usize + 1;
    for i in stale_from..to {
        assert_eq!(flight.kinds[i], Some(ControlErrorKind::StaleMeasurement), "sample {i}");
    }
    let worst = (from..to + 10)
        .map(|i| distance(&flight.positions[i], &flight.references[i]))
        .fold(0.0, f64::max);
    let back = (to..flight.positions.len())
        .rev()
        .find(|&i| distance(&flight.positions[i], &flight.references[i]) >= 0.5)
        .map_or(to, |i| i + 1);
    let seconds = (back - to) as f64 * dt;
    eprintln!("held 2 s: worst error {worst:.2} m, back within 0.5 m {seconds:.1} s after");
    assert!(seconds <= 30.0, "{seconds}");
}

/// RMS position error over the last two thirds of a circle flight of pd_hover_f32 started at `t0`.
fn f32_circle_rmse(t0: f64) -> f64 {
    use pd_hover_f32::*;
    let mut solver = Box::new(PdHoverF32Mpc::new());
    let p = Trajectory::Circular.position::<f64>(t0);
    let mut x = [0.0 as Real; NX];
    for i in 0..3 {
        x[i] = p[i] as Real;
    }
    solver.initialize(&x, &[0.0; NU]);
    let mut c = Controller::new(&mut *solver, Trajectory::Circular);
    c.start(t0).unwrap();
    let steps = 450;
    let (mut err2, mut count) = (0.0, 0);
    for i in 0..steps {
        let u = match c.feedback(&x) {
            Ok(s) => s.u0,
            Err(e) => e.solution.u0,
        };
        x = discrete_dynamics(&x, &u);
        c.prepare_next().unwrap();
        if i >= steps / 3 {
            let r = Trajectory::Circular.position::<f64>(c.time());
            for k in 0..3 {
                err2 += (f64::from(x[k]) - r[k]).powi(2);
            }
            count += 3;
        }
    }
    (err2 / count as f64).sqrt()
}

/// An f32 controller started at Unix time tracks like one started at 0.
#[test]
fn f32_controller_at_unix_time_tracks_like_at_zero() {
    let at_zero = f32_circle_rmse(0.0);
    let at_unix = f32_circle_rmse(1.7e9);
    eprintln!("pd_hover_f32 circle RMSE: {at_zero:.4} m from t = 0, {at_unix:.4} m from t = 1.7e9 s");
    assert!(at_zero < 0.5, "{at_zero}");
    assert!((at_unix - at_zero).abs() < 0.02, "{at_unix} vs {at_zero}");
}

/// The adapter's constants are the crate's (a compile-time check that both adapters exist).
#[test]
fn adapters() {
    assert_eq!(<PdHoverF32Mpc as MpcSolver<f32, 12, 4, 31>>::DT, pd_hover_f32::DT);
}
