// The worst-case RTI benchmark scenario, shared by `cargo bench -p uavgen-benches`
// (benches/worst_case.rs) and the harness `uavgen bench` builds against a
// generated crate (benches/harness). It is `include!`d into a module in which
// `solver` names the generated crate.
//
// Closed loop on each of the paper's trajectories (sinusoidal, circular,
// spiral) from the paper's start state, with the model itself as plant plus
// deterministic disturbances: small state noise every step, a velocity/rate
// kick every 97 steps, and a reference jump of up to ±2 m held for 60 steps
// every 173 steps. Each step is timed in two phases, `prepare` (linearise,
// condense, factorise) and `feedback` (gradient, QP, update).

use solver::{Mpc, Real, Status, DT, N, NU, NX};
use std::time::Instant;

/// Timings (ns) and counters of one run.
#[derive(Default, Clone, Debug)]
pub struct Record {
    pub prepare_ns: Vec<f64>,
    pub feedback_ns: Vec<f64>,
    pub total_ns: Vec<f64>,
    pub qp_iterations: Vec<usize>,
    pub statuses: [usize; 6],
}

/// Deterministic pseudo-random numbers in [−1, 1).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Position of the paper's trajectory `which` (0 sinusoidal, 1 circular, 2 spiral) at t.
pub fn trajectory(which: usize, t: f64) -> [f64; 3] {
    match which {
        0 => [4.0 * (0.32 * t).sin() + 3.0, 4.0 * (0.64 * t).sin(), 2.0 * (0.64 * t).sin() + 6.0],
        1 => [5.0 * t.cos(), 5.0 * t.sin(), 6.0],
        _ => [(0.06 * t).exp() * t.cos(), (0.06 * t).exp() * t.sin(), 0.1 * t + 5.0],
    }
}

fn status_index(s: Status) -> usize {
    match s {
        Status::Solved => 0,
        Status::IterationCap => 1,
        Status::HessianRegularised => 2,
        Status::InvalidInput => 3,
        Status::NumericalFailure => 4,
        Status::OutOfEnvelope => 5,
    }
}

/// One closed-loop step of the scenario's state: reference window and plant.
pub struct Scenario {
    pub which: usize,
    pub step: usize,
    pub x: [Real; NX],
    pub offset: [f64; 3],
    pub rng: Lcg,
}

impl Scenario {
    pub fn new(which: usize, seed: u64) -> Self {
        let mut x = [0.0 as Real; NX];
        x[0] = 3.0;
        x[1] = 3.0;
        x[2] = 5.0;
        Self { which, step: 0, x, offset: [0.0; 3], rng: Lcg(seed.wrapping_add(which as u64)) }
    }

    /// The reference window of the current step.
    pub fn reference(&mut self) -> [[Real; NX]; N + 1] {
        if self.step % 173 == 0 && self.step > 0 {
            self.offset = [2.0 * self.rng.next(), 2.0 * self.rng.next(), self.rng.next()];
        }
        if self.step % 173 == 60 {
            self.offset = [0.0; 3];
        }
        let t = self.step as f64 * DT as f64;
        let mut r = [[0.0 as Real; NX]; N + 1];
        for (k, row) in r.iter_mut().enumerate() {
            let p = trajectory(self.which, t + k as f64 * DT as f64);
            for i in 0..3 {
                row[i] = (p[i] + self.offset[i]) as Real;
            }
        }
        r
    }

    /// Plant: the model plus disturbances.
    pub fn advance(&mut self, u: &[Real; NU]) {
        self.x = solver::discrete_dynamics(&self.x, u);
        let kick = self.step % 97 == 96;
        for i in 0..NX {
            let scale = match (i, kick) {
                (3..=5, false) => 0.002,
                (6..=11, false) => 0.01,
                (6..=11, true) => 1.0,
                _ => 0.0,
            };
            self.x[i] += (scale * self.rng.next()) as Real;
        }
        self.step += 1;
    }
}

/// Run `steps` RTI steps on each of the 3 trajectories, timing every phase.
pub fn run(steps: usize, seed: u64) -> Record {
    let mut record = Record::default();
    for which in 0..3 {
        let mut mpc = Mpc::new();
        let mut scenario = Scenario::new(which, seed);
        for _ in 0..steps {
            let reference = scenario.reference();
            let t0 = Instant::now();
            mpc.prepare(&reference);
            let t1 = Instant::now();
            let solution = mpc.feedback(&scenario.x);
            let t2 = Instant::now();
            record.prepare_ns.push((t1 - t0).as_nanos() as f64);
            record.feedback_ns.push((t2 - t1).as_nanos() as f64);
            record.total_ns.push((t2 - t0).as_nanos() as f64);
            record.qp_iterations.push(solution.qp_iterations);
            record.statuses[status_index(solution.status)] += 1;
            scenario.advance(&solution.u0);
            mpc.shift();
        }
    }
    record
}

/// (median, p99, p99.9, max) of `values`.
pub fn quantiles(values: &[f64]) -> [f64; 4] {
    let mut v = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    [q(0.5), q(0.99), q(0.999), v[v.len() - 1]]
}

