//! A model on a logged segment: the inputs it sees and the initial values of the extra states of
//! its `corrections` (docs/evaluate.md#corrected-models).
//!
//! - Latency: channel i of the model's input at sample k is the logged u_{k−dᵢ},
//!   dᵢ = round(delayᵢ / Δt) with Δt the segment's sample period; before the segment's first
//!   sample the first logged input is assumed.
//! - `<input>_lagged`: the first-order filter ṡ = (u − s)/τ run over those (delayed) inputs from
//!   the segment's first sample, starting at rest (s₀ = u₀), with the inputs held over each sample:
//!   s_{k+1} = u_k + (s_k − u_k) e^{−(t_{k+1} − t_k)/τ} (exact for a zero-order hold).
//! - `flight_time`: t_k − t_start, the time since the segment's start.
//!
//! Without corrections the inputs are the logged ones and there are no extra states.

use super::{NU, NX};
use crate::model::Model;

/// The model's view of one logged input series.
pub(crate) struct ModelInputs {
    /// The input the model sees at every sample.
    pub u: Vec<[f64; NU]>,
    /// The extra states at every sample: the lag states (input order), then the flight time.
    extra: Vec<Vec<f64>>,
}

impl ModelInputs {
    /// `t`, `u`: the series (time stamps and logged inputs); `t_start`: the start of the segment
    /// (for the flight time); `dt`: the sample period the delays are rounded to.
    pub fn new(model: &Model, t: &[f64], u: &[[f64; NU]], t_start: f64, dt: f64) -> Self {
        let Some(c) = &model.corrections else {
            return Self {
                u: u.to_vec(),
                extra: vec![Vec::new(); t.len()],
            };
        };
        let delays: Vec<usize> = model
            .inputs
            .iter()
            .map(|name| (c.delay(name) / dt).round() as usize)
            .collect();
        let delayed: Vec<[f64; NU]> = (0..t.len())
            .map(|k| std::array::from_fn(|i| u[k.saturating_sub(delays[i])][i]))
            .collect();
        let lags: Vec<(usize, f64)> = model
            .inputs
            .iter()
            .enumerate()
            .filter_map(|(i, name)| c.lag(name).map(|tau| (i, tau)))
            .collect();
        let mut s: Vec<f64> = match delayed.first() {
            Some(u0) => lags.iter().map(|&(i, _)| u0[i]).collect(),
            None => Vec::new(),
        };
        let mut extra = Vec::with_capacity(t.len());
        for k in 0..t.len() {
            let mut e = s.clone();
            if c.thrust_decay.is_some() {
                e.push(t[k] - t_start);
            }
            extra.push(e);
            if k + 1 < t.len() {
                let h = t[k + 1] - t[k];
                for (sj, &(i, tau)) in s.iter_mut().zip(&lags) {
                    let uk = delayed[k][i];
                    *sj = uk + (*sj - uk) * (-h / tau).exp();
                }
            }
        }
        Self { u: delayed, extra }
    }

    /// The model's full state at sample k: the logged state `x`, then the extra states.
    pub fn state(&self, x: &[f64; NX], k: usize) -> Vec<f64> {
        x.iter().chain(&self.extra[k]).copied().collect()
    }
}

/// The logged part (the first 12 states) of a model state.
pub(crate) fn logged(x: &[f64]) -> [f64; NX] {
    let mut out = [0.0; NX];
    out.copy_from_slice(&x[..NX]);
    out
}
