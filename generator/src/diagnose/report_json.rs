//! The JSON shapes of report.json (every field is documented in docs/diagnose.md).

use super::catalogue::inputs::lag_channel_name;
use super::catalogue::linear::parameter_names;
use super::catalogue::loops;
use super::catalogue::{EffectKind, CHANNELS};
use super::scored::ChannelFit as ResponseFit;
use super::scored::{Candidate, Params};
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;

/// One scanned input channel of `latency` or `actuator_lag`.
#[derive(Clone, Debug, Serialize)]
pub struct InputScan {
    pub input: String,
    /// Delay or time constant fitted on the training data, s.
    pub value: f64,
    /// A delay refined over the horizon: the one-step optimum (to which `sigma` and `z` belong)
    /// and the residual cross-correlation's delay, between which it was chosen.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub one_step: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cross_correlation: Option<f64>,
    pub sigma: Option<f64>,
    /// Likelihood-ratio z of this channel alone.
    pub z: f64,
    /// Part of the effect.
    pub kept: bool,
    /// Why a channel that moved is not part of the effect (z, a stronger channel on the same
    /// rows, or the horizon rule).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_kept: Option<String>,
}

/// One catalogued effect in report.json.
#[derive(Clone, Debug, Serialize)]
pub struct EffectReport {
    pub name: String,
    /// The fitted parameters in the form of the `corrections` block (null when not applicable).
    pub parameters: Value,
    /// Standard errors, same shape (null where not defined).
    pub uncertainty: Value,
    /// Held-out one-step RMSE of the affected channels before and after the effect.
    pub heldout_rmse_before: BTreeMap<String, f64>,
    pub heldout_rmse_after: BTreeMap<String, f64>,
    /// The same on the training data (the fit's own data).
    pub training_rmse_before: BTreeMap<String, f64>,
    pub training_rmse_after: BTreeMap<String, f64>,
    /// Mean effective sample size N/τ of the scored channels' residuals after the effect, on the
    /// held-out and the training data (what ΔBIC and z count).
    pub heldout_effective_samples: f64,
    pub training_effective_samples: f64,
    /// Parameters the effect adds (for latency and actuator_lag: the channels kept).
    pub parameter_count: usize,
    /// Held-out ΔBIC (lower is better; the ranking key).
    pub score: f64,
    /// 1 − √(mean over the affected channels of MSE_after/MSE_before), held out.
    pub heldout_reduction: f64,
    /// The reduction as a share of the base model's held-out RMSE: what this effect adds to the
    /// effects named before it (= heldout_reduction in round 1).
    pub heldout_reduction_of_base: f64,
    pub delta_bic_train: f64,
    pub z: f64,
    /// The horizon rule: mean over the 12 states of the held-out MSE ratio after/before of free
    /// runs over the horizon (≤ 1 to be named; null when another rule failed first).
    pub heldout_horizon_ratio: Option<f64>,
    pub significant: bool,
    /// Named in the verdict.
    pub selected: bool,
    /// The round of the greedy selection these figures are from (1-based).
    pub round: usize,
    /// Why it is not significant.
    pub reasons: Vec<String>,
    pub channels: Vec<String>,
    pub meaning: String,
    /// Per input channel, for latency and actuator_lag.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scan: Option<Vec<InputScan>>,
    /// Per input channel, for channel_response.
    #[serde(rename = "channels_fitted", skip_serializing_if = "Option::is_none")]
    pub channels_scan: Option<Vec<ChannelScan>>,
    /// Per loop, for loop_mismatch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub loops: Option<Vec<LoopScan>>,
}

/// One fitted channel of `channel_response`.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelScan {
    pub input: String,
    /// Delay d, s.
    pub delay: f64,
    pub delay_sigma: Option<f64>,
    /// Lag τ, s (0: none).
    pub lag: f64,
    pub lag_sigma: Option<f64>,
    /// Gain k.
    pub gain: f64,
    pub gain_sigma: f64,
    /// d + τ, s.
    pub added_time: f64,
    /// The cross-correlation's delay that seeded the scan, s.
    pub seed: Option<f64>,
    pub z: f64,
    pub kept: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_kept: Option<String>,
}

