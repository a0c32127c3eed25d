//! The corrected model: the named model effects as the model format's `corrections` block
//! (`crate::model::corrections`), attached to the input model file as it is.
//!
//! Parameters come from the fit on all training data. The format requires drag coefficients and
//! the ground-effect gain ≥ 0 and a thrust gain > −1; a fitted value outside is written clamped
//! (with a note) and the shrink figures use the clamped value too. `stale_samples` has no entry
//! (it is about the data); `latency` is written as the input delays the runtime compensates.

use super::catalogue::{EffectKind, CHANNELS};
use super::problem::State;
use crate::model::{Corrections, Drag, GroundEffect, ThrustDecay};

/// The `corrections` block of the named effects.
pub(crate) fn corrections(
    state: &State,
    linear: &[(EffectKind, Vec<f64>)],
    inputs: &[String],
    rotor_radius: f64,
    source: String,
) -> Corrections {
    let mut c = Corrections {
        source: Some(source),
        ..Corrections::default()
    };
    for (kind, v) in linear {
        match kind {
            EffectKind::LinearDrag => c.linear_drag = Some(Drag { xy: v[0], z: v[1] }),
            EffectKind::QuadraticDrag => c.quadratic_drag = Some(Drag { xy: v[0], z: v[1] }),
            EffectKind::ForceBias => c.force_bias = Some([v[0], v[1], v[2]]),
            EffectKind::ThrustGain => c.thrust_gain = Some(v[0]),
            EffectKind::ThrustDecay => c.thrust_decay = Some(ThrustDecay { per_second: v[0] }),
            EffectKind::GroundEffect => {
                c.ground_effect = Some(GroundEffect {
                    gain: v[0],
                    rotor_radius,
                })
            }
            _ => {}
        }
    }
    for j in 0..4 {
        // The base model's own delay plus the fitted one, when named.
        let fitted = if state.delays_named() {
            state.transform.delay[j]
        } else {
            0.0
        };
        let total = state.transform.base_delay[j] + fitted;
        if total > 0.0 {
            c.latency.insert(inputs[j].clone(), total);
        }
        if let Some(tau) = state.transform.lag[j] {
            c.actuator_lag.insert(inputs[j].clone(), tau);
        }
        if let Some(k) = state.transform.gain[j] {
            c.input_gain.insert(inputs[j].clone(), k);
        }
    }
    for (l, m) in state.transform.loops.iter().enumerate() {
        if let Some(m) = m {
            c.loop_mismatch.insert(
                super::catalogue::loops::name(l).to_string(),
                crate::model::corrections::LoopMismatch {
                    gain: m.gain,
                    coupling: m.coupling,
                },
            );
        }
    }
    for (k, tau) in state.transform.accel_lag.iter().enumerate() {
        if let Some(tau) = tau {
            c.acceleration_lag.insert(CHANNELS[k].to_string(), *tau);
        }
    }
    c
}