/// The record as one JSON object.
pub fn to_json(record: &Record, name: &str) -> String {
    let arr = |q: [f64; 4]| format!("[{:.0}, {:.0}, {:.0}, {:.0}]", q[0], q[1], q[2], q[3]);
    format!(
        "{{\"model\": \"{name}\", \"steps\": {}, \"prepare_ns\": {}, \"feedback_ns\": {}, \"total_ns\": {}, \
         \"max_qp_iterations\": {}, \"statuses\": {{\"solved\": {}, \"iteration_cap\": {}, \"hessian_regularised\": {}, \
         \"invalid_input\": {}, \"numerical_failure\": {}, \"out_of_envelope\": {}}}, \"size_of_mpc\": {}}}",
        record.total_ns.len(),
        arr(quantiles(&record.prepare_ns)),
        arr(quantiles(&record.feedback_ns)),
        arr(quantiles(&record.total_ns)),
        record.qp_iterations.iter().max().copied().unwrap_or(0),
        record.statuses[0],
        record.statuses[1],
        record.statuses[2],
        record.statuses[3],
        record.statuses[4],
        record.statuses[5],
        core::mem::size_of::<Mpc>(),
    )
}

/// The preparation phase of one RTI step, not inlined: callgrind dumps after it (`--dump-after`),
/// so each step's count splits into prepare and feedback.
#[inline(never)]
pub fn measured_prepare(mpc: &mut Mpc, reference: &[[Real; NX]; N + 1]) -> solver::Status {
    mpc.prepare(reference)
}

/// The feedback phase of one RTI step, not inlined (see [`measured_prepare`]).
#[inline(never)]
pub fn measured_feedback(mpc: &mut Mpc, x: &[Real; NX]) -> solver::Solution {
    mpc.feedback(x)
}

/// One RTI step, not inlined, so callgrind can count exactly its instructions (collection is
/// toggled on this symbol; `uavgen bench` dumps after each of its two phases).
#[inline(never)]
pub fn measured_step(mpc: &mut Mpc, reference: &[[Real; NX]; N + 1], x: &[Real; NX]) -> solver::Solution {
    measured_prepare(mpc, reference);
    measured_feedback(mpc, x)
}

/// `steps` deterministic steps of each of the scenario's 3 trajectories (as in [`run`]) through
/// [`measured_step`]: step number `t · steps + k + 1` is step k of trajectory t.
pub fn run_for_instruction_count(steps: usize, seed: u64) {
    for which in 0..3 {
        let mut mpc = Mpc::new();
        let mut scenario = Scenario::new(which, seed);
        for _ in 0..steps {
            let reference = scenario.reference();
            let u = measured_step(&mut mpc, &reference, &scenario.x).u0;
            scenario.advance(&u);
            mpc.shift();
        }
    }
}

/// Steps measured after each adversarial disturbance.
pub const ADVERSARIAL_STEPS: usize = 8;

/// The adversarial search: `trials` randomised cases, each [`ADVERSARIAL_STEPS`] steps through
/// [`measured_step`] (step number `t · ADVERSARIAL_STEPS + k + 1` is step k of trial t). A trial
/// starts the plant at a random point at or near the edge of the generator's envelope (tilt
/// ±0.6 rad, speed ±5 m/s, rates ±3 rad/s, each component at its bound with probability ½), lets
/// the solver settle for 30 unmeasured steps on a hover reference, then applies one of: a
/// reference jump of up to ±10 m on every axis (saturating every input), a kick of ±3 on every
/// velocity and rate, a reverse of the reference (the same jump, back), or all at once; the
/// measured steps follow, with the plant kicked again every 3 steps in the last kind.
/// Returns the status counts (in [`Record::statuses`] order) and the largest QP iteration count of
/// the measured steps.
pub fn run_adversarial(trials: usize, seed: u64) -> ([usize; 6], usize) {
    let (mut statuses, mut max_iterations) = ([0; 6], 0);
    let mut rng = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(17));
    for trial in 0..trials {
        let edge = |rng: &mut Lcg, bound: f64| {
            let r = rng.next();
            if r.abs() > 0.5 {
                bound * r.signum()
            } else {
                2.0 * bound * r
            }
        };
        let mut x = [0.0 as Real; NX];
        let bounds = [0.0, 0.0, 0.0, 0.6, 0.6, std::f64::consts::PI, 5.0, 5.0, 5.0, 3.0, 3.0, 3.0];
        for i in 0..NX.min(12) {
            x[i] = edge(&mut rng, bounds[i]) as Real;
        }
        x[2] = (6.0 + rng.next()) as Real;
        let mut mpc = Mpc::new();
        let mut target = [x[0] as f64, x[1] as f64, x[2] as f64];
        let window = |p: [f64; 3]| {
            let mut r = [[0.0 as Real; NX]; N + 1];
            for row in r.iter_mut() {
                for i in 0..3 {
                    row[i] = p[i] as Real;
                }
            }
            r
        };
        for _ in 0..30 {
            mpc.prepare(&window(target));
            let u = mpc.feedback(&x).u0;
            x = solver::discrete_dynamics(&x, &u);
            mpc.shift();
        }
        let kind = trial % 4;
        let jump = [10.0 * rng.next(), 10.0 * rng.next(), 3.0 * rng.next()];
        let kick = |x: &mut [Real; NX], rng: &mut Lcg| {
            for v in x.iter_mut().take(12).skip(6) {
                *v += (3.0 * rng.next()) as Real;
            }
        };
        if kind == 0 || kind == 3 {
            for i in 0..3 {
                target[i] += jump[i];
            }
        }
        if kind == 1 || kind == 3 {
            kick(&mut x, &mut rng);
        }
        if kind == 2 {
            for i in 0..3 {
                target[i] -= jump[i];
            }
        }
        for k in 0..ADVERSARIAL_STEPS {
            let solution = measured_step(&mut mpc, &window(target), &x);
            statuses[status_index(solution.status)] += 1;
            max_iterations = max_iterations.max(solution.qp_iterations);
            x = solver::discrete_dynamics(&x, &solution.u0);
            if kind == 3 && k % 3 == 2 {
                kick(&mut x, &mut rng);
            }
            mpc.shift();
        }
    }
    (statuses, max_iterations)
}
