//! `uavgen track`: closed-loop MPC on the plant simulator, the paper's validation experiment.
//!
//! The MPC (the generated crate through `uavgen-runtime`'s `Controller` in a harness process, or
//! the generic reference solver) controls a [`Plant`] from the paper's start state (position
//! (3, 3, 5), level, at rest) along one of the paper's trajectories. Each sample: the plant's
//! measured state goes to the MPC, its input to the plant, which advances one sample period.
//! The report has RMSE, MAE and d₁ of the position per axis and overall, the solve times and
//! the solver statuses. See `docs/track.md`.

pub mod backend;
pub mod build;
pub mod compare;
pub mod extend;
pub mod plot;
pub mod report;

pub use backend::{Backend, GenericBackend, HarnessBackend, StepAnswer};
pub use extend::StateExtender;
pub use report::{TrackReport, TrackSample};

use crate::sim::{Plant, PlantFile};
use uavgen_runtime::Trajectory;

/// The paper's start state: position (3, 3, 5) m, level, at rest.
pub const START: [f64; 12] = [3.0, 3.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

/// One closed-loop run.
#[derive(Clone, Debug)]
pub struct TrackOptions {
    pub trajectory: Trajectory,
    /// Flight time in s.
    pub duration: f64,
    /// The plant's random seed (noise, turbulence, stale samples).
    pub seed: u64,
    /// Initial state of the plant.
    pub start: [f64; 12],
}

impl Default for TrackOptions {
    fn default() -> Self {
        Self {
            trajectory: Trajectory::Circular,
            duration: 30.0,
            seed: 1,
            start: START,
        }
    }
}

/// Turns the plant's 12 measured states, the time and the last input into the model's state vector.
pub type ExtendState<'a> = dyn FnMut(&[f64; 12], f64, &[f64]) -> Vec<f64> + 'a;

/// Fly `options.trajectory` with `backend` controlling a plant built from `plant`; `extend` turns
/// the plant's 12 measured states into the model's state vector (identity for 12-state models).
pub fn fly(
    backend: &mut dyn Backend,
    plant: &PlantFile,
    options: &TrackOptions,
    extend: &mut ExtendState,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<TrackSample>, String> {
    if !(options.duration.is_finite() && options.duration > 0.0) {
        return Err(format!(
            "--duration must be a positive number of seconds, got {}",
            options.duration
        ));
    }
    let mut p = Plant::new(plant, options.seed);
    p.reset(&options.start);
    let dt = p.sample_period();
    let steps = (options.duration / dt).round() as usize;
    let (u_min, u_max) = backend.bounds();
    // Hover: zero commands, clamped into the bounds.
    let hover: Vec<f64> = u_min
        .iter()
        .zip(&u_max)
        .map(|(lo, hi)| 0.0f64.clamp(*lo, *hi))
        .collect();
    let x0 = extend(&p.measured(), 0.0, &hover);
    backend.start(options.trajectory, 0.0, &x0, &hover)?;
    let mut samples = Vec::with_capacity(steps);
    let mut last_u = hover.clone();
    for k in 0..steps {
        let t = k as f64 * dt;
        let measured = p.measured();
        let x = extend(&measured, t, &last_u);
        let answer = backend.step(&x)?;
        let reference = options.trajectory.position(t);
        samples.push(TrackSample {
            t,
            reference,
            measured,
            truth: p.true_state(),
            answer: answer.clone(),
        });
        let u: [f64; 4] = answer
            .u
            .get(..4)
            .and_then(|s| s.try_into().ok())
            .ok_or_else(|| format!("the MPC returned {} inputs; the plant takes 4", answer.u.len()))?;
        p.step(&u);
        last_u = answer.u;
        progress(k + 1, steps);
    }
    Ok(samples)
}
