//! `input_delay = "auto"`: each channel's delay and lag estimated from the logs (the one-step scan,
//! [`response`]), then each delay refined by the refitted model's held-out free runs over one
//! horizon ([`horizon_delay`]). docs/identification.md, "Input delays".

use super::{output, round_s, sindy_fit, stage, IdentifyOptions, Method, OptimizerChoice, Report};
use crate::evaluate::{horizon_score, EvaluateOptions};
use crate::identify::dataset::{build, Dataset, DatasetOptions, Targets};
use crate::identify::excitation::Excitation;
use crate::identify::horizon_delay::{self, HeldOut, RefineOptions};
use crate::identify::loop_refine;
use crate::identify::pd;
use crate::identify::preprocess::SavGol;
use crate::identify::response::{self, InputResponse, ScanOptions, ScanSegment};
use crate::identify::sindy;
use crate::logs::FlightLog;
use crate::model::{parse_term, Term, DEFAULT_INPUTS, DEFAULT_STATES};
use nalgebra::{DMatrix, DVector};

/// The free runs of the delay refinement, s (one MPC horizon).
const REFINE_HORIZON_S: f64 = 1.0;

/// The ridge weights `identify` tries in turn without `alpha` (docs/sindy.md, "Ridge ladder").
pub(super) const RIDGE_LADDER: [f64; 3] = [1e-3, 1e-2, 1e-1];

/// The scan and the refinement, said on `report`; edge estimates added to `warnings`.
#[allow(clippy::too_many_arguments)]
pub(super) fn auto(
    options: &IdentifyOptions,
    logs: &[FlightLog],
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
    dt: f64,
    warnings: &mut Vec<String>,
    report: &dyn Report,
) -> Result<
    (
        InputResponse,
        response::ResponseEstimate,
        Option<horizon_delay::Refinement>,
    ),
    String,
> {
    report.line(
        "estimating input delays and lags (--input-delay auto: delays 0..0.5 s, lags 0.02..0.8 s; held-out one-step error of the driven row, guarded by its loop's held-out free runs) ...",
    );
    let est = stage(report, "estimating input delays and lags", || {
        estimate_response(logs, savgol, ex)
    })?;
    report.line(&format!(
        "  held out: {} {}; per channel: delay (Δχ² = 1 range), lag, one-step and loop free-run RMSE before -> after",
        est.folds, est.fold_kind
    ));
    for c in &est.channels {
        report.line(&format!("  {}", c.line()));
    }
    for c in &est.channels {
        if let Some(d) = c.refused_at_edge {
            let w = format!(
                "{}: the delay estimate {d:.3} s lies at the edge of the 0..{} s scan (the response may lie beyond it, or the data hold no minimum): refused, no delay",
                c.input,
                ScanOptions::default().max_delay
            );
            report.line(&format!("warning: {w}"));
            warnings.push(w);
        }
    }
    let refined = refine_delays(options, logs, &est.response, savgol, targets, ex, dt, report);
    let response = refined.as_ref().map_or(est.response, |r| r.response);
    Ok((response, est, refined))
}

/// Estimate the input response from the logs.
/// The scan always works on the integral form (`h` = 0: no derivative window), whatever targets the
/// fit uses (docs/sindy.md, "Targets").
fn estimate_response(
    logs: &[FlightLog],
    savgol: SavGol,
    ex: &Excitation,
) -> Result<response::ResponseEstimate, String> {
    // The logs' segments as `dataset::build` takes them with the integral targets and no input
    // response (long enough for the Savitzky-Golay window; sample k the interval [t_k, t_{k+1}]),
    // borrowed, not copied (docs/identification.md, "Memory").
    let mut segments = Vec::new();
    for (li, log) in logs.iter().enumerate() {
        for seg in &log.segments {
            let Some(dt) = crate::identify::dataset::usable_step(&seg.t, savgol.window) else {
                continue;
            };
            segments.extend(ScanSegment::interval_of(li, dt, &seg.t, &seg.x, &seg.u));
        }
    }
    if segments.is_empty() {
        return Err(format!(
            "{}: no segment is long enough for the Savitzky-Golay window {} and the input delays (the longest has {} samples)",
            logs.iter().map(|l| l.source.as_str()).collect::<Vec<_>>().join(", "),
            savgol.window,
            logs.iter().flat_map(|l| &l.segments).map(|s| s.t.len()).max().unwrap_or(0)
        ));
    }
    let options = ScanOptions {
        silent: ex.silent(),
        excluded_vars: ex.excluded_vars(),
        ..ScanOptions::default()
    };
    response::estimate(&segments, &options).map_err(|e| e.to_string())
}