/// One fitted loop of `loop_mismatch`.
#[derive(Clone, Debug, Serialize)]
pub struct LoopScan {
    /// The loop's rate state (roll_rate, pitch_rate, yaw_rate).
    pub rate_state: String,
    pub gain: f64,
    pub gain_sigma: f64,
    pub coupling: f64,
    pub coupling_sigma: f64,
    pub z: f64,
    pub kept: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_kept: Option<String>,
}

fn object(names: &[&str], values: &[f64]) -> Value {
    Value::Object(
        names
            .iter()
            .zip(values)
            .map(|(n, v)| (n.to_string(), json!(v)))
            .collect(),
    )
}

/// A linear effect's values in the form of the `corrections` block (`radius`: the ground
/// effect's rotor radius, null in the uncertainty).
pub(crate) fn linear_value(kind: EffectKind, values: &[f64], radius: Option<f64>) -> Value {
    match kind {
        EffectKind::ForceBias => json!(values),
        EffectKind::ThrustGain => json!(values[0]),
        EffectKind::GroundEffect => json!({"gain": values[0], "rotor_radius": radius}),
        k => object(parameter_names(k), values),
    }
}

/// The delays or lags of `inputs` (lag channel index, value) as an object keyed by input name
/// (`<state>_dot` for the lag of an acceleration row).
pub(crate) fn input_value(inputs: &[(usize, f64)]) -> Value {
    Value::Object(inputs.iter().map(|(j, v)| (lag_channel_name(*j), json!(v))).collect())
}

/// One loop's parameters as reported: gain, coupling and the bandwidth ratio √gain.
pub(crate) fn loop_value(gain: f64, coupling: f64) -> Value {
    json!({"gain": gain, "coupling": coupling, "bandwidth_ratio": loops::bandwidth_ratio(gain)})
}

/// `parameters` and `uncertainty` of a candidate.
fn parameters(c: &Candidate, rotor_radius: f64) -> (Value, Value) {
    match &c.params {
        Params::Linear { values, sigma } => (
            linear_value(c.kind, values, Some(rotor_radius)),
            linear_value(c.kind, sigma, None),
        ),
        Params::Input(scan) => {
            let kept: Vec<_> = scan.iter().filter(|s| s.kept).collect();
            // Without a kept channel: the best one if it moved at all.
            let shown: Vec<_> = if kept.is_empty() {
                scan.iter()
                    .max_by(|a, b| a.z.total_cmp(&b.z))
                    .filter(|s| s.value > 0.0)
                    .into_iter()
                    .collect()
            } else {
                kept
            };
            let p = shown.iter().map(|s| (lag_channel_name(s.input), json!(s.value)));
            let u = shown.iter().map(|s| (lag_channel_name(s.input), json!(s.sigma)));
            (Value::Object(p.collect()), Value::Object(u.collect()))
        }
        Params::Response(fits) => {
            let kept: Vec<_> = fits.iter().filter(|f| f.kept).collect();
            let shown: Vec<_> = if kept.is_empty() {
                fits.iter().max_by(|a, b| a.z.total_cmp(&b.z)).into_iter().collect()
            } else {
                kept
            };
            let name = |f: &&ResponseFit| lag_channel_name(f.input);
            let p = shown.iter().map(|f| {
                (
                    name(f),
                    json!({"delay": f.delay, "lag": f.lag, "gain": f.gain, "added_time": f.added_time()}),
                )
            });
            let u = shown.iter().map(|f| {
                (
                    name(f),
                    json!({"delay": f.delay_sigma, "lag": f.lag_sigma, "gain": f.gain_sigma}),
                )
            });
            (Value::Object(p.collect()), Value::Object(u.collect()))
        }
        Params::Loop(fits) => {
            let kept: Vec<_> = fits.iter().filter(|f| f.kept).collect();
            let shown: Vec<_> = if kept.is_empty() {
                fits.iter().max_by(|a, b| a.z.total_cmp(&b.z)).into_iter().collect()
            } else {
                kept
            };
            let p = shown
                .iter()
                .map(|f| (loops::name(f.l).to_string(), loop_value(f.gain, f.coupling)));
            let u = shown.iter().map(|f| {
                (
                    loops::name(f.l).to_string(),
                    json!({"gain": f.gain_sigma, "coupling": f.coupling_sigma}),
                )
            });
            (Value::Object(p.collect()), Value::Object(u.collect()))
        }
        Params::Stale {
            train_rows,
            train_total,
            holdout_rows,
            holdout_total,
        } => (
            json!({
                "training_rows": train_rows,
                "training_fraction": *train_rows as f64 / (*train_total).max(1) as f64,
                "heldout_rows": holdout_rows,
                "heldout_fraction": *holdout_rows as f64 / (*holdout_total).max(1) as f64,
            }),
            Value::Null,
        ),
        Params::NotApplicable => (Value::Null, Value::Null),
    }
}

