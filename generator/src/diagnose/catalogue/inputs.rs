//! The input effects: a pure delay and a first-order lag per input channel, applied to the logged
//! (zero-order-hold) commands. The model is evaluated with the **interval average** of what it
//! sees over each sample interval [t_m, t_{m+1}], which is what one sample of integration feels:
//!
//! ```text
//! delay d = (n + α) Δt, 0 ≤ α < 1:   ū_m = (1 − α) u_{m−n} + α u_{m−n−1}      (indices clamped at 0)
//! lag τ on the (delayed) input v:   s_{m+1} = a s_m + (1 − a) v_m,  a = e^{−Δt/τ},  s_0 = v_0
//!                                   s̄_m = v_m + (s_m − v_m) (τ/Δt) (1 − a)
//! ```
//!
//! (exact for the zero-order-hold v; s̄ → v as τ → 0). Delay then lag when a channel has both.

use super::super::residuals::Base;
use super::loops::{LoopParams, NLOOPS};
use serde::Serialize;

/// Lag channels of `actuator_lag`: the 4 inputs, then the 6 acceleration rows (vx … yaw_rate).
pub const LAG_CHANNELS: usize = 10;

/// The name of lag channel j: the input, or `<state>_dot` for an acceleration row.
pub fn lag_channel_name(j: usize) -> String {
    match j {
        0..=3 => crate::logs::INPUT_COLUMNS[j].to_string(),
        _ => format!("{}_dot", super::CHANNELS[j - 4]),
    }
}

/// Delays and lags per input channel (u_vz, u_roll, u_pitch, u_yaw_rate), and lags of the base
/// model's acceleration rows (motor lag: ℓ̇ = (b − ℓ)/τ replaces the row b).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct InputTransform {
    /// Pure delay per channel, s (0: none): the fitted part, on top of `base_delay`.
    pub delay: [f64; 4],
    /// The base model's own delay per channel (its `corrections.latency`).
    pub base_delay: [f64; 4],
    /// First-order lag time constant per channel, s.
    pub lag: [Option<f64>; 4],
    /// First-order lag time constant per acceleration row (vx … yaw_rate), s.
    pub accel_lag: [Option<f64>; 6],
    /// Gain per input channel (`input_gain`: the model sees k times the delayed, lagged input).
    pub gain: [Option<f64>; 4],
    /// `loop_mismatch` per loop (roll, pitch, yaw; [`super::loops`]).
    pub loops: [Option<LoopParams>; NLOOPS],
}

impl InputTransform {
    /// No fitted effect: the base model with its own input response ([`Base::own`]).
    pub(crate) fn of_base(base: &Base) -> Self {
        Self {
            base_delay: base.own.delay,
            lag: base.own.lag,
            ..Self::default()
        }
    }

    pub fn is_identity(&self) -> bool {
        self.delay.iter().chain(&self.base_delay).all(|d| *d == 0.0)
            && self.lag.iter().all(Option::is_none)
            && self.accel_lag.iter().all(Option::is_none)
            && self.loops.iter().all(Option::is_none)
            && self.gain.iter().all(Option::is_none)
    }

    /// The delay channel j sees: the base model's own plus the fitted one.
    pub fn total_delay(&self, j: usize) -> f64 {
        self.base_delay[j] + self.delay[j]
    }

    /// The delays as the corrected model file is run by `uavgen evaluate`, `track` and the
    /// generated crate: each channel's total rounded to whole samples of `dt`
    /// (`ir::delay_samples`), the fitted part adjusted to make up the difference.
    pub fn whole_samples(&self, dt: f64) -> Self {
        let mut t = *self;
        let totals: Vec<f64> = (0..4).map(|j| self.total_delay(j)).collect();
        for (j, n) in crate::ir::delay_samples(&totals, dt).into_iter().enumerate() {
            t.delay[j] = n as f64 * dt - self.base_delay[j];
        }
        t
    }

    /// The gain of input channel j (1 without one).
    pub fn gain_of(&self, j: usize) -> f64 {
        self.gain[j].unwrap_or(1.0)
    }

