//! Basic statistics over segmented series with missing values (NaN): means and RMS, per-segment
//! demeaning, auto- and cross-correlation within segments, effective sample sizes, Pearson
//! correlation, quantiles and the chi-square survival function.

use std::ops::Range;

/// The index ranges of the segments: `starts` (first = 0, increasing) up to `n`. Empty ranges
/// (repeated or out-of-range starts) are dropped.
pub fn segment_ranges(starts: &[usize], n: usize) -> Vec<Range<usize>> {
    let mut bounds: Vec<usize> = starts.iter().copied().filter(|&s| s < n).collect();
    if bounds.first() != Some(&0) {
        bounds.insert(0, 0);
    }
    bounds.push(n);
    bounds.windows(2).filter(|w| w[1] > w[0]).map(|w| w[0]..w[1]).collect()
}

/// Count, mean, RMS and standard deviation (population, 1/n) of the finite values of `x`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    pub n: usize,
    pub mean: f64,
    pub rms: f64,
    pub std: f64,
}

/// [`Moments`] of the finite values (all zero when there are none).
pub fn moments(x: impl IntoIterator<Item = f64>) -> Moments {
    let (mut n, mut s, mut ss) = (0usize, 0.0, 0.0);
    for v in x.into_iter().filter(|v| v.is_finite()) {
        n += 1;
        s += v;
        ss += v * v;
    }
    if n == 0 {
        return Moments::default();
    }
    let mean = s / n as f64;
    let ms = ss / n as f64;
    Moments {
        n,
        mean,
        rms: ms.sqrt(),
        std: (ms - mean * mean).max(0.0).sqrt(),
    }
}

/// `x` minus the mean of its finite values within each segment (NaN stays NaN).
pub fn demean_by_segment(x: &[f64], ranges: &[Range<usize>]) -> Vec<f64> {
    let mut out = x.to_vec();
    for r in ranges {
        let m = moments(x[r.clone()].iter().copied());
        if m.n > 0 {
            for v in &mut out[r.clone()] {
                *v -= m.mean;
            }
        }
    }
    out
}

/// Σ x_t y_{t+lag} over the pairs inside one segment where both are finite (lag may be negative).
fn lagged_products(x: &[f64], y: &[f64], ranges: &[Range<usize>], lag: isize) -> (f64, usize) {
    let (mut s, mut n) = (0.0, 0usize);
    for r in ranges {
        let len = r.len() as isize;
        if lag.abs() >= len {
            continue;
        }
        let (x0, y0, count) = if lag >= 0 {
            (r.start, r.start + lag as usize, (len - lag) as usize)
        } else {
            (r.start + (-lag) as usize, r.start, (len + lag) as usize)
        };
        for i in 0..count {
            let (a, b) = (x[x0 + i], y[y0 + i]);
            if a.is_finite() && b.is_finite() {
                s += a * b;
                n += 1;
            }
        }
    }
    (s, n)
}

/// Sample autocorrelation of a demeaned series at one lag within segments, the standard
/// (biased) estimator ρ_k = Σ_pairs x_t x_{t+k} / Σ x_t², and the number of pairs.
pub fn autocorrelation_at(x: &[f64], ranges: &[Range<usize>], lag: usize) -> (f64, usize) {
    let (s0, n0) = lagged_products(x, x, ranges, 0);
    if n0 == 0 || s0 <= 0.0 {
        return (0.0, 0);
    }
    let (s, n) = lagged_products(x, x, ranges, lag as isize);
    (s / s0, n)
}

/// Autocorrelations ρ_0 … ρ_max_lag of a demeaned series (see [`autocorrelation_at`]) and the
/// number of pairs at each lag.
pub fn autocorrelation(x: &[f64], ranges: &[Range<usize>], max_lag: usize) -> (Vec<f64>, Vec<usize>) {
    (0..=max_lag).map(|k| autocorrelation_at(x, ranges, k)).unzip()
}

/// Normalised cross-correlation of two demeaned series at `lag` (positive: `x` leads `y`),
/// within segments: Σ_pairs x_t y_{t+lag} / √(Σ x² Σ y²), sums over the samples where both are
/// finite. 0 if either has no variance.
pub fn cross_correlation_at(x: &[f64], y: &[f64], ranges: &[Range<usize>], lag: isize) -> f64 {
    let both = |a: f64, b: f64| a.is_finite() && b.is_finite();
    let (mut sxx, mut syy) = (0.0, 0.0);
    for r in ranges {
        for i in r.clone() {
            if both(x[i], y[i]) {
                sxx += x[i] * x[i];
                syy += y[i] * y[i];
            }
        }
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return 0.0;
    }
    // Mask each series by the other's finiteness so the sums match the denominators.
    let (s, _) = lagged_products(x, y, ranges, lag);
    s / (sxx * syy).sqrt()
}