/// The second stage ([`horizon_delay`]): each channel's delay chosen by the held-out free runs of
/// the model refitted on 80 % of every segment (its first and its last 20 % held out in turn).
/// `None` (and a line saying why) when the logs are too short to hold a part out or the one-step
/// response cannot be scored.
#[allow(clippy::too_many_arguments)]
fn refine_delays(
    options: &IdentifyOptions,
    logs: &[FlightLog],
    start: &InputResponse,
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
    dt: f64,
    report: &dyn Report,
) -> Option<horizon_delay::Refinement> {
    let refine = RefineOptions {
        fixed: ex.silent(),
        confirm: options.method == Method::Sindy && options.optimizer == OptimizerChoice::Stlsq,
        ..RefineOptions::default()
    };
    let min_rows = refine.min_rows(dt);
    // Long logs: evenly spread excerpts (the stage estimates four delays; its cost follows the log).
    let excerpt = horizon_delay::excerpt_logs(logs, horizon_delay::MAX_REFINE_S, horizon_delay::EXCERPT_S);
    let rows = |l: &[FlightLog]| l.iter().map(|l| l.rows()).sum::<usize>();
    if rows(&excerpt) < rows(logs) {
        report.line(&format!(
            "  delays over the horizon refined on {} s of the logs ({} evenly spread excerpts of at most {} s; the logs are {:.0} s long)",
            horizon_delay::MAX_REFINE_S,
            excerpt.iter().map(|l| l.segments.len()).sum::<usize>(),
            horizon_delay::EXCERPT_S,
            rows(logs) as f64 * dt
        ));
    }
    let splits: Vec<_> = [HeldOut::Tail, HeldOut::Head]
        .into_iter()
        .map(|end| horizon_delay::split_logs(&excerpt, refine.train_share, min_rows, end))
        .collect();
    if splits.iter().any(|(_, test)| test.is_empty()) {
        report.line(&format!(
            "  delays not refined over the horizon: no segment is long enough to hold out {:.0} % of it ({} s; the one-step delays are kept)",
            100.0 * (1.0 - refine.train_share),
            refine.min_part
        ));
        return None;
    }
    let evaluate_options = EvaluateOptions {
        horizon: response::samples(REFINE_HORIZON_S, dt),
        dataset: DatasetOptions {
            savgol,
            ..DatasetOptions::default()
        },
        stale: options.stale,
        ..EvaluateOptions::default()
    };
    // Per split: the held-out horizon RMSE of the model refitted with `r` (free runs every
    // `stride`-th sample, horizon_delay::SCORE_SPACING_S). SINDy (STLSQ, whose coefficients are
    // least squares on the selected terms): the whole sweep is fitted once per split, with the
    // start's response; a candidate refits only the rows its changed channels drive, on the
    // terms the start's fit selected ([`refit_rows`]); the other rows are the start's.
    let stride = horizon_delay::score_stride(dt);
    let row_refit = refine.confirm;
    let mut starts: Vec<Option<(crate::model::SindyFile, InputResponse)>> = vec![None; splits.len()];
    let mut split_rmse = |i: usize, r: &InputResponse, full: bool| -> Option<f64> {
        let (train, test) = &splits[i];
        let model = if row_refit {
            let file = match &starts[i] {
                Some(_) if full => candidate_sindy(options, train, r, savgol, targets, ex)?,
                None => {
                    let file = candidate_sindy(options, train, r, savgol, targets, ex)?;
                    starts[i] = Some((file.clone(), *r));
                    file
                }
                Some((file, r0)) => {
                    let rows: Vec<usize> = (0..4)
                        .filter(|&j| r.delay[j] != r0.delay[j] || r.lag[j] != r0.lag[j])
                        .map(|j| loop_refine::LOOPS[j].row)
                        .collect();
                    refit_rows(file, train, r, &rows, savgol, targets)?
                }
            };
            model_of(options, &serde_json::to_string(&file).ok()?, r)?
        } else {
            candidate_model(options, train, r, savgol, targets, ex)?
        };
        let e = horizon_score(&model, test, &evaluate_options, stride).ok()?;
        // A candidate whose free runs diverge is not a better model, whatever its finite runs say.
        (e.diverged == 0).then_some(e.overall_rmse?)
    };
    // The worse split's RMSE relative to the start's (the first call scores the start).
    let mut reference: Option<Vec<f64>> = None;
    let mut score = |r: &InputResponse, full: bool| -> Option<f64> {
        let rmse: Vec<f64> = (0..splits.len())
            .map(|i| split_rmse(i, r, full))
            .collect::<Option<_>>()?;
        let base = reference.get_or_insert_with(|| rmse.clone());
        rmse.iter().zip(base.iter()).map(|(a, b)| a / b).reduce(f64::max)
    };
    let refined = stage(report, "refining the delays over the horizon", || {
        horizon_delay::refine(start, dt, &refine, &mut score)
    });
    match &refined {
        Some(r) => {
            report.line(&format!(
                "  delays refined over the horizon (model refitted on {:.0} % of every segment{}, free runs of {} samples starting {} sample(s) apart on the rest, its first and its last part in turn; score: the worse part's overall RMSE relative to the one-step delays'): {:.3} -> {:.3}",
                100.0 * refine.train_share,
                if row_refit {
                    " — a candidate refits only the rows its channel drives, on the terms of the fit with the one-step delays; a channel's two best, if at least half the required gain better, are confirmed by the whole refit"
                } else {
                    ""
                },
                evaluate_options.horizon,
                stride,
                r.before,
                r.after
            ));
            for c in &r.channels {
                report.line(&format!(
                    "  {:<10} delay {:.3} s -> {:.3} s (tried {}){}",
                    c.input,
                    c.one_step,
                    c.delay,
                    c.scores
                        .iter()
                        .map(|(d, s)| format!("{d:.3}: {s:.4}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    if c.confirmed.is_empty() {
                        String::new()
                    } else {
                        format!(
                            "; by the whole refit {}",
                            c.confirmed
                                .iter()
                                .map(|(d, s)| format!("{d:.3}: {s:.4}"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    }
                ));
            }
        }
        None => report.line(
            "  delays not refined over the horizon: the model with the one-step delays could not be fitted or its held-out free runs diverged (the one-step delays are kept)",
        ),
    }
    refined
}

/// The data set a candidate is fitted on: `logs` with the input response `r` (`None` if it cannot
/// be built).
fn candidate_dataset(logs: &[FlightLog], r: &InputResponse, savgol: SavGol, targets: Targets) -> Option<Dataset> {
    build(
        logs,
        &DatasetOptions {
            savgol,
            response: Some(*r),
            targets,
            ..DatasetOptions::default()
        },
    )
    .ok()
}

/// The SINDy file `identify` would fit on `logs` with the input response `r` (as
/// [`candidate_model`], before its corrections are attached).
fn candidate_sindy(
    options: &IdentifyOptions,
    logs: &[FlightLog],
    r: &InputResponse,
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
) -> Option<crate::model::SindyFile> {
    let dataset = candidate_dataset(logs, r, savgol, targets)?;
    let alpha = options.alpha.unwrap_or(RIDGE_LADDER[0]);
    let sindy_options = sindy_fit::sindy_options(options, alpha, sindy_fit::sweep(options), ex);
    let fit = sindy::fit_with_progress(
        &dataset,
        &sindy_options,
        "candidate",
        serde_json::json!({}),
        &mut |_, _| {},
    )
    .ok()?;
    Some(fit.file)
}

/// The model of the fitted text `file` with the input response `r` attached.
fn model_of(options: &IdentifyOptions, file: &str, r: &InputResponse) -> Option<crate::model::Model> {
    let text = output::attach(file, options, Some(*r)).ok()?;
    crate::model::parse(&text, "candidate model").ok()
}

/// `file` with the rows `rows` (state indices) refitted on `logs` with the input response `r`:
/// each row's non-zero terms keep their place and take the least-squares coefficients of the
/// data set the fit would see (the same targets, and on the integral form the same averaged
/// library, as `sindy::fit_with_progress`) — what STLSQ's unbiased refit gives for that support.
/// `None` when the data set cannot be built or a row's least squares is not finite.
fn refit_rows(
    file: &crate::model::SindyFile,
    logs: &[FlightLog],
    r: &InputResponse,
    rows: &[usize],
    savgol: SavGol,
    targets: Targets,
) -> Option<crate::model::SindyFile> {
    let mut out = file.clone();
    if rows.is_empty() {
        return Some(out);
    }
    let dataset = candidate_dataset(logs, r, savgol, targets)?;
    let vars: Vec<String> = DEFAULT_STATES
        .iter()
        .chain(DEFAULT_INPUTS.iter())
        .map(|s| s.to_string())
        .collect();
    let n = dataset.len();
    let interval = dataset.is_interval_form();
    for &row in rows {
        let idx: Vec<usize> = (0..out.coefficients.len())
            .filter(|&i| out.coefficients[i].state == DEFAULT_STATES[row] && out.coefficients[i].coefficient != 0.0)
            .collect();
        if idx.is_empty() {
            continue;
        }
        let terms: Vec<Term> = idx
            .iter()
            .map(|&i| parse_term(&out.coefficients[i].term, &vars).ok())
            .collect::<Option<_>>()?;
        let mut x = DMatrix::zeros(n, terms.len());
        let mut y = DVector::zeros(n);
        let mut ends = dataset.interval_ends();
        for (m, (xs, u, dx)) in dataset.samples().enumerate() {
            let v: Vec<f64> = xs.iter().chain(u.iter()).copied().collect();
            let e: Option<Vec<f64>> = if interval {
                Some(ends.next()?.iter().chain(u.iter()).copied().collect())
            } else {
                None
            };
            for (c, t) in terms.iter().enumerate() {
                let a = sindy::eval_term(t, &v);
                x[(m, c)] = match &e {
                    Some(e) => 0.5 * (a + sindy::eval_term(t, e)),
                    None => a,
                };
            }
            y[m] = dx[row];
        }
        let svd = x.svd(true, true);
        let tol = 1e-12 * svd.singular_values.max();
        let coef = svd.solve(&y, tol).ok()?;
        if coef.iter().any(|c| !c.is_finite()) {
            return None;
        }
        for (&i, c) in idx.iter().zip(coef.iter()) {
            out.coefficients[i].coefficient = *c;
        }
    }
    Some(out)
}

/// The model `identify` would fit on `logs` with the input response `r`, quietly and without the
/// horizon check or the ridge ladder (its first rung): a candidate of the delay refinement.
fn candidate_model(
    options: &IdentifyOptions,
    logs: &[FlightLog],
    r: &InputResponse,
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
) -> Option<crate::model::Model> {
    let file = match options.method {
        Method::Sindy => serde_json::to_string(&candidate_sindy(options, logs, r, savgol, targets, ex)?).ok()?,
        Method::Pd => {
            let dataset = candidate_dataset(logs, r, savgol, targets)?;
            let fit = pd::fit(
                &dataset,
                &options.pd_options(ex).ok()?,
                "candidate",
                serde_json::json!({}),
            )
            .ok()?;
            serde_json::to_string(&fit.file).ok()?
        }
    };
    model_of(options, &file, r)
}

/// `provenance.input_response`: what `input_delay = "auto"` found per channel, and the refinement
/// over the horizon.
pub(super) fn input_response_json(
    est: &response::ResponseEstimate,
    refined: Option<&horizon_delay::Refinement>,
) -> serde_json::Value {
    let channels: serde_json::Map<String, serde_json::Value> = est
        .channels
        .iter()
        .map(|c| {
            (
                c.input.to_string(),
                serde_json::json!({
                    "delay": round_s(c.delay),
                    "delay_range": [round_s(c.delay_range.0), round_s(c.delay_range.1)],
                    "lag": c.lag.map(round_s),
                    "lag_range": c.lag_range.map(|(a, b)| [round_s(a), round_s(b)]),
                    "held_out_one_step_rmse": [c.one_step_rmse.0, c.one_step_rmse.1],
                    "held_out_horizon_rmse": [c.horizon_rmse.0, c.horizon_rmse.1, c.horizon_rmse.2],
                    "evidence": c.evidence,
                    "note": c.note,
                    "silent": c.silent,
                    "refused_at_edge": c.refused_at_edge.map(round_s),
                }),
            )
        })
        .collect();
    let mut v = serde_json::json!({
        "held_out": format!("{} {}", est.folds, est.fold_kind),
        "channels": channels,
    });
    if let Some(r) = refined {
        v["refined_over_the_horizon"] = refinement_json(r, &RefineOptions::default());
    }
    v
}

/// The refinement (made with `options`) for the model's provenance.
fn refinement_json(r: &horizon_delay::Refinement, options: &RefineOptions) -> serde_json::Value {
    let channels: serde_json::Map<String, serde_json::Value> = r
        .channels
        .iter()
        .map(|c| {
            (
                c.input.to_string(),
                serde_json::json!({
                    "one_step": round_s(c.one_step),
                    "delay": round_s(c.delay),
                    "scores": c.scores.iter().map(|(d, s)| serde_json::json!([round_s(*d), if s.is_finite() { serde_json::json!(s) } else { serde_json::Value::Null }])).collect::<Vec<_>>(),
                    "confirmed_by_whole_refit": c.confirmed.iter().map(|(d, s)| serde_json::json!([round_s(*d), if s.is_finite() { serde_json::json!(s) } else { serde_json::Value::Null }])).collect::<Vec<_>>(),
                }),
            )
        })
        .collect();
    serde_json::json!({
        "held_out": format!("the first and the last {:.0} % of every segment in turn", 100.0 * (1.0 - options.train_share)),
        "score": "the worse held-out part's horizon RMSE relative to the one-step delays'",
        "score_before_after": [r.before, r.after],
        "channels": channels,
    })
}