    /// The base model's f at (x, u) (u: the inputs it sees) with the named loop mismatches.
    pub(crate) fn model_f(&self, base: &Base, x: &[f64; 12], u: &[f64; 4]) -> [f64; 12] {
        let mut f = base.f(x, u);
        if self.loops.iter().any(Option::is_some) {
            super::loops::apply(base, &self.loops, x, u, &mut f);
        }
        f
    }

    /// The lag of lag channel j (see [`LAG_CHANNELS`]).
    pub fn lag_of(&self, j: usize) -> Option<f64> {
        match j {
            0..=3 => self.lag[j],
            _ => self.accel_lag[j - 4],
        }
    }

    pub fn set_lag(&mut self, j: usize, tau: Option<f64>) {
        match j {
            0..=3 => self.lag[j] = tau,
            _ => self.accel_lag[j - 4] = tau,
        }
    }

    /// The smallest time constant of any lag (∞ without lags).
    pub fn fastest_lag(&self) -> f64 {
        self.lag
            .iter()
            .chain(&self.accel_lag)
            .flatten()
            .cloned()
            .fold(f64::INFINITY, f64::min)
    }

    /// The acceleration lags applied to the dynamic rows vx..yaw_rate of f′ (one row per sample;
    /// `ends`: the base rows at the end of each sample under its input): each lagged row c gets the
    /// interval average of its lag minus that of the row, the row going linearly between the two
    /// ends ([`row_lag`]).
    pub fn lag_rows(&self, f: &mut [[f64; 6]], ends: &[[f64; 6]], dt: f64) {
        for c in 0..6 {
            if let Some(tau) = self.accel_lag[c] {
                let b0: Vec<f64> = f.iter().map(|r| r[c]).collect();
                let b1: Vec<f64> = ends.iter().map(|r| r[c]).collect();
                let (_, correction) = row_lag(&b0, &b1, dt, tau);
                for (r, d) in f.iter_mut().zip(correction) {
                    r[c] += d;
                }
            }
        }
    }

    /// The interval-average inputs the model sees, one per sample of `u`.
    pub fn apply(&self, u: &[[f64; 4]], dt: f64) -> Vec<[f64; 4]> {
        let mut out = u.to_vec();
        for j in 0..4 {
            if self.total_delay(j) == 0.0 && self.lag[j].is_none() && self.gain[j].is_none() {
                continue;
            }
            let col: Vec<f64> = u.iter().map(|r| r[j]).collect();
            let seen = channel_average(&col, dt, self.total_delay(j), self.lag[j]);
            let k = self.gain_of(j);
            for (o, v) in out.iter_mut().zip(seen) {
                o[j] = k * v;
            }
        }
        out
    }
}

pub use crate::ir::corrections::{channel_average, delayed, lag_states};

/// The lag of a row b that goes linearly from b0_m to b1_m over sample m (first-order hold):
/// the lag states ℓ_m at the samples (ℓ₀ = b0₀) and, per sample, the interval average of ℓ minus
/// that of b:
///
/// ```text
/// r = (b1_m − b0_m)/Δt,  a = e^{−Δt/τ},  k = (τ/Δt)(1 − a)
/// ℓ_{m+1} = b1_m − rτ + (ℓ_m − b0_m + rτ) a
/// ℓ̄_m − b̄_m = −rτ + (ℓ_m − b0_m + rτ) k
/// ```
pub fn row_lag(b0: &[f64], b1: &[f64], dt: f64, tau: f64) -> (Vec<f64>, Vec<f64>) {
    let k = -(tau / dt) * (-dt / tau).exp_m1();
    let mut ell = b0.first().copied().unwrap_or(0.0);
    let (mut states, mut correction) = (Vec::with_capacity(b0.len()), Vec::with_capacity(b0.len()));
    for (&p, &q) in b0.iter().zip(b1) {
        let rt = (q - p) / dt * tau;
        states.push(ell);
        correction.push(-rt + (ell - p + rt) * k);
        ell = crate::ir::corrections::lag_foh(ell, p, q, dt, tau);
    }
    (states, correction)
}

