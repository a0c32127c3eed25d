//! Lagged relations between inputs and residuals: the normalised cross-correlation input →
//! residual at lags −L..L, raw and after prewhitening the input (a localised peak at a positive
//! lag reveals an unmodelled delay), and the input → response lag of the data itself
//! (prewhitened cross-correlation of each input with the state whose derivative it drives).

use super::stats::{self, cross_correlation_at, demean_by_segment};
use super::{n_eff_pair_from_acfs, Prepared, WhereInput, WhereOptions, INPUT_COLUMNS, STATE_COLUMNS};
use serde::Serialize;
use std::ops::Range;

/// The cross-correlation of one input with one channel's one-step residual.
#[derive(Clone, Debug, Serialize)]
pub struct CrossCorrelation {
    pub input: String,
    pub channel: String,
    /// L: the ρ vectors hold lags −L … L.
    pub max_lag: usize,
    /// ρ(ℓ) = Σ u_t r_{t+ℓ} / √(Σu² Σr²), ℓ = −L … L (positive: the input leads the residual).
    pub rho: Vec<f64>,
    /// Lag of the largest |ρ| (samples) and in seconds.
    pub peak_lag: isize,
    pub peak_seconds: f64,
    pub peak_rho: f64,
    /// ρ(0).
    pub rho_zero: f64,
    /// Bartlett effective sample size of the pair.
    pub n_eff: f64,
    /// 2 / √n_eff.
    pub bound: f64,
    /// |peak_rho| > bound.
    pub significant: bool,
    /// The same after prewhitening: input and residual filtered by the input's AR model.
    pub prewhitened: Prewhitened,
}

/// A cross-correlation of a prewhitened input with a series filtered alike (Box-Jenkins): for a
/// linear relation it is proportional to the impulse response, so its peak localises a delay.
#[derive(Clone, Debug, Serialize)]
pub struct Prewhitened {
    /// Order p of the input's AR model (Yule-Walker).
    pub order: usize,
    /// ρ(ℓ), ℓ = −L … L.
    pub rho: Vec<f64>,
    pub peak_lag: isize,
    pub peak_seconds: f64,
    pub peak_rho: f64,
    /// Median |ρ| over the lags: the background level.
    pub median_abs: f64,
    pub n_eff: f64,
    /// 2 / √n_eff.
    pub bound: f64,
    /// |peak_rho| > bound.
    pub significant: bool,
    /// |peak_rho| − median_abs > 2 bound: the peak stands out from the background.
    pub localised: bool,
}

/// How long after an input the state it drives responds, from the data alone.
#[derive(Clone, Debug, Serialize)]
pub struct ResponseLag {
    pub input: String,
    /// The driven state (u_vz → vz, u_roll → roll_rate, u_pitch → pitch_rate, u_yaw_rate → yaw_rate).
    pub response: String,
    /// Prewhitened input → state cross-correlation.
    #[serde(flatten)]
    pub xcorr: Prewhitened,
}

/// The index of the state whose derivative input j drives: u_vz → vz, u_roll → roll_rate,
/// u_pitch → pitch_rate, u_yaw_rate → yaw_rate.
pub const DRIVEN_STATE: [usize; 4] = [8, 9, 10, 11];

/// ρ(ℓ) for ℓ in `lags` of two demeaned series within segments.
pub fn cross_correlation(x: &[f64], y: &[f64], ranges: &[Range<usize>], lags: impl Iterator<Item = isize>) -> Vec<f64> {
    lags.map(|l| cross_correlation_at(x, y, ranges, l)).collect()
}

/// Index and value of the largest |ρ| (the first one on ties).
fn peak(rho: &[f64]) -> (usize, f64) {
    rho.iter().enumerate().fold(
        (0, 0.0),
        |(bi, bv), (i, v)| if v.abs() > bv.abs() { (i, *v) } else { (bi, bv) },
    )
}

