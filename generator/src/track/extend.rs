//! The model's state vector from the plant's 12 measured states: the extra states of a corrected
//! model (docs/model-format.md) are estimated the way a flight computer would.
//!
//! - `<input>_lagged`: the first-order lag of that input, s⁺ = s + (1 − e^{−Δt/τ}) (u − s), run over
//!   the inputs sent (the input held over the sample just flown), starting at the first input;
//! - `flight_time`: the time since the start of the run.

use crate::model::corrections::{FLIGHT_TIME, LAGGED_SUFFIX};
use crate::Model;

/// Estimates the extra states over a closed-loop run.
#[derive(Clone, Debug)]
pub struct StateExtender {
    /// For each extra state: the input index and its time constant, or None for flight_time.
    extra: Vec<Option<(usize, f64)>>,
    values: Vec<f64>,
    dt: f64,
    started: bool,
}

impl StateExtender {
    /// For `model` (12 standard states plus its corrections' extra states) at sample period `dt`.
    pub fn new(model: &Model, dt: f64) -> Result<Self, String> {
        let base = model.base_nx();
        if base != 12 {
            return Err(format!(
                "the model has {base} states; the plant gives the 12 standard ones"
            ));
        }
        let mut extra = Vec::new();
        for name in &model.states[base..] {
            if name == FLIGHT_TIME {
                extra.push(None);
            } else if let Some(input) = name.strip_suffix(LAGGED_SUFFIX) {
                let j = model
                    .inputs
                    .iter()
                    .position(|u| u == input)
                    .ok_or_else(|| format!("extra state {name}: no input {input}"))?;
                let tau = model
                    .corrections
                    .as_ref()
                    .and_then(|c| c.lag(input))
                    .ok_or_else(|| format!("extra state {name}: no actuator_lag for {input}"))?;
                extra.push(Some((j, tau)));
            } else {
                return Err(format!("extra state {name}: not one uavgen track can estimate"));
            }
        }
        Ok(Self {
            values: vec![0.0; extra.len()],
            extra,
            dt,
            started: false,
        })
    }

    /// The full state at time `t` after `last_u` was held over the previous sample.
    pub fn extend(&mut self, measured: &[f64; 12], t: f64, last_u: &[f64]) -> Vec<f64> {
        for (v, e) in self.values.iter_mut().zip(&self.extra) {
            match *e {
                None => *v = t,
                Some((j, tau)) => {
                    let u = last_u.get(j).copied().unwrap_or(0.0);
                    if self.started {
                        // s⁺ = s + (1 − e^{−Δt/τ}) (u − s)
                        *v += (1.0 - (-self.dt / tau).exp()) * (u - *v);
                    } else {
                        *v = u;
                    }
                }
            }
        }
        self.started = true;
        measured.iter().copied().chain(self.values.iter().copied()).collect()
    }
}