/// The delay grid in s: 0, step, 2 step, … max (in samples of `dt`).
pub fn delay_grid(max_samples: f64, step_samples: f64, dt: f64) -> Vec<f64> {
    let count = (max_samples / step_samples).round() as usize;
    (0..=count).map(|i| i as f64 * step_samples * dt).collect()
}

/// The default lag grid: `count` time constants spaced logarithmically from `min` to `max` s.
pub fn lag_grid(min: f64, max: f64, count: usize) -> Vec<f64> {
    if count < 2 {
        return vec![min];
    }
    let r = (max / min).ln() / (count - 1) as f64;
    (0..count).map(|i| min * (r * i as f64).exp()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delay_interpolates_the_held_input() {
        let u = [0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        assert_eq!(delayed(&u, 0.1, 0.0), u.to_vec());
        let d = delayed(&u, 0.1, 0.1);
        assert_eq!(d, vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let d = delayed(&u, 0.1, 0.125);
        assert!((d[3] - 0.75).abs() < 1e-12 && d[2] == 0.0 && d[4] == 1.0);
    }

    /// ℓ̇ = (b − ℓ)/τ integrated finely for a row that jumps at the samples and is linear within
    /// them: the states and the interval-average corrections of [`row_lag`] are exact, and
    /// `ir::corrections::lag_foh` (what `track` and `evaluate` use) gives the same states.
    #[test]
    fn row_lag_is_exact_for_a_row_linear_within_each_sample() {
        let (dt, tau) = (0.1, 0.05);
        let b0 = [1.0, -0.5, 0.3, 0.3];
        let b1 = [2.0, 0.5, 0.3, -1.0];
        let (states, correction) = row_lag(&b0, &b1, dt, tau);
        let fine = 200_000;
        let h = dt / fine as f64;
        let mut ell = b0[0];
        for m in 0..4 {
            assert!((states[m] - ell).abs() < 1e-5, "sample {m}: {} vs {ell}", states[m]);
            let next = crate::ir::corrections::lag_foh(states[m], b0[m], b1[m], dt, tau);
            let (mut sum_l, mut sum_b) = (0.0, 0.0);
            for i in 0..fine {
                // Midpoint rule on ℓ̇ = (b − ℓ)/τ.
                let t = (i as f64 + 0.5) * h;
                let b = b0[m] + (b1[m] - b0[m]) * t / dt;
                let mid = ell + 0.5 * h * (b - ell) / tau;
                sum_l += mid * h;
                sum_b += b * h;
                ell += h * (b - mid) / tau;
            }
            assert!((next - ell).abs() < 1e-5, "sample {m}: lag_foh {next} vs {ell}");
            let exact = (sum_l - sum_b) / dt;
            assert!(
                (correction[m] - exact).abs() < 1e-5,
                "sample {m}: {} vs {exact}",
                correction[m]
            );
        }
    }

    #[test]
    fn lag_channels_name_inputs_then_rows() {
        let mut t = InputTransform::default();
        t.set_lag(1, Some(0.1));
        t.set_lag(7, Some(0.04));
        assert_eq!((t.lag[1], t.accel_lag[3]), (Some(0.1), Some(0.04)));
        assert_eq!((t.lag_of(1), t.lag_of(7), t.lag_of(4)), (Some(0.1), Some(0.04), None));
        assert_eq!(t.fastest_lag(), 0.04);
        assert!(!t.is_identity());
        assert_eq!(
            (lag_channel_name(1), lag_channel_name(7)),
            ("u_roll".to_string(), "roll_rate_dot".to_string())
        );
    }

    #[test]
    fn lag_average_is_the_exact_mean_over_the_interval() {
        let (dt, tau) = (0.1, 0.2);
        let u = [0.0, 1.0, 1.0, 1.0];
        let avg = channel_average(&u, dt, 0.0, Some(tau));
        // Interval 1 starts at s = 0 with input 1: mean of 1 − e^{−t/τ} over [0, Δt].
        let exact = 1.0 - tau / dt * (1.0 - (-dt / tau).exp());
        assert!((avg[1] - exact).abs() < 1e-12);
        // Tiny τ: the input itself.
        let avg = channel_average(&u, dt, 0.0, Some(1e-6));
        assert!((avg[1] - 1.0).abs() < 1e-4);
    }
}
