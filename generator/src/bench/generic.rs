//! The generic reference solver (interpreted model + clarabel) timed on the
//! benchmark scenario of `benches/scenario.rs` (same trajectories, jumps and
//! disturbances, same pseudo-random sequence), for a side-by-side figure.

use crate::discretize::discrete_step;
use crate::reference::{GenericMpc, MpcProblem};
use crate::{Model, ModelIr, MpcOptions};
use std::time::Instant;

/// (median, p99, max) of the generic RTI step time in ns, and the steps run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GenericTimings {
    pub steps: usize,
    pub total_ns: [f64; 3],
    pub failures: usize,
}

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// The paper's trajectories in the benchmark's order (sinusoid, circle, spiral): the runtime's own.
fn trajectory(which: usize, t: f64) -> [f64; 3] {
    uavgen_runtime::Trajectory::ALL[which.min(2)].position(t)
}

/// Time `steps` generic RTI steps on each of the 3 trajectories.
pub fn run_generic(
    model: &Model,
    options: &MpcOptions,
    horizon: usize,
    dt: f64,
    substeps: usize,
    steps: usize,
    seed: u64,
) -> GenericTimings {
    let mut times = Vec::new();
    let mut failures = 0;
    let nx = model.nx();
    for which in 0..3 {
        let problem = MpcProblem {
            horizon,
            dt,
            substeps,
            options: options.clone(),
        };
        let mut mpc = GenericMpc::new(ModelIr::new(model), problem);
        let plant = ModelIr::new(model);
        let mut rng = Lcg(seed.wrapping_add(which as u64));
        let mut x = vec![0.0; nx];
        x[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
        let mut offset = [0.0; 3];
        let mut u = vec![0.0; model.nu()];
        for step in 0..steps {
            if step % 173 == 0 && step > 0 {
                offset = [2.0 * rng.next(), 2.0 * rng.next(), rng.next()];
            }
            if step % 173 == 60 {
                offset = [0.0; 3];
            }
            let t = step as f64 * dt;
            let reference: Vec<Vec<f64>> = (0..=horizon)
                .map(|k| {
                    let p = trajectory(which, t + k as f64 * dt);
                    let mut r = vec![0.0; nx];
                    for i in 0..3 {
                        r[i] = p[i] + offset[i];
                    }
                    r
                })
                .collect();
            let start = Instant::now();
            match mpc.rti_step(&x, &reference) {
                Ok(s) => u = s.u0,
                Err(_) => failures += 1,
            }
            times.push(start.elapsed().as_nanos() as f64);
            x = discrete_step(&plant, &x, &u, dt, substeps);
            let kick = step % 97 == 96;
            for (i, xi) in x.iter_mut().enumerate() {
                let scale = match (i, kick) {
                    (3..=5, false) => 0.002,
                    (6..=11, false) => 0.01,
                    (6..=11, true) => 1.0,
                    _ => 0.0,
                };
                *xi += scale * rng.next();
            }
            mpc.shift();
        }
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    GenericTimings {
        steps: times.len(),
        total_ns: [q(0.5), q(0.99), times[times.len() - 1]],
        failures,
    }
}
