//! SINDy in `identify`: the sparsity sweep, selection by the criterion, rows moved to sparser values
//! until one MPC horizon stays bounded, the ridge ladder, then the loop refinement
//! (docs/sindy.md, docs/identification.md "Loop refinement").

use super::delays::RIDGE_LADDER;
use super::{output, stage, IdentifyOptions, OptimizerChoice, Report};
use crate::identify::bounded_selection::{select_bounded_with, BoundedSelection};
use crate::identify::dataset::Dataset;
use crate::identify::excitation::Excitation;
use crate::identify::horizon_check::{self, HorizonCheck};
use crate::identify::loop_refine;
use crate::identify::response::InputResponse;
use crate::identify::sindy::{self, AicSelection, FittedRows, Optimizer, Regularizer, SindyOptions};

/// The default STLSQ sweep: thresholds on normalised columns (they scale like √N, docs/sindy.md),
/// 0.5 … 256 in steps of √2 (the bounded selection needs sparse values to move rows to).
fn stlsq_sweep() -> Vec<f64> {
    (0..=18)
        .map(|i| 0.5 * 2f64.powf(i as f64 / 2.0))
        .map(|v| (v * 1e3).round() / 1e3)
        .collect()
}

/// The default SR3 sweep, as multiples of `threshold`.
const SR3_SWEEP: [f64; 8] = [0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// The sparsity values the SINDy fit sweeps (`None`: one value, `threshold`).
pub(super) fn sweep(options: &IdentifyOptions) -> Option<Vec<f64>> {
    let threshold = options.threshold.unwrap_or(0.05);
    let sweeping = options.sweep || options.threshold.is_none();
    sweeping.then(|| match (&options.sweep_values, options.optimizer) {
        (Some(v), _) => v.clone(),
        (None, OptimizerChoice::Stlsq) => stlsq_sweep(),
        (None, _) => SR3_SWEEP.iter().map(|f| threshold.max(1e-3) * f).collect(),
    })
}

/// The SINDy options of `options` with ridge weight `alpha`.
pub(super) fn sindy_options(
    options: &IdentifyOptions,
    alpha: f64,
    sweep: Option<Vec<f64>>,
    ex: &Excitation,
) -> SindyOptions {
    let threshold = options.threshold.unwrap_or(0.05);
    let optimizer = match options.optimizer {
        OptimizerChoice::Stlsq => Optimizer::Stlsq {
            threshold,
            alpha,
            max_iter: 20,
            unbias: true,
        },
        OptimizerChoice::Sr3L0 => Optimizer::sr3(Regularizer::L0, threshold),
        OptimizerChoice::Sr3L1 => Optimizer::sr3(Regularizer::L1, threshold),
    };
    SindyOptions {
        library: options.library,
        optimizer,
        sweep,
        selection: AicSelection::PerRow,
        criterion: options.criterion,
        rows: if options.all_rows {
            FittedRows::All
        } else {
            FittedRows::Dynamic
        },
        excluded_vars: ex.excluded_vars(),
        ..SindyOptions::default()
    }
}

/// The SINDy fit of `identify`: the sweep, selection by the criterion, then rows moved to sparser
/// values until one MPC horizon stays bounded; without `alpha` the ridge ladder is climbed until
/// that succeeds (if no rung does, the one with the fewest unbounded trials is kept, for the
/// caller's check to report).
pub(super) fn fit(
    options: &IdentifyOptions,
    dataset: &Dataset,
    logs: usize,
    provenance: serde_json::Value,
    response: Option<InputResponse>,
    ex: &Excitation,
    report: &dyn Report,
) -> Result<String, String> {
    let sweep = sweep(options);
    let ladder: Vec<f64> = match (options.alpha, options.optimizer) {
        (Some(a), _) => vec![a],
        (None, OptimizerChoice::Stlsq) if sweep.is_some() && options.horizon_check => RIDGE_LADDER.to_vec(),
        (None, _) => vec![RIDGE_LADDER[0]],
    };
    report.line(&format!(
        "fitting SINDy on {} samples from {logs} log(s) ...",
        dataset.len()
    ));
    // The fit kept: the first rung that passes, else the one with the fewest unbounded trials.
    let mut fit: Option<(usize, f64, sindy::SindyFit)> = None;
    for (rung, &alpha) in ladder.iter().enumerate() {
        let sindy_options = sindy_options(options, alpha, sweep.clone(), ex);
        report.begin(
            "sparsity values",
            Some(sindy_options.sweep.as_ref().map_or(1, Vec::len)),
        );
        let f = sindy::fit_with_progress(
            dataset,
            &sindy_options,
            &options.name,
            provenance.clone(),
            &mut |done, _| report.advance(done),
        );
        report.end();
        let mut f = f.map_err(|e| e.to_string())?;
        let mut unbounded = 0;
        if sindy_options.sweep.is_some() && options.horizon_check {
            let check = output::horizon_check_options(ex);
            let with = |fit: &sindy::SindyFit| output::attach(&fit.to_json(), options, response);
            let selection = stage(report, &format!("horizon check (ridge α = {alpha})"), || {
                select_bounded_corrected(&mut f, &check, &with)
            });
            if let Some(sel) = selection {
                for (row, from, to) in &sel.moves {
                    report.line(&format!("  horizon check: {row} moved from sparsity {from} to {to}"));
                }
                unbounded = sel.report.unbounded;
                if unbounded > 0 && rung + 1 < ladder.len() {
                    report.line(&format!(
                        "  ridge α = {alpha}: {} of {} horizon-check trials still unbounded; refitting with α = {}",
                        sel.report.unbounded,
                        sel.report.trials,
                        ladder[rung + 1]
                    ));
                }
            }
        }
        let better = match &fit {
            None => true,
            Some((u, _, _)) => unbounded < *u,
        };
        if better {
            fit = Some((unbounded, alpha, f));
        }
        if unbounded == 0 {
            if ladder.len() > 1 {
                report.line(&format!(
                    "  ridge α = {alpha} (the first of {ladder:?} whose selection passes the horizon check)"
                ));
            }
            break;
        }
    }
    let (unbounded, alpha, fit) = fit.ok_or("no SINDy fit")?;
    if unbounded > 0 && ladder.len() > 1 {
        report.line(&format!(
            "  ridge α: no rung of {ladder:?} passes the horizon check; keeping α = {alpha} (the fewest unbounded trials, {unbounded})"
        ));
    }
    for row in &fit.rows {
        report.line(&format!(
            "  {:<10} {:>3} terms, training RMSE {:.4}, R² {:.3}",
            row.state, row.terms, row.rmse, row.r2
        ));
    }
    if fit.rows.iter().all(|r| r.terms == 0) {
        return Err(format!(
            "{}: not written: the fit selected no term in any row (the logs do not excite the dynamics, or --threshold is too large)",
            options.out_label
        ));
    }
    serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())
}

