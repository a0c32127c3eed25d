//! A model on a logged segment: the inputs it sees and the initial values of the extra states of
//! its `corrections` (docs/evaluate.md#corrected-models).
//!
//! - Latency: channel i of the model's input at sample k is the logged u_{k−dᵢ},
//!   dᵢ = round(delayᵢ / Δt) with Δt the segment's sample period; before the segment's first
//!   sample the first logged input is assumed.
//! - `<input>_lagged`: the first-order filter ṡ = (u − s)/τ run over those (delayed) inputs from
//!   the segment's first sample, starting at rest (s₀ = u₀), with the inputs held over each sample:
//!   s_{k+1} = u_k + (s_k − u_k) e^{−(t_{k+1} − t_k)/τ} (exact for a zero-order hold).
//! - `<state>_dot_lagged`: the first-order filter ℓ̇ = (b − ℓ)/τ of the base model's row b of that
//!   state, evaluated at the logged states and the inputs the model sees, run from the segment's
//!   first sample (ℓ₀ = b₀) with b linear over each sample between its values at the two ends
//!   under that sample's input (`ir::corrections::lag_foh`).
//! - `flight_time`: t_k − t_start, the time since the segment's start.
//!
//! Without corrections the inputs are the logged ones and there are no extra states.

use super::{NU, NX};
use crate::ir::corrections::{dot_lag_states, dot_lag_targets, lag_foh};
use crate::ir::ModelIr;
use crate::model::Model;

/// The model's view of one logged input series.
pub(crate) struct ModelInputs {
    /// The input the model sees at every sample.
    pub u: Vec<[f64; NU]>,
    /// The extra states at every sample, `width` per sample in one flat series (no allocation
    /// per sample): the lag states (input order), then the flight time.
    extra: Vec<f64>,
    width: usize,
}

impl ModelInputs {
    /// `t`, `u`: the series (time stamps and logged inputs); `t_start`: the start of the segment
    /// (for the flight time); `dt`: the sample period the delays are rounded to.
    pub fn new(
        model: &Model,
        ir: &ModelIr,
        t: &[f64],
        x: &[[f64; NX]],
        u: &[[f64; NU]],
        t_start: f64,
        dt: f64,
    ) -> Self {
        let Some(c) = &model.corrections else {
            return Self {
                u: u.to_vec(),
                extra: Vec::new(),
                width: 0,
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
        let dot_lags = dot_lag_states(model);
        let width = lags.len() + dot_lags.len() + usize::from(c.thrust_decay.is_some());
        let mut extra = Vec::with_capacity(t.len() * width);
        for k in 0..t.len() {
            extra.extend_from_slice(&s);
            extra.extend(std::iter::repeat(0.0).take(dot_lags.len()));
            if c.thrust_decay.is_some() {
                extra.push(t[k] - t_start);
            }
            if k + 1 < t.len() {
                let h = t[k + 1] - t[k];
                for (sj, &(i, tau)) in s.iter_mut().zip(&lags) {
                    let uk = delayed[k][i];
                    *sj = uk + (*sj - uk) * (-h / tau).exp();
                }
            }
        }
        // ℓ: the base rows at both ends of every sample under its input, then the lag over them.
        if !dot_lags.is_empty() && !t.is_empty() {
            let target = |k: usize, u: &[f64; NU]| {
                let z: Vec<f64> = x[k].iter().chain(&extra[k * width..(k + 1) * width]).copied().collect();
                dot_lag_targets(&dot_lags, &z, &ir.eval_f(&z, u))
            };
            let ends: Vec<(Vec<f64>, Vec<f64>)> = (0..t.len() - 1)
                .map(|k| (target(k, &delayed[k]), target(k + 1, &delayed[k])))
                .collect();
            let mut ell = target(0, &delayed[0]);
            for k in 0..t.len() {
                for (i, l) in ell.iter().enumerate() {
                    extra[k * width + lags.len() + i] = *l;
                }
                if let Some((b0, b1)) = ends.get(k) {
                    for (i, &(_, tau)) in dot_lags.iter().enumerate() {
                        ell[i] = lag_foh(ell[i], b0[i], b1[i], t[k + 1] - t[k], tau);
                    }
                }
            }
        }
        Self {
            u: delayed,
            extra,
            width,
        }
    }

    /// The model's full state at sample k: the logged state `x`, then the extra states.
    pub fn state(&self, x: &[f64; NX], k: usize) -> Vec<f64> {
        x.iter()
            .chain(&self.extra[k * self.width..(k + 1) * self.width])
            .copied()
            .collect()
    }
}

/// The logged part (the first 12 states) of a model state.
pub(crate) fn logged(x: &[f64]) -> [f64; NX] {
    let mut out = [0.0; NX];
    out.copy_from_slice(&x[..NX]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::StateExtender;

    /// What `evaluate` reconstructs from a log and what `track`'s extender estimates online from
    /// the same measurements and inputs are the same extra states (input lags, acceleration lags,
    /// flight time).
    #[test]
    fn evaluate_and_track_estimate_the_same_extra_states() {
        let text = r#"{
            "format": "uavgen-model/1", "kind": "sindy", "name": "toy",
            "library": ["u_vz", "u_roll", "sin(roll)", "roll_rate", "roll"],
            "kinematic": [["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
            "coefficients": [
                {"state": "vz", "term": "u_vz", "coefficient": 2.0},
                {"state": "vy", "term": "sin(roll)", "coefficient": -9.81},
                {"state": "roll_rate", "term": "roll_rate", "coefficient": -12.0},
                {"state": "roll_rate", "term": "roll", "coefficient": -80.0},
                {"state": "roll_rate", "term": "u_roll", "coefficient": 80.0}
            ],
            "corrections": {
                "actuator_lag": {"u_roll": 0.08},
                "acceleration_lag": {"vz": 0.05, "roll_rate": 0.03},
                "thrust_decay": {"per_second": -0.001}
            }
        }"#;
        let model = crate::model::parse(text, "toy.json").unwrap();
        let ir = ModelIr::new(&model);
        let dt = 1.0 / 30.0;
        let n: usize = 60;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let x: Vec<[f64; NX]> = t
            .iter()
            .map(|&t| {
                let mut x = [0.0; NX];
                x[3] = 0.2 * (2.0 * t).sin();
                x[8] = 0.5 * (1.3 * t).cos();
                x[9] = 0.4 * (2.0 * t).cos();
                x
            })
            .collect();
        let u: Vec<[f64; NU]> = t
            .iter()
            .map(|&t| [(1.7 * t).sin(), 0.3 * (0.9 * t).cos(), 0.0, 0.0])
            .collect();
        let inputs = ModelInputs::new(&model, &ir, &t, &x, &u, 0.0, dt);
        let mut extender = StateExtender::new(&model, dt).unwrap();
        for k in 0..n {
            let last_u = u[k.saturating_sub(1)];
            let online = extender.extend(&x[k], t[k], &last_u);
            let offline = inputs.state(&x[k], k);
            assert_eq!(online.len(), 16);
            for (i, (a, b)) in online.iter().zip(&offline).enumerate() {
                assert!(
                    (a - b).abs() < 1e-12,
                    "sample {k}, state {i}: track {a} vs evaluate {b}"
                );
            }
        }
    }
}