/// The integrated autocorrelation time τ = 1 + 2 Σ_{k≥1} c_k of a correlation sequence c_0 = 1,
/// c_1, … supplied lazily, truncated by Geyer's initial monotone positive sequence: pair sums
/// Γ_m = c_{2m} + c_{2m+1} are added while positive, each capped by the previous one. τ is
/// clamped to [1, `max_tau`]: never more precision than independent samples.
pub fn integrated_time(mut c: impl FnMut(usize) -> f64, max_lag: usize, max_tau: f64) -> f64 {
    let mut sum = 0.0; // Σ Γ_m
    let mut prev = f64::INFINITY;
    let mut m = 0;
    while 2 * m < max_lag {
        let g = if m == 0 { 1.0 } else { c(2 * m) } + c(2 * m + 1);
        if g <= 0.0 {
            break;
        }
        let g = g.min(prev);
        sum += g;
        prev = g;
        m += 1;
    }
    (2.0 * sum - 1.0).clamp(1.0, max_tau.max(1.0))
}

/// Effective sample size of the mean of a demeaned series: N / τ with τ from [`integrated_time`]
/// over its within-segment autocorrelation (lags up to `max_lag`).
pub fn effective_n(x: &[f64], ranges: &[Range<usize>], max_lag: usize) -> f64 {
    let n = x.iter().filter(|v| v.is_finite()).count();
    if n < 2 {
        return n as f64;
    }
    let tau = integrated_time(|k| autocorrelation_at(x, ranges, k).0, max_lag, n as f64);
    n as f64 / tau
}

/// Effective sample size for the correlation of two demeaned series (Bartlett):
/// N / (1 + 2 Σ_{k≥1} ρx_k ρy_k), the sum truncated as in [`integrated_time`]. The significance
/// bound of a correlation between them is about 2 / √N_eff.
pub fn effective_n_pair(x: &[f64], y: &[f64], ranges: &[Range<usize>], max_lag: usize) -> f64 {
    let n = x.iter().zip(y).filter(|(a, b)| a.is_finite() && b.is_finite()).count();
    if n < 2 {
        return n as f64;
    }
    let tau = integrated_time(
        |k| autocorrelation_at(x, ranges, k).0 * autocorrelation_at(y, ranges, k).0,
        max_lag,
        n as f64,
    );
    n as f64 / tau
}

/// Pearson correlation of the pairs where both are finite (`None` with fewer than 3 pairs or
/// no variance).
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    linear_fit(x, y).map(|f| f.r)
}

/// Least-squares line y ≈ intercept + slope · x and the correlation r, over finite pairs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    pub slope: f64,
    pub intercept: f64,
    pub r: f64,
    pub n: usize,
}

/// [`LineFit`] of `y` on `x` (`None` with fewer than 3 finite pairs or no variance).
pub fn linear_fit(x: &[f64], y: &[f64]) -> Option<LineFit> {
    let pairs: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    let n = pairs.len();
    if n < 3 {
        return None;
    }
    let mx = pairs.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let my = pairs.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
        sxy += (a - mx) * (b - my);
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    Some(LineFit {
        slope,
        intercept: my - slope * mx,
        r: (sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0),
        n,
    })
}

/// The p-quantile (0 ≤ p ≤ 1) of sorted values by linear interpolation between order statistics
/// (numpy's default). Panics on an empty slice.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    assert!(!sorted.is_empty(), "quantile of no values");
    let h = p.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms; relative error ~1e-15).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(πx).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularized upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a), a > 0, x ≥ 0:
/// series for P when x < a + 1, Lentz's continued fraction for Q otherwise.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    assert!(a > 0.0, "gamma_q needs a > 0");
    if x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x.is_infinite() {
        return 0.0;
    }
    let log_prefactor = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        // P(a, x) = e^{−x} x^a / Γ(a + 1) Σ x^n / ((a+1)…(a+n)).
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-17 {
                break;
            }
        }
        (1.0 - sum * log_prefactor.exp()).clamp(0.0, 1.0)
    } else {
        const TINY: f64 = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < TINY {
                d = TINY;
            }
            c = b + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (log_prefactor.exp() * h).clamp(0.0, 1.0)
    }
}

