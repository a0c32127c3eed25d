//! `uavgen track` (and `uavgen.track` in Python): the checks, the backend and one closed-loop
//! flight with its report and files, shared by both front ends.

use crate::codegen::GenerateOptions;
use crate::model::Model;
use crate::sim::PlantFile;
use crate::track::{self, Backend, Flight, GenericBackend, HarnessBackend, TrackOptions, TrackReport, VerdictRules};
use crate::MpcOptions;
use std::path::{Path, PathBuf};
use uavgen_runtime::Trajectory;

/// The trajectories by their CLI names.
pub const TRAJECTORIES: [(&str, Trajectory); 3] = [
    ("circle", Trajectory::Circular),
    ("sinusoid", Trajectory::Sinusoidal),
    ("spiral", Trajectory::Spiral),
];

/// A trajectory by its CLI name (`circle`, `sinusoid`, `spiral`).
pub fn trajectory(name: &str) -> Result<Trajectory, String> {
    TRAJECTORIES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| *t)
        .ok_or_else(|| format!("--trajectory: `{name}` is not one of circle, sinusoid, spiral"))
}

/// Everything a set of closed loops needs, checked ([`Session::new`]).
pub struct Session {
    pub model: Model,
    /// What the reports name the model and the plant by (the paths as given).
    pub model_label: String,
    pub plant: PlantFile,
    pub plant_label: String,
    /// The plant's sample period, s.
    pub dt: f64,
    pub duration: f64,
    pub seed: u64,
    pub horizon: usize,
    pub mpc: Option<MpcOptions>,
    pub rules: VerdictRules,
    pub options: GenerateOptions,
}

impl Session {
    /// Check the duration, the verdict rules, the model's dimensions and the generation options
    /// (the CLI's messages), before any work.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model: Model,
        model_label: &str,
        plant: PlantFile,
        plant_label: &str,
        duration: f64,
        seed: u64,
        horizon: usize,
        mpc: Option<MpcOptions>,
        rules: VerdictRules,
    ) -> Result<Self, String> {
        Self::check_duration(duration)?;
        rules.validate()?;
        Self::check_model(&model, model_label)?;
        let dt = crate::Plant::new(&plant, seed).sample_period();
        let options = GenerateOptions {
            horizon,
            rate_hz: 1.0 / dt,
            mpc: mpc.clone(),
            ..GenerateOptions::default()
        };
        options.validate().map_err(|e| e.to_string())?;
        Ok(Self {
            model,
            model_label: model_label.to_owned(),
            plant,
            plant_label: plant_label.to_owned(),
            dt,
            duration,
            seed,
            horizon,
            mpc,
            rules,
            options,
        })
    }

    /// A flight time in s: positive, at most the simulator's longest.
    pub fn check_duration(duration: f64) -> Result<(), String> {
        let max = crate::sim::run::MAX_DURATION_S;
        if !(duration.is_finite() && duration > 0.0 && duration <= max) {
            return Err(format!(
                "--duration: must be a positive number of seconds, at most {max}, got {}",
                crate::validate::short(duration)
            ));
        }
        Ok(())
    }

    /// `uavgen track` flies models with the 12 standard states and 4 inputs.
    pub fn check_model(model: &Model, label: &str) -> Result<(), String> {
        if model.base_nx() != 12 || model.nu() != 4 {
            return Err(format!(
                "{label}: uavgen track needs a model with the 12 standard states and 4 inputs (this one has {} and {})",
                model.base_nx(),
                model.nu()
            ));
        }
        Ok(())
    }

    /// The generic reference solver (interpreted model + clarabel).
    pub fn generic_backend(&self) -> Result<Box<dyn Backend>, String> {
        let ir = crate::ModelIr::new(&self.model);
        let substeps = crate::discretize::auto_substeps(&ir, self.dt, &self.options.envelope)
            .map_err(|e| format!("{}: {e}", self.model_label))?
            .substeps;
        let mpc = self.mpc.clone().unwrap_or_else(|| MpcOptions::defaults(&self.model));
        Ok(Box::new(GenericBackend::new(
            &self.model,
            mpc,
            self.horizon,
            self.dt,
            substeps,
        )))
    }

    /// The generated crate in the tracking harness, built with cargo in `work_dir`; `run` runs the
    /// build (the CLI wraps it in a spinner; `|work| work()` otherwise).
    pub fn harness_backend(
        &self,
        work_dir: &Path,
        run: impl FnOnce(&dyn Fn() -> Result<(String, PathBuf), String>) -> Result<(String, PathBuf), String>,
    ) -> Result<Box<dyn Backend>, String> {
        let (name, binary) = run(&|| track::build::build_harness(&self.model, &self.options, work_dir))?;
        Ok(Box::new(HarnessBackend::spawn(&binary, &name)?))
    }

    /// Fly one trajectory (`name` as the report names it); `progress(done)` after each sample.
    pub fn fly(
        &self,
        backend: &mut dyn Backend,
        which: Trajectory,
        name: &str,
        progress: &mut dyn FnMut(usize),
    ) -> Result<(TrackReport, Flight), String> {
        let options = TrackOptions {
            trajectory: which,
            duration: self.duration,
            seed: self.seed,
            max_distance: self.rules.max_distance,
            ..TrackOptions::default()
        };
        let mut extender = track::StateExtender::new(&self.model, self.dt)?;
        let flight = track::fly(
            backend,
            &self.plant,
            &options,
            &mut |x, t, u| extender.extend(x, t, u),
            &mut |done, _| progress(done),
        )?;
        let report = TrackReport::new(
            &self.model_label,
            &self.plant_label,
            name,
            &backend.describe(),
            self.seed,
            self.dt,
            &flight,
            &backend.bounds(),
            &self.rules,
        );
        Ok((report, flight))
    }

    /// Samples a flight of the session's duration has.
    pub fn planned_samples(&self) -> usize {
        (self.duration / self.dt).round() as usize
    }
}

/// report.md, report.json, samples.csv and the plots of one flight into `dir`.
pub fn write_flight(dir: &Path, name: &str, report: &TrackReport, flight: &Flight) -> Result<(), String> {
    let write = crate::sim::write_atomically;
    let s = |e: crate::sim::PlantError| e.to_string();
    write(&dir.join("report.md"), &report.markdown()).map_err(s)?;
    let json = serde_json::to_string_pretty(report).map_err(|e| e.to_string())? + "\n";
    write(&dir.join("report.json"), &json).map_err(s)?;
    write(&dir.join("samples.csv"), &track::report::samples_csv(&flight.samples)).map_err(s)?;
    track::plot::write(&flight.samples, name, dir)?;
    Ok(())
}

/// The line the CLI prints per flight.
pub fn summary_line(name: &str, report: &TrackReport) -> String {
    format!(
        "{}: {} ({}); position RMSE {:.4} m (x {:.4}, y {:.4}, z {:.4}), MAE {:.4}, d1 {:.4}; feedback median {:.1} µs, max {:.1} µs; {} inputs out of bounds",
        name,
        report.verdict.name().to_uppercase(),
        report.verdict_reason,
        report.overall.rmse,
        report.axes["x"].rmse,
        report.axes["y"].rmse,
        report.axes["z"].rmse,
        report.overall.mae,
        report.overall.d1,
        report.feedback.median_us,
        report.feedback.max_us,
        report.inputs_out_of_bounds
    )
}