/// The report entry of a candidate evaluated in `round` (1-based).
pub fn effect_report(c: &Candidate, round: usize, selected: bool, rotor_radius: f64) -> EffectReport {
    let (parameters, uncertainty) = parameters(c, rotor_radius);
    let (before, after) = (c.test_before.rmse(), c.test_after.rmse());
    let pick = |v: [f64; 6]| c.channels.iter().map(|&ch| (CHANNELS[ch].to_string(), v[ch])).collect();
    EffectReport {
        name: c.kind.name().to_string(),
        parameters,
        uncertainty,
        heldout_rmse_before: pick(before),
        heldout_rmse_after: pick(after),
        training_rmse_before: pick(c.train_before.rmse()),
        training_rmse_after: pick(c.train_after.rmse()),
        parameter_count: c.k,
        heldout_effective_samples: c.test_n_eff,
        training_effective_samples: c.train_n_eff,
        score: c.delta_bic_test,
        heldout_reduction: c.reduction,
        heldout_reduction_of_base: c.reduction_of_base,
        delta_bic_train: c.delta_bic_train,
        z: c.z,
        heldout_horizon_ratio: c.horizon_ratio,
        significant: c.significant,
        selected,
        round,
        reasons: c.reasons.clone(),
        channels: c.channels.iter().map(|&ch| CHANNELS[ch].to_string()).collect(),
        meaning: c.kind.meaning().to_string(),
        channels_scan: match &c.params {
            Params::Response(fits) => Some(
                fits.iter()
                    .map(|f| ChannelScan {
                        input: lag_channel_name(f.input),
                        delay: f.delay,
                        delay_sigma: f.delay_sigma,
                        lag: f.lag,
                        lag_sigma: f.lag_sigma,
                        gain: f.gain,
                        gain_sigma: f.gain_sigma,
                        added_time: f.added_time(),
                        seed: f.seed,
                        z: f.z,
                        kept: f.kept,
                        not_kept: f.not_kept.clone(),
                    })
                    .collect(),
            ),
            _ => None,
        },
        loops: match &c.params {
            Params::Loop(fits) => Some(
                fits.iter()
                    .map(|f| LoopScan {
                        rate_state: loops::name(f.l).to_string(),
                        gain: f.gain,
                        gain_sigma: f.gain_sigma,
                        coupling: f.coupling,
                        coupling_sigma: f.coupling_sigma,
                        z: f.z,
                        kept: f.kept,
                        not_kept: f.not_kept.clone(),
                    })
                    .collect(),
            ),
            _ => None,
        },
        scan: match &c.params {
            Params::Input(scan) => Some(
                scan.iter()
                    .map(|s| InputScan {
                        input: lag_channel_name(s.input),
                        value: s.value,
                        one_step: s.one_step,
                        cross_correlation: s.seed,
                        sigma: s.sigma,
                        z: s.z,
                        kept: s.kept,
                        not_kept: s.not_kept.clone(),
                    })
                    .collect(),
            ),
            _ => None,
        },
    }
}

/// One candidate's score in one round.
#[derive(Clone, Debug, Serialize)]
pub struct RoundEntry {
    pub name: String,
    pub score: f64,
    pub heldout_reduction: f64,
    pub z: f64,
    pub significant: bool,
}

/// One round of the greedy selection.
#[derive(Clone, Debug, Serialize)]
pub struct RoundReport {
    pub round: usize,
    /// The effect named in this round (null: the selection stopped).
    pub named: Option<String>,
    /// Every candidate, best score first.
    pub candidates: Vec<RoundEntry>,
}
