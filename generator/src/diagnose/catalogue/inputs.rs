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

use serde::Serialize;

/// Delays and lags per input channel (u_vz, u_roll, u_pitch, u_yaw_rate).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct InputTransform {
    /// Pure delay per channel, s (0: none).
    pub delay: [f64; 4],
    /// First-order lag time constant per channel, s.
    pub lag: [Option<f64>; 4],
}

impl InputTransform {
    pub fn is_identity(&self) -> bool {
        self.delay.iter().all(|d| *d == 0.0) && self.lag.iter().all(Option::is_none)
    }

    /// The interval-average inputs the model sees, one per sample of `u`.
    pub fn apply(&self, u: &[[f64; 4]], dt: f64) -> Vec<[f64; 4]> {
        let mut out = u.to_vec();
        for j in 0..4 {
            if self.delay[j] == 0.0 && self.lag[j].is_none() {
                continue;
            }
            let col: Vec<f64> = u.iter().map(|r| r[j]).collect();
            let seen = channel_average(&col, dt, self.delay[j], self.lag[j]);
            for (o, v) in out.iter_mut().zip(seen) {
                o[j] = v;
            }
        }
        out
    }
}

/// The delayed input, interval averages (see the module documentation).
pub fn delayed(u: &[f64], dt: f64, delay: f64) -> Vec<f64> {
    if delay <= 0.0 {
        return u.to_vec();
    }
    let samples = delay / dt;
    let n = samples.floor() as usize;
    let alpha = samples - n as f64;
    let at = |m: usize, back: usize| u[m.saturating_sub(back)];
    (0..u.len())
        .map(|m| (1.0 - alpha) * at(m, n) + alpha * at(m, n + 1))
        .collect()
}

/// The lag state s_m at the sample instants for the zero-order-hold input v (s_0 = v_0).
pub fn lag_states(v: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let a = (-dt / tau).exp();
    let mut s = Vec::with_capacity(v.len());
    let mut cur = v.first().copied().unwrap_or(0.0);
    for &vm in v {
        s.push(cur);
        cur = a * cur + (1.0 - a) * vm;
    }
    s
}

/// What the model sees of one channel over each interval: delayed, then lagged (interval average).
pub fn channel_average(u: &[f64], dt: f64, delay: f64, lag: Option<f64>) -> Vec<f64> {
    let v = delayed(u, dt, delay);
    match lag {
        None => v,
        Some(tau) => {
            let s = lag_states(&v, dt, tau);
            // (τ/Δt)(1 − a) = −(τ/Δt) expm1(−Δt/τ), accurate for small Δt/τ.
            let k = -(tau / dt) * (-dt / tau).exp_m1();
            v.iter().zip(&s).map(|(vm, sm)| vm + (sm - vm) * k).collect()
        }
    }
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
