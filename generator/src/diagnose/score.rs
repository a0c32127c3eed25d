//! Scoring a candidate: per-channel sums of squared residuals before and after, effective sample
//! sizes, the change of the Bayesian information criterion, the RMSE reduction, and the selection
//! rule.
//!
//! For the affected channels c (each with its own unit), N_c samples, effective N_c/τ_c (τ_c the
//! integrated autocorrelation time of the residual before the effect, the same for every candidate
//! of a round, [`super::fit::integrated_time`]; lags up to 200 samples on training data, up to the
//! Savitzky-Golay window on held-out data: there the correlation counted is the derivative
//! filter's, while slower correlation is the base model's systematic error, whose chance alignment
//! with a candidate the reduction rule guards against) and k parameters:
//!
//! ```text
//! ΔBIC      = Σ_c (N_c/τ_c) ln(SSE_c,after / SSE_c,before) + k ln(mean_c N_c/τ_c)
//! reduction = 1 − √( mean_c SSE_c,after / SSE_c,before )        (relative RMSE reduction)
//! z_LR      = √( max(0, −Σ_c (N_c/τ_c) ln(SSE_c,after / SSE_c,before)) )
//! ```
//!
//! Both are invariant to the units of the channels (only ratios per channel enter), so candidates
//! acting on different channels (drag on vx vy vz, a delay on u_roll on roll_rate) are compared on
//! one scale: ΔBIC is the change of −2 ln(likelihood) of all six channels (the others are
//! unchanged) plus the complexity penalty.

use super::fit::integrated_time;
use serde::Serialize;

/// The selection rule (docs/diagnose.md): an effect is significant when all three hold.
#[derive(Clone, Debug, Serialize)]
pub struct Rules {
    /// Held-out ΔBIC must be below this (default −10: "very strong" evidence).
    pub max_delta_bic: f64,
    /// Held-out RMSE reduction of the affected channels must reach this (default 0.03), both
    /// relative to the model with the effects named so far and as a share of the base model's
    /// RMSE (what the effect adds).
    pub min_reduction: f64,
    /// The parameter must be significantly non-zero on the training data: |θ|/σ_θ above this for
    /// at least one parameter of a linear effect (σ inflated by √τ), the likelihood-ratio z for a
    /// scanned or data effect (default 3).
    pub min_z: f64,
    /// At most this many effects are named (default 3).
    pub max_effects: usize,
}

impl Default for Rules {
    fn default() -> Self {
        Self {
            max_delta_bic: -10.0,
            min_reduction: 0.03,
            min_z: 3.0,
            max_effects: 3,
        }
    }
}

/// Per-channel sums of squared residuals over a set of samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sums {
    pub sse: [f64; 6],
    pub n: usize,
}

impl Sums {
    pub fn add(&mut self, o: &Sums) {
        for c in 0..6 {
            self.sse[c] += o.sse[c];
        }
        self.n += o.n;
    }

    /// Add the samples of `res` that `mask` marks, one at a time (continuing the running sums:
    /// a residual given in pieces sums as in one).
    pub fn push_masked(&mut self, res: &[[f64; 6]], mask: &[bool]) {
        for (r, keep) in res.iter().zip(mask) {
            if *keep {
                for c in 0..6 {
                    self.sse[c] += r[c] * r[c];
                }
                self.n += 1;
            }
        }
    }

    pub fn mse(&self) -> [f64; 6] {
        let n = self.n.max(1) as f64;
        self.sse.map(|s| s / n)
    }

    pub fn rmse(&self) -> [f64; 6] {
        self.mse().map(f64::sqrt)
    }
}

/// Sums over the segments `segs` of per-segment residuals.
pub fn sums(res: &[Vec<[f64; 6]>], segs: &[usize]) -> Sums {
    let mut out = Sums::default();
    for &s in segs {
        for r in &res[s] {
            for c in 0..6 {
                out.sse[c] += r[c] * r[c];
            }
        }
        out.n += res[s].len();
    }
    out
}

/// Sums over the segments `segs`, counting only the samples `mask` marks.
pub fn sums_masked(res: &[Vec<[f64; 6]>], segs: &[usize], mask: &[Vec<bool>]) -> Sums {
    let mut out = Sums::default();
    for &s in segs {
        out.push_masked(&res[s], &mask[s]);
    }
    out
}

/// τ_c per channel (lags up to `max_lag`) of the residuals of `segs` (each a list of per-segment residual arrays).
pub fn taus(parts: &[&[[f64; 6]]], channels: &[usize], max_lag: usize) -> [f64; 6] {
    let mut tau = [1.0; 6];
    for &c in channels {
        let series: Vec<Vec<f64>> = parts.iter().map(|p| p.iter().map(|r| r[c]).collect()).collect();
        let slices: Vec<&[f64]> = series.iter().map(|s| s.as_slice()).collect();
        tau[c] = integrated_time(&slices, max_lag);
    }
    tau
}

/// Σ_c (N/τ_c) ln(SSE_after/SSE_before) over `channels` (the log-likelihood change, −2 Δℓ).
pub fn log_ratio(before: &Sums, after: &Sums, tau: &[f64; 6], channels: &[usize]) -> f64 {
    channels
        .iter()
        .map(|&c| {
            let (b, a) = (before.sse[c], after.sse[c]);
            if b <= 0.0 || a <= 0.0 {
                return 0.0;
            }
            after.n as f64 / tau[c] * (a / b).ln()
        })
        .sum()
}

/// ΔBIC with `k` parameters (see the module documentation).
pub fn delta_bic(before: &Sums, after: &Sums, tau: &[f64; 6], channels: &[usize], k: usize) -> f64 {
    if channels.is_empty() {
        return 0.0;
    }
    let n_eff = channels.iter().map(|&c| after.n as f64 / tau[c]).sum::<f64>() / channels.len() as f64;
    log_ratio(before, after, tau, channels) + k as f64 * n_eff.max(1.0).ln()
}

/// The likelihood-ratio z (see the module documentation).
pub fn lr_z(before: &Sums, after: &Sums, tau: &[f64; 6], channels: &[usize]) -> f64 {
    (-log_ratio(before, after, tau, channels)).max(0.0).sqrt()
}

/// 1 − √(mean_c SSE_after/SSE_before) over `channels`.
pub fn reduction(before: &Sums, after: &Sums, channels: &[usize]) -> f64 {
    let ratios: Vec<f64> = channels
        .iter()
        .filter(|&&c| before.sse[c] > 0.0)
        .map(|&c| (after.sse[c] / after.n.max(1) as f64) / (before.sse[c] / before.n.max(1) as f64))
        .collect();
    if ratios.is_empty() {
        return 0.0;
    }
    1.0 - (ratios.iter().sum::<f64>() / ratios.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_bic_of_a_halved_error() {
        let before = Sums {
            sse: [4.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            n: 100,
        };
        let mut after = before;
        after.sse[0] = 1.0;
        let tau = [2.0; 6];
        // 50 ln(1/4) + 1 · ln 50.
        let d = delta_bic(&before, &after, &tau, &[0], 1);
        assert!((d - (50.0 * 0.25f64.ln() + 50f64.ln())).abs() < 1e-12);
        assert!((reduction(&before, &after, &[0]) - 0.5).abs() < 1e-12);
        assert!((lr_z(&before, &after, &tau, &[0]) - (50.0 * 4f64.ln()).sqrt()).abs() < 1e-12);
    }
}