/// Survival function of the chi-square distribution with `dof` degrees of freedom:
/// P(χ² > x) = Q(dof/2, x/2).
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    gamma_q(0.5 * dof, 0.5 * x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * b.abs().max(1e-300)
    }

    #[test]
    fn chi2_sf_matches_scipy() {
        // scipy.stats.chi2.sf(x, k), scipy 1.17.1.
        for (x, k, want) in [
            (10.0, 5.0, 0.07523524614651217),
            (3.841458820694124, 1.0, 0.04999999999999989),
            (1.0, 1.0, 0.31731050786291115),
            (0.5, 3.0, 0.9188914116546758),
            (30.0, 20.0, 0.06985366069940986),
            (150.0, 20.0, 6.285681673933351e-22),
            (18.0, 40.0, 0.998944046315641),
            (2.0, 2.0, 0.36787944117144245),
        ] {
            let got = chi2_sf(x, k);
            assert!(close(got, want, 1e-10), "chi2_sf({x}, {k}) = {got:e}, scipy {want:e}");
        }
        assert_eq!(chi2_sf(0.0, 4.0), 1.0);
        assert_eq!(chi2_sf(f64::INFINITY, 4.0), 0.0);
    }

    #[test]
    fn ln_gamma_of_integers_and_a_half() {
        assert!(ln_gamma(1.0).abs() < 1e-14 && ln_gamma(2.0).abs() < 1e-14);
        assert!(close(ln_gamma(5.0), 24.0_f64.ln(), 1e-14));
        assert!(close(ln_gamma(0.5), std::f64::consts::PI.sqrt().ln(), 1e-13));
        assert!(close(ln_gamma(0.1), 2.252712651734206, 1e-13));
    }

    #[test]
    fn segment_ranges_cover_the_samples() {
        assert_eq!(segment_ranges(&[0, 3, 3, 7], 10), vec![0..3, 3..7, 7..10]);
        let one = |r: Vec<Range<usize>>| (r.len() == 1).then(|| r[0].clone());
        assert_eq!(one(segment_ranges(&[], 4)), Some(0..4));
        assert_eq!(one(segment_ranges(&[0, 9], 5)), Some(0..5));
    }

    #[test]
    fn autocorrelation_stays_within_segments() {
        // Two segments of alternating ±1: lag-1 pairs inside segments are all −1.
        let x = [1.0, -1.0, 1.0, -1.0, 1.0, -1.0];
        let r = segment_ranges(&[0, 3], 6);
        let (rho, pairs) = autocorrelation(&x, &r, 2);
        assert_eq!(pairs, vec![6, 4, 2]);
        assert!(close(rho[1], -4.0 / 6.0, 1e-12));
        assert!(close(rho[2], 2.0 / 6.0, 1e-12));
    }

    #[test]
    fn cross_correlation_sign_of_lag() {
        // y is x delayed by 1: the correlation is at lag +1 (x leads y).
        let x = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0];
        let y = [0.0, 0.0, 1.0, 0.0, -1.0, 0.0];
        let r = segment_ranges(&[0], 6);
        assert!(close(cross_correlation_at(&x, &y, &r, 1), 1.0, 1e-12));
        // Lag −1 pairs x_t with y_{t−1}: only x_3 y_2 = −1 is non-zero, over √(2 · 2).
        assert!(close(cross_correlation_at(&x, &y, &r, -1), -0.5, 1e-12));
        assert!(cross_correlation_at(&x, &y, &r, 2).abs() < 1e-12);
    }

    #[test]
    fn integrated_time_of_ar1() {
        // ρ_k = φ^k: τ = (1 + φ) / (1 − φ).
        let phi: f64 = 0.6;
        let tau = integrated_time(|k| phi.powi(k as i32), 400, 1e9);
        assert!(close(tau, 1.6 / 0.4, 1e-9), "tau {tau}");
        assert_eq!(integrated_time(|k| if k == 0 { 1.0 } else { 0.0 }, 10, 1e9), 1.0);
        // Negative correlation is not allowed to claim more than N samples.
        assert_eq!(integrated_time(|k| (-0.5f64).powi(k as i32), 10, 1e9), 1.0);
    }

    #[test]
    fn moments_and_fit() {
        let m = moments([1.0, f64::NAN, 3.0]);
        assert_eq!(m.n, 2);
        assert!(close(m.mean, 2.0, 1e-15) && close(m.rms, 5f64.sqrt(), 1e-15) && close(m.std, 1.0, 1e-15));
        let f = linear_fit(&[0.0, 1.0, 2.0, 3.0], &[1.0, 3.0, 5.0, 7.0]).unwrap();
        assert!(close(f.slope, 2.0, 1e-12) && close(f.intercept, 1.0, 1e-12) && close(f.r, 1.0, 1e-12));
        assert!(pearson(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]).is_none());
        let s = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile_sorted(&s, 0.5), 2.0);
        assert_eq!(quantile_sorted(&s, 0.125), 0.5);
    }
}
