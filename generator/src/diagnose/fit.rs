//! Fitting helpers: weighted least squares with parameter covariances, the effective sample size of
//! autocorrelated residuals, and the curvature of a scanned likelihood profile.

use nalgebra::{DMatrix, DVector};

/// The longest lag summed in [`integrated_time`] (as the SINDy criteria, identify/sindy).
pub const MAX_LAG: usize = 200;

/// The integrated autocorrelation time τ = 1 + 2 Σ_{k≥1} ρ_k of a residual given as one slice per
/// segment (lags never pair samples of different segments), ρ_k its lag-k autocorrelation about the
/// pooled mean, summed while positive, up to `max_lag` ([`MAX_LAG`] for training residuals). N_eff = N / τ: Savitzky-Golay
/// derivatives (and sample-and-hold rows) make neighbouring residuals far from independent, so
/// standard errors are inflated by √τ and information criteria use N_eff.
pub fn integrated_time(parts: &[&[f64]], max_lag: usize) -> f64 {
    let n: usize = parts.iter().map(|p| p.len()).sum();
    if n < 3 {
        return 1.0;
    }
    let mean = parts.iter().flat_map(|p| p.iter()).sum::<f64>() / n as f64;
    let var: f64 = parts.iter().flat_map(|p| p.iter()).map(|v| (v - mean).powi(2)).sum();
    if var <= 0.0 {
        return 1.0;
    }
    let mut tau = 1.0;
    for lag in 1..max_lag.min(n - 1) {
        let mut s = 0.0;
        for p in parts {
            for k in lag..p.len() {
                s += (p[k] - mean) * (p[k - lag] - mean);
            }
        }
        let rho = s / var;
        if rho <= 0.0 {
            break;
        }
        tau += 2.0 * rho;
    }
    tau.min(n as f64)
}

/// Normal equations of a weighted least-squares problem, accumulated row by row.
pub struct Normal {
    a: DMatrix<f64>,
    b: DVector<f64>,
}

impl Normal {
    pub fn new(p: usize) -> Self {
        Self {
            a: DMatrix::zeros(p, p),
            b: DVector::zeros(p),
        }
    }

    /// Add the equation row · θ ≈ y with weight w.
    pub fn add(&mut self, row: &[f64], y: f64, w: f64) {
        let p = row.len();
        for i in 0..p {
            if row[i] == 0.0 {
                continue;
            }
            self.b[i] += w * row[i] * y;
            for j in 0..p {
                self.a[(i, j)] += w * row[i] * row[j];
            }
        }
    }

    /// θ and the unscaled covariance (ΦᵀWΦ)⁺, by the equilibrated symmetric eigendecomposition;
    /// directions with eigenvalues below 1e-10 of the largest are left out (θ = 0 along them,
    /// infinite variance reported as NaN).
    pub fn solve(&self) -> (Vec<f64>, DMatrix<f64>) {
        let p = self.b.len();
        let d: Vec<f64> = (0..p)
            .map(|i| {
                let v = self.a[(i, i)];
                if v > 0.0 {
                    1.0 / v.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let scaled = DMatrix::from_fn(p, p, |i, j| self.a[(i, j)] * d[i] * d[j]);
        let eig = scaled.symmetric_eigen();
        let max = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
        let mut pinv = DMatrix::zeros(p, p);
        for (k, &l) in eig.eigenvalues.iter().enumerate() {
            if l > 1e-10 * max && l > 0.0 {
                let v = eig.eigenvectors.column(k);
                pinv += (v * v.transpose()) / l;
            }
        }
        let cov = DMatrix::from_fn(p, p, |i, j| {
            if d[i] == 0.0 || d[j] == 0.0 {
                if i == j {
                    f64::NAN
                } else {
                    0.0
                }
            } else {
                pinv[(i, j)] * d[i] * d[j]
            }
        });
        let rhs = DVector::from_fn(p, |i, _| self.b[i] * d[i]);
        let z = &pinv * rhs;
        let theta = (0..p).map(|i| z[i] * d[i]).collect();
        (theta, cov)
    }
}

/// The standard deviation 1/√(−ℓ'') of a scanned parameter from the log-likelihood profile ℓ at
/// three neighbouring grid points (x₀ < x₁ < x₂, the maximum at x₁); `None` without curvature.
pub fn profile_sigma(x: [f64; 3], l: [f64; 3]) -> Option<f64> {
    let d2 = 2.0 * ((l[2] - l[1]) / (x[2] - x[1]) - (l[1] - l[0]) / (x[1] - x[0])) / (x[2] - x[0]);
    (d2 < 0.0 && d2.is_finite()).then(|| 1.0 / (-d2).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_recovers_a_line_with_its_standard_error() {
        let mut ne = Normal::new(2);
        let n = 1000;
        let mut res = 0.0;
        for k in 0..n {
            let x = k as f64 / n as f64;
            let noise = if k % 2 == 0 { 0.1 } else { -0.1 };
            ne.add(&[1.0, x], 2.0 + 3.0 * x + noise, 1.0);
            res += noise * noise;
        }
        let (th, cov) = ne.solve();
        assert!((th[0] - 2.0).abs() < 1e-2 && (th[1] - 3.0).abs() < 2e-2);
        let s2 = res / (n - 2) as f64;
        // σ of the slope for x uniform on [0, 1): √(12 s² / n).
        let sd = (cov[(1, 1)] * s2).sqrt();
        assert!((sd - (12.0 * s2 / n as f64).sqrt()).abs() < 1e-3 * sd.max(1e-9) + 1e-4);
    }

    #[test]
    fn zero_column_is_left_out() {
        let mut ne = Normal::new(2);
        for k in 0..10 {
            ne.add(&[1.0, 0.0], k as f64, 1.0);
        }
        let (th, cov) = ne.solve();
        assert!((th[0] - 4.5).abs() < 1e-12 && th[1] == 0.0 && cov[(1, 1)].is_nan());
    }

    #[test]
    fn white_noise_has_tau_near_one_and_a_moving_average_more() {
        let mut s = 12345u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let w: Vec<f64> = (0..5000).map(|_| rnd()).collect();
        let tau = integrated_time(&[&w], MAX_LAG);
        assert!(tau < 1.2, "{tau}");
        let ma: Vec<f64> = w.windows(5).map(|p| p.iter().sum()).collect();
        let tau = integrated_time(&[&ma], MAX_LAG);
        assert!((tau - 5.0).abs() < 1.0, "{tau}");
    }

    #[test]
    fn parabola_curvature() {
        // ℓ = −(x − 1)²/(2σ²), σ = 0.5.
        let l = |x: f64| -(x - 1.0f64).powi(2) / (2.0 * 0.25);
        let s = profile_sigma([0.8, 1.0, 1.3], [l(0.8), l(1.0), l(1.3)]).unwrap();
        assert!((s - 0.5).abs() < 1e-12);
    }
}