/// Yule-Walker AR(p) coefficients a₁ … a_p (x_t ≈ Σ aᵢ x_{t−i}) from autocorrelations ρ_0 … ρ_p
/// by the Levinson-Durbin recursion; stops early if the prediction error vanishes.
pub fn yule_walker(rho: &[f64], order: usize) -> Vec<f64> {
    let order = order.min(rho.len().saturating_sub(1));
    let mut a: Vec<f64> = Vec::new();
    let mut err = rho.first().copied().unwrap_or(0.0);
    for k in 1..=order {
        if err <= 1e-12 {
            break;
        }
        let acc = rho[k] - (1..k).map(|j| a[j - 1] * rho[k - j]).sum::<f64>();
        let kk = acc / err;
        let mut next = a.clone();
        for j in 1..k {
            next[j - 1] = a[j - 1] - kk * a[k - j - 1];
        }
        next.push(kk);
        a = next;
        err *= 1.0 - kk * kk;
    }
    a
}

/// e_t = x_t − Σ aᵢ x_{t−i} within segments (the first p samples of each segment are NaN).
pub fn ar_filter(x: &[f64], a: &[f64], ranges: &[Range<usize>]) -> Vec<f64> {
    let mut e = vec![f64::NAN; x.len()];
    for r in ranges {
        for t in (r.start + a.len())..r.end {
            e[t] = x[t] - a.iter().enumerate().map(|(i, ai)| ai * x[t - 1 - i]).sum::<f64>();
        }
    }
    e
}

