//! Identify's PD stage: the bounded least-squares fit ([`pd::fit_refined`]) and, with
//! `refine_loops` (the default), its attitude loops refined by simulation error
//! ([`pd::refine`]; docs/identification.md "Loop refinement").

use super::{stage, IdentifyOptions, Report};
use crate::identify::dataset::{build_for_free_runs, Dataset, DatasetOptions};
use crate::identify::excitation::Excitation;
use crate::identify::pd;
use crate::identify::preprocess::SavGol;
use crate::identify::response::InputResponse;
use crate::logs::FlightLog;

/// The PD model's text and, when a loop was refined, the equation-error fit's text to fall back
/// on should the refined model fail the horizon check. The logs are dropped once the loop
/// refinement's integral form is built from them, before the fit.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit(
    options: &IdentifyOptions,
    logs: Vec<FlightLog>,
    dataset: &Dataset,
    savgol: SavGol,
    response: Option<InputResponse>,
    ex: &Excitation,
    dt: f64,
    provenance: serde_json::Value,
    report: &dyn Report,
) -> Result<(String, Option<String>), String> {
    let pd_options = options.pd_options(ex)?;
    report.line(&format!(
        "fitting the PD model on {} samples from {} log(s) ...",
        dataset.len(),
        logs.len()
    ));
    // The refinement's free runs step over sample intervals: the integral form of the same logs,
    // delays and lags (the fit's own data set when its targets are integral).
    let interval;
    let refinement = if options.refine_loops {
        let data = if dataset.is_interval_form() {
            Some(dataset)
        } else {
            // The refinement's free runs read the states, the interval ends and the inputs: the
            // integral form without its mean slopes.
            match build_for_free_runs(
                &logs,
                &DatasetOptions {
                    savgol,
                    response,
                    ..DatasetOptions::default()
                },
            ) {
                Ok(d) => {
                    interval = d;
                    Some(&interval)
                }
                Err(e) => {
                    report.line(&format!(
                        "loop refinement: skipped (the integral form of the logs: {e})"
                    ));
                    None
                }
            }
        };
        data.map(|d| (d, pd::refine::options_for_period(dt)))
    } else {
        None
    };
    drop(logs);
    if let Some((_, refine)) = &refinement {
        report.line(&format!(
            "then refining its attitude loops by simulation error (--refine-loops auto: ξ2, ξ5, ξ8 and ξ3, ξ6, ξ9 on free runs of {} samples every {} samples, at most {} runs, held out by log or block; kept at a {:.0} % held-out gain)",
            refine.horizon,
            refine.stride,
            refine.max_windows,
            100.0 * refine.min_gain
        ));
    }
    let (fit, refined) = stage(report, "fitting the PD model", || {
        pd::fit_refined(
            dataset,
            &pd_options,
            refinement.as_ref().map(|(d, r)| (*d, r)),
            &options.name,
            provenance,
        )
    })
    .map_err(|e| e.to_string())?;
    let Some(r) = refined else {
        report.line(&fit.diagnostics.summary());
        return Ok((text(&fit)?, None));
    };
    if let Some(unrefined) = &r.unrefined {
        report.line(&format!("equation-error fit:\n{}", unrefined.diagnostics.summary()));
    }
    report.line("loop refinement:");
    for l in &r.loops {
        report.line(&format!("  {}", l.line()));
    }
    if r.unrefined.is_some() {
        report.line("refined model:");
    }
    report.line(&fit.diagnostics.summary());
    let fallback = r.unrefined.as_deref().map(text).transpose()?;
    Ok((text(&fit)?, fallback))
}

fn text(fit: &pd::PdFit) -> Result<String, String> {
    serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())
}
