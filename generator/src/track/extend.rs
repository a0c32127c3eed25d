//! The model's state vector from the plant's 12 measured states: the extra states of a corrected
//! model (docs/model-format.md) are estimated the way a flight computer would.
//!
//! - `<input>_lagged`: the first-order lag of that input, s⁺ = s + (1 − e^{−Δt/τ}) (u − s), run over
//!   the inputs sent (the input held over the sample just flown), starting at the first input;
//! - `<state>_dot_lagged`: the first-order lag of the base model's row b of that state, with b
//!   linear over the sample just flown between its values at the previous and the current
//!   measured state under the input held over it (`ir::corrections::lag_foh`), starting at rest
//!   (ℓ = b);
//! - `flight_time`: the time since the start of the run.

use crate::ir::corrections::{dot_lag_states, dot_lag_targets, lag_foh};
use crate::model::corrections::{DOT_LAGGED_SUFFIX, FLIGHT_TIME, LAGGED_SUFFIX};
use crate::{Model, ModelIr};

#[derive(Clone, Copy, Debug)]
enum Extra {
    /// The lag of input j with time constant τ.
    Input(usize, f64),
    /// An acceleration lag (advanced with the model's f).
    Dot,
    FlightTime,
}

/// Estimates the extra states over a closed-loop run.
pub struct StateExtender {
    extra: Vec<Extra>,
    values: Vec<f64>,
    /// The acceleration lags: (index in the full state, τ), and the model to evaluate their rows.
    dot_lags: Vec<(usize, f64)>,
    ir: Option<ModelIr>,
    /// The full state of the previous call.
    previous: Vec<f64>,
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
                extra.push(Extra::FlightTime);
            } else if name.ends_with(DOT_LAGGED_SUFFIX) {
                extra.push(Extra::Dot);
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
                extra.push(Extra::Input(j, tau));
            } else {
                return Err(format!("extra state {name}: not one uavgen track can estimate"));
            }
        }
        let dot_lags = dot_lag_states(model);
        Ok(Self {
            values: vec![0.0; extra.len()],
            extra,
            ir: (!dot_lags.is_empty()).then(|| ModelIr::new(model)),
            dot_lags,
            previous: Vec::new(),
            dt,
            started: false,
        })
    }

    /// The full state at time `t` after `last_u` was held over the previous sample.
    pub fn extend(&mut self, measured: &[f64; 12], t: f64, last_u: &[f64]) -> Vec<f64> {
        for (v, e) in self.values.iter_mut().zip(&self.extra) {
            match *e {
                Extra::FlightTime => *v = t,
                Extra::Dot => {}
                Extra::Input(j, tau) => {
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
        let mut z: Vec<f64> = measured.iter().copied().chain(self.values.iter().copied()).collect();
        if let Some(ir) = &self.ir {
            // ℓ over the sample just flown: the base rows at its start and its end under last_u.
            let b1 = dot_lag_targets(&self.dot_lags, &z, &ir.eval_f(&z, last_u));
            let b0 = self
                .started
                .then(|| dot_lag_targets(&self.dot_lags, &self.previous, &ir.eval_f(&self.previous, last_u)));
            for (k, &(i, tau)) in self.dot_lags.iter().enumerate() {
                let ell = match &b0 {
                    Some(b0) => lag_foh(self.previous[i], b0[k], b1[k], self.dt, tau),
                    None => b1[k],
                };
                z[i] = ell;
                self.values[i - 12] = ell;
            }
        }
        self.started = true;
        self.previous.clone_from(&z);
        z
    }
}