/// [`select_bounded_with`] on the model as it will be written (with its corrections).
fn select_bounded_corrected(
    fit: &mut sindy::SindyFit,
    check: &HorizonCheck,
    with: &dyn Fn(&sindy::SindyFit) -> Result<String, String>,
) -> Option<BoundedSelection> {
    select_bounded_with(fit, &|f| {
        let text = with(f).ok()?;
        let model = crate::model::parse(&text, "identified model").ok()?;
        horizon_check::check(&model, check)
    })
}

/// What [`refine_loops`] gives: the text to write (the refinement recorded in its provenance) and,
/// when a loop was refined, the sparse fit's text to fall back on (its provenance saying so).
pub(super) struct RefinedTexts {
    pub chosen: String,
    pub fallback: Option<String>,
}

/// `refine_loops`: the simulation-error refinement of the loops' rows ([`loop_refine`]), said on
/// `report` and recorded in the provenance (`provenance.loop_refinement`). `None` when it does not
/// run (off, or derivative targets).
pub(super) fn refine_loops(
    options: &IdentifyOptions,
    fitted: &str,
    dataset: &Dataset,
    dt: f64,
    report: &dyn Report,
) -> Result<Option<RefinedTexts>, String> {
    if !options.refine_loops {
        return Ok(None);
    }
    if !dataset.is_interval_form() {
        report.line("loop refinement: skipped (it needs the integral targets, --targets integral)");
        return Ok(None);
    }
    let sparse: crate::model::SindyFile = serde_json::from_str(fitted).map_err(|e| e.to_string())?;
    let mut file = sparse.clone();
    let refine = loop_refine::RefineOptions::for_period(dt);
    report.line(&format!(
        "refining the loops by simulation error (--refine-loops auto: free runs of {} samples every {} samples, at most {} runs, held out by log; kept at a {:.0} % held-out gain) ...",
        refine.horizon,
        refine.stride,
        refine.max_windows,
        100.0 * refine.min_gain
    ));
    let loops_report = stage(report, "refining the loops", || {
        loop_refine::refine(&mut file.coefficients, dataset, &refine)
    });
    for r in &loops_report {
        report.line(&format!("  {}", r.line()));
    }
    let record = loop_refine::record(&refine, &loops_report, "sparse_fit");
    let text = |mut f: crate::model::SindyFile, record: serde_json::Value| -> Result<String, String> {
        if let serde_json::Value::Object(p) = &mut f.provenance {
            p.insert("loop_refinement".into(), record);
        }
        serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
    };
    let fallback = if loops_report.iter().any(|r| r.kept) {
        let mut reverted = record.clone();
        reverted["reverted"] = "the refined model failed the horizon check: the sparse fit's coefficients".into();
        Some(text(sparse, reverted)? + "\n")
    } else {
        None
    };
    Ok(Some(RefinedTexts {
        chosen: text(file, record)?,
        fallback,
    }))
}
