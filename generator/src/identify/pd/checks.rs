//! Post-fit checks: hover, stability of the linearisation at hover, free runs over the data.

use super::PdFitOptions;
use crate::discretize::{auto_substeps, discrete_step, Envelope};
use crate::identify::dataset::Dataset;
use crate::ir::ModelIr;
use crate::model::Model;
use nalgebra::{DMatrix, Schur};
use serde::Serialize;

/// The linearisation at hover counts as stable when max Re λ(∂f/∂x) ≤ this (1/s). The free integrators
/// (position, yaw, horizontal velocity) give exact zeros up to rounding.
pub const STABILITY_TOLERANCE: f64 = 1e-6;

/// Bounds a free run must stay within.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FreeRunLimits {
    /// |roll|, |pitch| in rad (the model is singular at |pitch| = π/2).
    pub tilt: f64,
    /// |vx|, |vy|, |vz| in m/s.
    pub speed: f64,
    /// |Euler-angle rates| in rad/s.
    pub angular_rate: f64,
}

/// The limits of the free-run check.
pub const FREE_RUN_LIMITS: FreeRunLimits = FreeRunLimits {
    tilt: 1.5,
    speed: 100.0,
    angular_rate: 100.0,
};

/// Substeps used when the automatic rule fails (a very stiff fit).
const FALLBACK_SUBSTEPS: usize = 64;

/// The fitted model run from a segment's first state under its logged inputs.
#[derive(Clone, Debug, Serialize)]
pub struct FreeRun {
    pub log: usize,
    pub segment: usize,
    pub samples: usize,
    /// Steps completed within the limits (samples − 1 when bounded).
    pub steps: usize,
    /// RK4 substeps per sample (automatic rule, [`crate::discretize::auto_substeps`]).
    pub substeps: usize,
    pub bounded: bool,
    /// Which limit was crossed, and when.
    pub failure: Option<String>,
    /// RMSE per state over the completed steps (predicted vs the dataset's states).
    pub rmse: [f64; 12],
}

pub(super) struct Checks {
    pub hover_ratio: f64,
    pub hover_input: [f64; 4],
    pub eigenvalues: Vec<[f64; 2]>,
    pub max_real_eigenvalue: f64,
    pub stable: bool,
    pub free_runs: Vec<FreeRun>,
}

fn eigenvalues(a: &DMatrix<f64>) -> Vec<[f64; 2]> {
    match Schur::try_new(a.clone(), f64::EPSILON, 10_000) {
        Some(s) => s.complex_eigenvalues().iter().map(|z| [z.re, z.im]).collect(),
        None => vec![[f64::NAN, f64::NAN]; a.nrows()],
    }
}

pub(super) fn run(model: &Model, dataset: &Dataset, options: &PdFitOptions, xi: &[f64; 16]) -> Checks {
    let ir = ModelIr::new(model);
    let mg = options.mass * options.gravity;
    let hover_ratio = xi[12] / mg;
    let trim = if xi[0] > 0.0 { (mg - xi[12]) / xi[0] } else { 0.0 };
    let hover_input = [trim, 0.0, 0.0, 0.0];
    let (fx, _) = ir.eval_jacobian(&[0.0; 12], &hover_input);
    let a = DMatrix::from_fn(12, 12, |i, j| fx[i][j]);
    let eig = eigenvalues(&a);
    let max_real_eigenvalue = eig.iter().map(|z| z[0]).fold(f64::NEG_INFINITY, f64::max);
    let stable = max_real_eigenvalue <= STABILITY_TOLERANCE;

    let mut free_runs = Vec::new();
    if options.free_run {
        let mut cache: Vec<(f64, usize)> = Vec::new();
        for seg in &dataset.segments {
            let substeps = match cache.iter().find(|(dt, _)| *dt == seg.dt) {
                Some(&(_, m)) => m,
                None => {
                    let m = auto_substeps(&ir, seg.dt, &Envelope::default())
                        .map(|c| c.substeps)
                        .unwrap_or(FALLBACK_SUBSTEPS);
                    cache.push((seg.dt, m));
                    m
                }
            };
            free_runs.push(free_run(&ir, seg, substeps));
        }
    }
    Checks {
        hover_ratio,
        hover_input,
        eigenvalues: eig,
        max_real_eigenvalue,
        stable,
        free_runs,
    }
}

fn violation(x: &[f64]) -> Option<String> {
    let l = FREE_RUN_LIMITS;
    if x.iter().any(|v| !v.is_finite()) {
        return Some("state not finite".into());
    }
    if x[3].abs() > l.tilt || x[4].abs() > l.tilt {
        return Some(format!("tilt beyond {} rad", l.tilt));
    }
    if x[6..9].iter().any(|v| v.abs() > l.speed) {
        return Some(format!("speed beyond {} m/s", l.speed));
    }
    if x[9..12].iter().any(|v| v.abs() > l.angular_rate) {
        return Some(format!("angular rate beyond {} rad/s", l.angular_rate));
    }
    None
}

fn free_run(ir: &ModelIr, seg: &crate::identify::dataset::SegmentData, substeps: usize) -> FreeRun {
    let n = seg.x.len().min(seg.u.len());
    let mut run = FreeRun {
        log: seg.log,
        segment: seg.segment,
        samples: n,
        steps: 0,
        substeps,
        bounded: true,
        failure: None,
        rmse: [0.0; 12],
    };
    if n == 0 {
        return run;
    }
    let mut x = seg.x[0].to_vec();
    let mut sq = [0.0; 12];
    for k in 0..n - 1 {
        let dt = match seg.t.get(k + 1).zip(seg.t.get(k)) {
            Some((b, a)) if b > a => b - a,
            _ => seg.dt,
        };
        x = discrete_step(ir, &x, &seg.u[k], dt, substeps);
        if let Some(why) = violation(&x) {
            run.bounded = false;
            run.failure = Some(format!("{why} after {:.2} s", (k + 1) as f64 * seg.dt));
            break;
        }
        run.steps += 1;
        for i in 0..12 {
            sq[i] += (x[i] - seg.x[k + 1][i]).powi(2);
        }
    }
    if run.steps > 0 {
        run.rmse = sq.map(|s| (s / run.steps as f64).sqrt());
    }
    run
}
