//! The report's lists from the selection: every candidate's entry (named ones with the figures of
//! the round that named them and their parameters after backfitting, the others from the last
//! round), the rounds, and the notes.

use super::catalogue::{self, EffectKind};
use super::data::Prepared;
use super::problem::State;
use super::report_json::{self, EffectReport, RoundEntry, RoundReport};
use super::response_time::ChannelTime;
use super::scored::Candidate;
use super::select::Round;
use super::DiagnoseOptions;

/// The parameters of a named effect after backfitting, where they differ from its round's.
fn final_parameters(
    named: EffectKind,
    state: &State,
    linear: &[(EffectKind, Vec<f64>)],
    rotor_radius: f64,
) -> Option<serde_json::Value> {
    if let Some((_, v)) = linear.iter().find(|(k, _)| *k == named) {
        return Some(report_json::linear_value(named, v, Some(rotor_radius)));
    }
    let t = &state.transform;
    let inputs: Vec<(usize, f64)> = (0..catalogue::inputs::LAG_CHANNELS)
        .filter_map(|j| match named {
            EffectKind::Latency if j < 4 => (t.delay[j] > 0.0).then_some((j, t.delay[j])),
            EffectKind::ActuatorLag => t.lag_of(j).map(|v| (j, v)),
            _ => None,
        })
        .collect();
    if !inputs.is_empty() {
        return Some(report_json::input_value(&inputs));
    }
    match named {
        EffectKind::LoopMismatch => Some(serde_json::Value::Object(
            t.loops
                .iter()
                .enumerate()
                .filter_map(|(l, p)| {
                    p.map(|p| {
                        (
                            catalogue::loops::name(l).to_string(),
                            report_json::loop_value(p.gain, p.coupling),
                        )
                    })
                })
                .collect(),
        )),
        EffectKind::ChannelResponse => Some(serde_json::Value::Object(
            (0..4)
                .filter(|&j| t.gain[j].is_some())
                .map(|j| {
                    let (d, tau) = (t.delay[j], t.lag[j].unwrap_or(0.0));
                    (
                        catalogue::inputs::lag_channel_name(j),
                        serde_json::json!({"delay": d, "lag": tau, "gain": t.gain_of(j), "added_time": d + tau}),
                    )
                })
                .collect(),
        )),
        _ => None,
    }
}

/// Every candidate's report entry: the named ones in order, then the rest of the last round by
/// score.
pub(crate) fn effects(
    rounds: &[Round],
    state: &State,
    linear: &[(EffectKind, Vec<f64>)],
    rotor_radius: f64,
) -> Vec<EffectReport> {
    let mut effects = Vec::new();
    for (r, round) in rounds.iter().enumerate() {
        let Some(named) = round.named else { continue };
        let Some(c) = round.candidates.iter().find(|c| c.kind == named) else {
            continue;
        };
        let mut e = report_json::effect_report(c, r + 1, true, rotor_radius);
        if let Some(p) = final_parameters(named, state, linear, rotor_radius) {
            e.parameters = p;
        }
        effects.push(e);
    }
    if let Some(last) = rounds.last() {
        let mut rest: Vec<&Candidate> = last
            .candidates
            .iter()
            .filter(|c| !state.named.contains(&c.kind))
            .collect();
        rest.sort_by(|a, b| a.delta_bic_test.total_cmp(&b.delta_bic_test));
        let r = rounds.len();
        effects.extend(
            rest.into_iter()
                .map(|c| report_json::effect_report(c, r, false, rotor_radius)),
        );
    }
    effects
}

/// The rounds, each candidate's score, best first.
pub(crate) fn rounds(rounds: &[Round]) -> Vec<RoundReport> {
    rounds
        .iter()
        .enumerate()
        .map(|(r, round)| {
            let mut candidates: Vec<RoundEntry> = round
                .candidates
                .iter()
                .map(|c| RoundEntry {
                    name: c.kind.name().to_string(),
                    score: c.delta_bic_test,
                    heldout_reduction: c.reduction,
                    z: c.z,
                    significant: c.significant,
                })
                .collect();
            candidates.sort_by(|a, b| a.score.total_cmp(&b.score));
            RoundReport {
                round: r + 1,
                named: round.named.map(|k| k.name().to_string()),
                candidates,
            }
        })
        .collect()
}

/// How the residual analysis's cross-correlation (the aircraft's whole response) and the fitted
/// corrections (what the base model lacks of it) relate, channel by channel.
pub(crate) fn xcorr_note(where_report: Option<&crate::analysis::WhereReport>, times: &[ChannelTime]) -> Option<String> {
    let w = where_report?;
    let parts: Vec<String> = w
        .response_lags
        .iter()
        .zip(times)
        .map(|(lag, t)| {
            let x = &lag.xcorr;
            let data = if x.significant && x.localised && x.peak_seconds > 0.0 {
                format!("the data's {} follows {} by {:.2} s", lag.response, lag.input, x.peak_seconds)
            } else if x.significant && x.localised {
                format!(
                    "{} → {}: the cross-correlation peaks at {:.2} s (the state leads the command: feedback, not a delay)",
                    lag.input, lag.response, x.peak_seconds
                )
            } else {
                format!("{} → {}: no localised lag in the data", lag.input, lag.response)
            };
            let ms = |r: &super::response_time::Response| r.t63.map_or("—".to_string(), |v| format!("{v:.2} s"));
            format!(
                "{data}; the base model's {} answers in {} (63 %), the corrected model's in {}",
                t.output,
                ms(&t.base),
                ms(&t.corrected)
            )
        })
        .collect();
    (!parts.is_empty()).then(|| {
        format!(
            "cross-correlation and fits: the cross-correlation measures the aircraft's whole response to a command, the \
             fitted delays, lags and loop gains only what the base model lacks of it (its own loops already take time), \
             so a fitted delay is shorter than the lag in the data; compare the data's lag with the corrected model's \
             response instead: {}",
            parts.join("; ")
        )
    })
}

/// Notes on the data and the named effects.
pub(crate) fn notes(data: &Prepared, state: &State, options: &DiagnoseOptions) -> Vec<String> {
    let mut notes = Vec::new();
    if options.candidates.contains(&EffectKind::GroundEffect) {
        let lowest = data
            .raw
            .iter()
            .filter(|s| !s.holdout)
            .flat_map(|s| {
                s.interior()
                    .filter(|&k| s.airborne[k - s.h])
                    .map(move |k| s.x[k][2].abs())
            })
            .fold(f64::INFINITY, f64::min);
        let one_percent = options.rotor_radius / 4.0 * 99f64.sqrt();
        if lowest > one_percent {
            notes.push(format!(
                "the training logs never fly below z = {lowest:.2} m; the ground effect reaches 1 % of the thrust \
                 only below {one_percent:.2} m (rotor radius {} m), so ground_effect can hardly be detected in them",
                options.rotor_radius
            ));
        }
    }
    if state.named.contains(&EffectKind::StaleSamples) {
        notes.push(
            "stale_samples is about the data, not the model: corrected.json has no entry for it; every figure here \
             treats the repeated rows as missing (interpolated), as identify and evaluate do by default (--stale)"
                .to_string(),
        );
    }
    if state.named.contains(&EffectKind::Latency) || state.named.contains(&EffectKind::ChannelResponse) {
        notes.push(
            "latency is written as input delays (corrections.latency): the runtime compensates them, they are not \
             part of f"
                .to_string(),
        );
    }

    notes
}
