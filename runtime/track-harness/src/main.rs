//! Closed-loop tracking harness for one generated crate, named `solver` in Cargo.toml:
//! the crate's `Mpc` behind the runtime's [`Controller`] tracking one of the paper's
//! trajectories. `uavgen track` copies this file into a scratch crate pointing `solver` at the
//! crate it generated, runs the binary and drives it line by line over stdin/stdout, while the
//! plant simulator stays in `uavgen` (docs/track.md).
//!
//! Protocol (one request per line, one answer per line; numbers in Rust's shortest round-trip
//! formatting):
//! - `dims` → `dims NX NU N DT u_min… u_max…`
//! - `start TRAJECTORY T0 x0… u…` (TRAJECTORY: sinusoid | circle | spiral; NX states, NU inputs)
//!   → `started STATUS`: the guess is set to the constant x0, u and the first QP prepared at T0.
//! - `step x…` (the measured state, NX numbers) → `u u… STATUS QP_ITERATIONS FEEDBACK_NS PREPARE_NS ERROR`:
//!   the controller's feedback for x, then its preparation of the next sample (timed separately
//!   with `std::time::Instant`); ERROR is `-` or the runtime's `ControlErrorKind`.
//! - anything malformed → `error MESSAGE` (the harness keeps running).
//!
//! A model with input delays (`corrections.latency`, the crate's `INPUT_DELAY_SAMPLES`) is
//! compensated by the runtime's `DelayCompensator`: the MPC solves from the state predicted over the
//! delay with the inputs already sent. The compensator also runs the crate's disturbance observer
//! (`DISTURBANCE_GAIN`, `DISTURBANCE_BOUND`; offset-free tracking, docs/mpc.md), whose estimate the
//! controller hands to the MPC before every preparation.

use std::io::{BufRead, Write};
use std::time::Instant;
use uavgen_runtime::{mpc_adapter, Controller, DelayCompensator, MpcSolver, NoCycleCounter, Trajectory};

mpc_adapter!(struct Solver(solver));

const NX: usize = solver::NX;
const NU: usize = solver::NU;
const N1: usize = solver::N + 1;
type R = solver::Real;

fn numbers(words: &[&str]) -> Result<Vec<R>, String> {
    words
        .iter()
        .map(|w| w.parse::<R>().map_err(|_| format!("not a number: '{w}'")))
        .collect()
}

fn fixed<const K: usize>(v: &[R]) -> Result<[R; K], String> {
    <[R; K]>::try_from(v).map_err(|_| format!("expected {K} numbers, got {}", v.len()))
}

fn trajectory(name: &str) -> Result<Trajectory, String> {
    match name {
        "sinusoid" | "sinusoidal" => Ok(Trajectory::Sinusoidal),
        "circle" | "circular" => Ok(Trajectory::Circular),
        "spiral" => Ok(Trajectory::Spiral),
        other => Err(format!("unknown trajectory '{other}'")),
    }
}

fn join(v: &[R]) -> String {
    v.iter().map(|a| format!("{a:?}")).collect::<Vec<_>>().join(" ")
}

/// The longest input delay (samples) the harness compensates.
const MAX_DELAY: usize = 32;
type Dynamics = fn(&[R; NX], &[R; NU]) -> [R; NX];
type Predictor = DelayCompensator<R, Dynamics, NX, NU, MAX_DELAY>;
/// The controller solves from the state predicted over the model's input delays
/// (`solver::INPUT_DELAY_SAMPLES`, all 0 unless the model file has `corrections.latency`: then the
/// prediction is the identity).
type Ctl<'a> = Controller<&'a mut Solver, Trajectory, R, NX, NU, N1, NoCycleCounter, Predictor>;

fn handle<'a>(line: &str, solver: &mut Option<&'a mut Solver>, ctl: &mut Option<Ctl<'a>>) -> Result<String, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    match words.first().copied() {
        Some("dims") => Ok(format!(
            "dims {NX} {NU} {} {:?} {} {}",
            solver::N,
            solver::DT,
            join(&<Solver as MpcSolver<R, NX, NU, N1>>::U_MIN),
            join(&<Solver as MpcSolver<R, NX, NU, N1>>::U_MAX)
        )),
        Some("start") => {
            let traj = trajectory(words.get(1).copied().unwrap_or(""))?;
            let rest = numbers(&words[2.min(words.len())..])?;
            if rest.len() != 1 + NX + NU {
                return Err(format!("start expects T0, {NX} states and {NU} inputs"));
            }
            let x0: [R; NX] = fixed(&rest[1..1 + NX])?;
            let u: [R; NU] = fixed(&rest[1 + NX..])?;
            // A new controller borrows the one solver; the previous one (if any) is dropped first.
            let s = match ctl.take() {
                Some(c) => c.into_parts().0,
                None => solver.take().ok_or("no solver")?,
            };
            let dynamics: Dynamics = solver::discrete_dynamics;
            let predictor = DelayCompensator::new(dynamics, solver::INPUT_DELAY_SAMPLES, u)
                .map_err(|e| format!("{e:?}"))?
                .with_disturbance_observer(solver::DISTURBANCE_GAIN, solver::DISTURBANCE_BOUND);
            let mut c = Controller::new(s, traj).with_delay_compensation(predictor);
            c.initialize(&x0, &u);
            let status = c.start(rest[0]).map_err(|e| format!("reference: {e}"))?;
            *ctl = Some(c);
            Ok(format!("started {status:?}"))
        }
        Some("step") => {
            let c = ctl.as_mut().ok_or("step before start")?;
            let x: [R; NX] = fixed(&numbers(&words[1..])?)?;
            let t0 = Instant::now();
            let feedback = c.feedback(&x);
            let t1 = Instant::now();
            let prepared = c.prepare_next();
            let t2 = Instant::now();
            let (solution, error) = match feedback {
                Ok(s) => (s, "-".to_string()),
                Err(e) => (e.solution, format!("{:?}", e.kind)),
            };
            let error = match (error.as_str(), prepared) {
                ("-", Err(e)) => format!("Reference({e:?})"),
                _ => error,
            };
            Ok(format!(
                "u {} {:?} {} {} {} {}",
                join(&solution.u0),
                solution.status,
                solution.qp_iterations,
                (t1 - t0).as_nanos(),
                (t2 - t1).as_nanos(),
                error.replace(' ', "")
            ))
        }
        _ => Err(format!("unknown request '{line}'")),
    }
}

fn main() {
    // The generated Mpc is a few hundred kB: on the heap, borrowed for the whole run.
    let solver: &'static mut Solver = Box::leak(Box::new(Solver::new()));
    let mut solver = Some(solver);
    let mut ctl = None;
    let stdin = std::io::stdin();
    let mut out = std::io::stdout().lock();
    for line in stdin.lock().lines() {
        let Ok(line) = line else { break };
        let answer = handle(line.trim(), &mut solver, &mut ctl).unwrap_or_else(|e| format!("error {e}"));
        if writeln!(out, "{answer}").and_then(|()| out.flush()).is_err() {
            break;
        }
    }
}
