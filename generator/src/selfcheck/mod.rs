//! `uavgen diagnose --self-check`: the diagnosis protocol run end to end on withheld effects.
//!
//! The simulator flies nominal logs (the nominal plant with sensor noise); a SINDy model is
//! identified from them, so every effect is withheld from it. Then, for each plant effect at a
//! realistic and at a small magnitude (and for pairs of effects), the simulator flies a training and
//! a held-out log with that effect, and `diagnose` must name the matching catalogue effect first
//! and shrink the held-out one-step error of the affected channels; fresh nominal logs must give
//! `none`. The shrink is measured on the held-out flight logged without sensor noise, against the
//! base model's error on the same flight flown without the effect (the gap the effect opened).
//! See `docs/diagnosis.md`.

pub mod cases;
pub mod report;

pub use cases::{default_cases, Case, Magnitude};
pub use report::{CaseResult, SelfCheck};

use crate::diagnose::{base_side, diagnose_with_reference, DiagnoseOptions};
use crate::identify::bounded_selection::select_bounded;
use crate::identify::dataset::{build, DatasetOptions};
use crate::identify::horizon_check::HorizonCheck;
use crate::identify::sindy::{self, Criterion, SindyOptions};
use crate::logs::{parse_log, FlightLog};
use crate::model::Model;
use crate::sim::{simulate, PlantFile, Profile, SimulateOptions};

/// What the self-check flies.
#[derive(Clone, Debug)]
pub struct SelfCheckOptions {
    /// Seconds of excitation per training log and per held-out log.
    pub train_seconds: f64,
    pub test_seconds: f64,
    /// Seconds of nominal excitation the base model is identified from.
    pub base_seconds: f64,
    /// The cases (default: every effect at both magnitudes, the pairs, fresh nominal logs).
    pub cases: Vec<Case>,
    pub seed: u64,
}

impl Default for SelfCheckOptions {
    fn default() -> Self {
        Self {
            train_seconds: 120.0,
            test_seconds: 60.0,
            base_seconds: 180.0,
            cases: default_cases(),
            seed: 1,
        }
    }
}

/// Fly `seconds` of excitation: the log as flown (with the plant's sensor noise) and the same
/// flight logged without sensor noise.
fn fly(plant: &PlantFile, seconds: f64, seed: u64, label: &str) -> Result<(FlightLog, FlightLog), String> {
    let log = simulate(plant, &SimulateOptions::new(vec![Profile::Excite], vec![seconds], seed))
        .map_err(|e| format!("{label}: {e}"))?;
    let parse = |l: &crate::sim::SimulatedLog, label: &str| parse_log(&l.to_csv(), label).map_err(|e| e.to_string());
    Ok((
        parse(&log, label)?,
        parse(&log.noise_free(), &format!("{label}, noise-free"))?,
    ))
}

/// The nominal plant with realistic sensor noise: what every case starts from.
pub fn base_plant(nominal: &PlantFile, noise: &PlantFile) -> PlantFile {
    let mut p = nominal.clone();
    p.effects.sensor_noise = noise.effects.sensor_noise.clone();
    p
}

/// A SINDy model identified from `logs` the way `uavgen identify --method sindy --sweep --criterion
/// bic` does (physics library, STLSQ, per-row BIC over 16…64, bounded over one horizon).
pub fn identify_base(logs: &[FlightLog]) -> Result<Model, String> {
    let dataset = build(logs, &DatasetOptions::default()).map_err(|e| e.to_string())?;
    let options = SindyOptions {
        sweep: Some(vec![16.0, 20.0, 24.0, 32.0, 40.0, 48.0, 64.0]),
        criterion: Criterion::Bic,
        ..SindyOptions::default()
    };
    let mut fit =
        sindy::fit(&dataset, &options, "selfcheck_base", serde_json::Value::Null).map_err(|e| e.to_string())?;
    if let Some(sel) = select_bounded(&mut fit, &HorizonCheck::default()) {
        if !sel.report.passed() {
            return Err(format!(
                "the nominal model fails the horizon check: {}",
                sel.report.summary()
            ));
        }
    }
    crate::model::parse(&fit.to_json(), "selfcheck_base.json").map_err(|e| e.to_string())
}

/// Run the protocol. `plants` is the directory with `nominal.json` and `effects/*.json`;
/// `progress(done, total, case)` after each case.
pub fn run(
    plants: &std::path::Path,
    options: &SelfCheckOptions,
    progress: &mut dyn FnMut(usize, usize, &str),
) -> Result<SelfCheck, String> {
    let load = |p: std::path::PathBuf| PlantFile::load(&p).map_err(|e| e.to_string());
    let nominal = load(plants.join("nominal.json"))?;
    let noise = load(plants.join("effects/sensor_noise.json"))?;
    let base = base_plant(&nominal, &noise);
    let (base_log, _) = fly(&base, options.base_seconds, options.seed, "nominal (identification)")?;
    let model = identify_base(std::slice::from_ref(&base_log))?;
    let mut results = Vec::with_capacity(options.cases.len());
    for (i, case) in options.cases.iter().enumerate() {
        let plant = case.plant(&base, plants)?;
        let seed = options.seed + 100 * (i as u64 + 1);
        let (train, _) = fly(
            &plant,
            options.train_seconds,
            seed,
            &format!("{} (training)", case.name()),
        )?;
        let (test, reference) = fly(
            &plant,
            options.test_seconds,
            seed + 1,
            &format!("{} (held out)", case.name()),
        )?;
        let diag_options = DiagnoseOptions {
            where_analysis: false,
            ..DiagnoseOptions::default()
        };
        let d = diagnose_with_reference(&model, &[train], &[test], &[reference], &diag_options)
            .map_err(|e| format!("{}: {e}", case.name()))?;
        // The same held-out flight without the effect: the base model's own error there.
        let (_, without) = fly(
            &base,
            options.test_seconds,
            seed + 1,
            &format!("{} (held out, without the effect)", case.name()),
        )?;
        let without = base_side(&model, &[without], &diag_options).map_err(|e| format!("{}: {e}", case.name()))?;
        results.push(CaseResult::new(case, &d, Some(&without)));
        progress(i + 1, options.cases.len(), &case.name());
    }
    Ok(SelfCheck {
        base_model_terms: model_terms(&model),
        results,
    })
}

fn model_terms(model: &Model) -> usize {
    use crate::model::{Dynamics, Row};
    match &model.dynamics {
        Dynamics::Sindy(s) => s
            .rows
            .iter()
            .map(|r| match r {
                Row::Sparse(t) => t.len(),
                Row::Kinematic(_) => 0,
            })
            .sum(),
        Dynamics::Pd(_) => 16,
    }
}
