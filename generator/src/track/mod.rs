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
pub mod verdict;

pub use backend::{Backend, GenericBackend, HarnessBackend, StepAnswer};
pub use extend::StateExtender;
pub use report::{TrackReport, TrackSample};
pub use verdict::{Verdict, VerdictRules};

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
    /// The flight stops at the first sample that [`verdict::divergence`] calls lost with this
    /// distance bound (m): non-finite state, farther than this from the reference, on the ground.
    pub max_distance: f64,
}

impl Default for TrackOptions {
    fn default() -> Self {
        Self {
            trajectory: Trajectory::Circular,
            duration: 30.0,
            seed: 1,
            start: START,
            max_distance: verdict::DEFAULT_MAX_DISTANCE,
        }
    }
}

/// The samples of one run.
#[derive(Clone, Debug)]
pub struct Flight {
    /// One per sample flown (the first, at t = 0, is always flown).
    pub samples: Vec<TrackSample>,
    /// The samples the duration asked for.
    pub planned: usize,
    /// The time and the reason the flight was lost ([`verdict::divergence`]), if it was.
    pub lost: Option<(f64, String)>,
}

/// Turns the plant's 12 measured states, the time and the last input into the model's state vector.
pub type ExtendState<'a> = dyn FnMut(&[f64; 12], f64, &[f64]) -> Vec<f64> + 'a;

/// Fly `options.trajectory` with `backend` controlling a plant built from `plant`; `extend` turns
/// the plant's 12 measured states into the model's state vector (identity for 12-state models).
/// A lost flight ([`verdict::divergence`] of the true state at a sample) stops there: that sample
/// is not flown, and `lost` says when and why.
pub fn fly(
    backend: &mut dyn Backend,
    plant: &PlantFile,
    options: &TrackOptions,
    extend: &mut ExtendState,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Flight, String> {
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
    if steps == 0 {
        return Err(format!(
            "--duration {} s is shorter than one sample period ({dt} s)",
            options.duration
        ));
    }
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
        let reference = options.trajectory.position(t);
        let truth = p.true_state();
        if let Some(why) = verdict::divergence(&truth, &reference, options.max_distance).filter(|_| k > 0) {
            progress(steps, steps);
            return Ok(Flight {
                samples,
                planned: steps,
                lost: Some((t, why)),
            });
        }
        let measured = p.measured();
        let x = extend(&measured, t, &last_u);
        let answer = backend.step(&x)?;
        samples.push(TrackSample {
            t,
            reference,
            measured,
            truth,
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
    // The state the last input led to.
    let t = steps as f64 * dt;
    let lost =
        verdict::divergence(&p.true_state(), &options.trajectory.position(t), options.max_distance).map(|why| (t, why));
    Ok(Flight {
        samples,
        planned: steps,
        lost,
    })
}
