//! A base model that already carries an input response: `uavgen identify --input-delay auto`
//! writes the delays (and lags) it found as `corrections.latency` / `corrections.actuator_lag`.
//!
//! Diagnosis takes them as part of the base: the model's f with its inputs delayed and lagged as
//! the block says (the "before" figures are those of `uavgen evaluate` on the model file as it
//! is). A fitted delay adds to the model's own (channel j sees u(t − d_model − d_fitted)); a
//! fitted lag, gain or loop mismatch acts on top and replaces the model's lag of that channel.
//! corrected.json carries the totals. Any other correction in the block (drag, biases, …) is
//! refused: diagnose the model without it.

use super::residuals::OwnResponse;
use super::DiagnoseError;
use crate::model::{Corrections, Model};

/// The model without its `corrections` block (and without the extra states the block adds), and
/// the input response the block gives (the identity without a block).
pub(crate) fn split(model: &Model) -> Result<(Model, OwnResponse), DiagnoseError> {
    let Some(c) = &model.corrections else {
        return Ok((model.clone(), OwnResponse::default()));
    };
    let response_only = Corrections {
        source: None,
        latency: Default::default(),
        actuator_lag: Default::default(),
        ..c.clone()
    };
    if response_only != Corrections::default() {
        return Err(DiagnoseError::HasCorrections {
            model: model.name.clone(),
        });
    }
    let mut own = OwnResponse::default();
    for (j, input) in model.inputs.iter().enumerate().take(4) {
        own.delay[j] = c.latency.get(input).copied().unwrap_or(0.0);
        own.lag[j] = c.actuator_lag.get(input).copied();
    }
    let extra = c.extra_states(&model.inputs).len();
    let mut stripped = model.clone();
    stripped.states.truncate(stripped.states.len() - extra);
    stripped.corrections = None;
    Ok((stripped, own))
}

/// What the report says about the model's own input response (None without one).
pub(crate) fn note(own: &OwnResponse, inputs: &[String]) -> Option<String> {
    let parts: Vec<String> = (0..4)
        .filter_map(|j| {
            let d = own.delay[j];
            let lag = own.lag[j];
            if d == 0.0 && lag.is_none() {
                return None;
            }
            let mut s = format!("{} delay {d:.4} s", inputs[j]);
            if let Some(tau) = lag {
                s += &format!(", lag {tau:.4} s");
            }
            Some(s)
        })
        .collect();
    (!parts.is_empty()).then(|| {
        format!(
            "The model carries an input response of its own ({}): it is part of the base model here (the \"before\" \
             figures are the model file's, as `uavgen evaluate` gives them). Fitted delays add to it, fitted lags \
             replace the model's lag of that channel; corrected.json holds the totals.",
            parts.join("; ")
        )
    })
}
