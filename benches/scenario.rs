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
    pub statuses: [usize; 5],
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
         \"invalid_input\": {}, \"numerical_failure\": {}}}, \"size_of_mpc\": {}}}",
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
        core::mem::size_of::<Mpc>(),
    )
}

/// One RTI step, not inlined, so callgrind can count exactly its instructions
/// (`--toggle-collect` / `--dump-after` on this symbol).
#[inline(never)]
pub fn measured_step(mpc: &mut Mpc, reference: &[[Real; NX]; N + 1], x: &[Real; NX]) -> [Real; NU] {
    mpc.prepare(reference);
    mpc.feedback(x).u0
}

/// `steps` deterministic steps of each of the scenario's 3 trajectories (as in [`run`]) through
/// [`measured_step`]: call number `t · steps + k + 1` is step k of trajectory t.
pub fn run_for_instruction_count(steps: usize, seed: u64) {
    for which in 0..3 {
        let mut mpc = Mpc::new();
        let mut scenario = Scenario::new(which, seed);
        for _ in 0..steps {
            let reference = scenario.reference();
            let u = measured_step(&mut mpc, &reference, &scenario.x);
            scenario.advance(&u);
            mpc.shift();
        }
    }
}