/// Prewhitened cross-correlation of a demeaned input `u` (AR coefficients `a`) with a demeaned
/// series `y`, lags −L … L.
pub fn prewhitened(
    u: &[f64],
    y: &[f64],
    a: &[f64],
    ranges: &[Range<usize>],
    max_lag: usize,
    dt: f64,
    acf_lags: usize,
) -> Prewhitened {
    let (eu, ey) = (ar_filter(u, a, ranges), ar_filter(y, a, ranges));
    let l = max_lag as isize;
    let rho = cross_correlation(&eu, &ey, ranges, -l..=l);
    let (i, value) = peak(&rho);
    let mut abs: Vec<f64> = rho.iter().map(|v| v.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let median_abs = if abs.is_empty() {
        0.0
    } else {
        stats::quantile_sorted(&abs, 0.5)
    };
    let eu = demean_by_segment(&eu, ranges);
    let ey = demean_by_segment(&ey, ranges);
    let n_eff = stats::effective_n_pair(&eu, &ey, ranges, acf_lags);
    let bound = 2.0 / n_eff.max(1.0).sqrt();
    let peak_lag = i as isize - l;
    Prewhitened {
        order: a.len(),
        peak_lag,
        peak_seconds: peak_lag as f64 * dt,
        peak_rho: value,
        median_abs,
        n_eff,
        bound,
        significant: value.abs() > bound,
        localised: value.abs() - median_abs > 2.0 * bound,
        rho,
    }
}

/// The input → residual cross-correlations, input-major.
pub(crate) fn cross_correlations(input: &WhereInput, p: &Prepared, options: &WhereOptions) -> Vec<CrossCorrelation> {
    let l = options.max_lag as isize;
    let mut out = Vec::new();
    for j in 0..4 {
        let a = yule_walker(&p.inputs_acf[j], options.prewhiten_order);
        for (c, name) in input.channels.iter().enumerate() {
            let (u, r) = (&p.inputs[j], &p.one_step[c]);
            let rho = cross_correlation(u, r, &p.ranges, -l..=l);
            let (i, peak_rho) = peak(&rho);
            let n = r.iter().filter(|v| v.is_finite()).count();
            let n_eff = n_eff_pair_from_acfs(&p.inputs_acf[j], &p.one_step_acf[c], n);
            let bound = 2.0 / n_eff.max(1.0).sqrt();
            let peak_lag = i as isize - l;
            out.push(CrossCorrelation {
                input: INPUT_COLUMNS[j].to_string(),
                channel: name.clone(),
                max_lag: options.max_lag,
                rho_zero: rho[l as usize],
                peak_lag,
                peak_seconds: peak_lag as f64 * input.dt,
                peak_rho,
                n_eff,
                bound,
                significant: peak_rho.abs() > bound,
                prewhitened: prewhitened(u, r, &a, &p.ranges, options.max_lag, input.dt, options.acf_lags),
                rho,
            });
        }
    }
    out
}

/// The input → response lags (one per input).
pub(crate) fn response_lags(input: &WhereInput, p: &Prepared, options: &WhereOptions) -> Vec<ResponseLag> {
    (0..4)
        .map(|j| {
            let a = yule_walker(&p.inputs_acf[j], options.prewhiten_order);
            let s: Vec<f64> = input.states.iter().map(|x| x[DRIVEN_STATE[j]]).collect();
            let y = demean_by_segment(&s, &p.ranges);
            ResponseLag {
                input: INPUT_COLUMNS[j].to_string(),
                response: STATE_COLUMNS[DRIVEN_STATE[j]].to_string(),
                xcorr: prewhitened(
                    &p.inputs[j],
                    &y,
                    &a,
                    &p.ranges,
                    options.max_lag,
                    input.dt,
                    options.acf_lags,
                ),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yule_walker_recovers_ar1_and_ar2() {
        // AR(1) φ = 0.7: ρ_k = 0.7^k, so a = [0.7, 0].
        let rho: Vec<f64> = (0..4).map(|k| 0.7f64.powi(k)).collect();
        let a = yule_walker(&rho, 2);
        assert!((a[0] - 0.7).abs() < 1e-12 && a[1].abs() < 1e-12, "{a:?}");
        // AR(2) x_t = 0.5 x_{t−1} + 0.3 x_{t−2}: ρ1 = 0.5/(1 − 0.3), ρ2 = 0.5 ρ1 + 0.3.
        let r1 = 0.5 / 0.7;
        let a = yule_walker(&[1.0, r1, 0.5 * r1 + 0.3], 2);
        assert!((a[0] - 0.5).abs() < 1e-12 && (a[1] - 0.3).abs() < 1e-12, "{a:?}");
    }

    #[test]
    fn ar_filter_whitens_within_segments() {
        let x = [1.0, 2.0, 4.0, 8.0, 1.0, 3.0];
        let e = ar_filter(&x, &[2.0], &[0..4, 4..6]);
        assert!(e[0].is_nan() && e[4].is_nan());
        assert_eq!(&e[1..4], &[0.0, 0.0, 0.0]);
        assert_eq!(e[5], 1.0);
    }

    #[test]
    fn prewhitening_localises_the_delay_of_a_smooth_input() {
        // u is an AR(1) with φ = 0.95 (smooth); y = u delayed by 4. The raw correlation is broad,
        // the prewhitened one a single spike at lag 4.
        let n = 4000;
        let mut state = 12345u64;
        let mut u = vec![0.0; n];
        for k in 1..n {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let e = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            u[k] = 0.95 * u[k - 1] + e;
        }
        let mut y = vec![0.0; n];
        y[4..].copy_from_slice(&u[..n - 4]);
        let r = stats::segment_ranges(&[0], n);
        let (u, y) = (demean_by_segment(&u, &r), demean_by_segment(&y, &r));
        let raw = cross_correlation(&u, &y, &r, -10..=10);
        assert!(raw[10 + 1] > 0.7 && raw[10 + 7] > 0.7, "raw is broad: {raw:?}");
        let acf = stats::autocorrelation(&u, &r, 4).0;
        let a = yule_walker(&acf, 4);
        let pw = prewhitened(&u, &y, &a, &r, 10, 0.1, 100);
        assert_eq!(pw.peak_lag, 4);
        assert!(pw.peak_rho > 0.95 && pw.localised && pw.significant, "{pw:?}");
        assert!((pw.peak_seconds - 0.4).abs() < 1e-12);
    }
}
