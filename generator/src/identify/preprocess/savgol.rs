//! Savitzky-Golay smoothing and differentiation.
//!
//! For a window of `window = 2h + 1` samples and a polynomial order `order`, the output at
//! sample `i` is the value (or `k`-th time derivative) at `t_i` of the least-squares polynomial
//! of degree `order` through the window of samples centred on `i`. Because the fit is linear in
//! the data, it is a fixed weighted sum of the window, the [`SavGol::coefficients`].
//!
//! # Edges
//! The first and last `h` samples have no centred window. As scipy's
//! `savgol_filter(..., mode="interp")` (its default), one polynomial is fitted to the first
//! `window` samples and evaluated (or differentiated) at samples `0..h`, and one to the last
//! `window` samples and evaluated at the last `h` samples. This keeps the output exact for
//! polynomials of degree ≤ `order` everywhere, including the edges, and uses no padding
//! (no invented data); the price is a noisier estimate at the edges (an off-centre fit). A
//! signal must therefore have at least `window` samples.
//!
//! # Numerics
//! The fit uses the scaled abscissa s = (j − h)/h ∈ [−1, 1] and a Householder QR of the
//! window × (order + 1) Vandermonde matrix, not the normal equations, so the coefficients are
//! accurate to rounding for the window and order sizes used in practice. The output agrees
//! with scipy 1.17 to 1e-10 (test `preprocess_metrics.rs`, fixture from
//! `scripts/savgol_fixture.py`).

use super::{check_dt, PreprocessError};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// A Savitzky-Golay filter: window length (odd, ≥ 3) and polynomial order (< window).
///
/// Build it with [`SavGol::new`] to validate the parameters; the fields are public, and every
/// method validates them again (an invalid filter is an error in the `try_*` methods and
/// [`SavGol::filter`], a panic in the others).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SavGol {
    /// Number of samples in the window; odd and ≥ 3.
    pub window: usize,
    /// Degree of the fitted polynomial; less than `window`. 0 is a moving average.
    pub order: usize,
}

impl SavGol {
    /// A validated filter.
    pub fn new(window: usize, order: usize) -> Result<Self, PreprocessError> {
        let filter = SavGol { window, order };
        filter.validate()?;
        Ok(filter)
    }

    /// Check window ≥ 3, window odd, order < window.
    pub fn validate(&self) -> Result<(), PreprocessError> {
        let (window, order) = (self.window, self.order);
        if window < 3 {
            Err(PreprocessError::WindowTooSmall { window })
        } else if window % 2 == 0 {
            Err(PreprocessError::WindowEven { window })
        } else if order >= window {
            Err(PreprocessError::OrderTooHigh { window, order })
        } else {
            Ok(())
        }
    }

    /// h = (window − 1)/2, the samples on each side of the centre.
    pub fn half_window(&self) -> usize {
        self.window / 2
    }

    /// The weights `c` of the centred filter for the `derivative`-th derivative (0: smoothing)
    /// at sample interval `dt`: the output at sample `i` is `Σ_j c[j] · y[i − h + j]`
    /// (scipy's `savgol_coeffs(..., use="dot")`). A derivative above `order` gives zeros.
    ///
    /// # Panics
    /// If the filter is invalid or `dt` is not finite and positive; see
    /// [`SavGol::try_coefficients`].
    pub fn coefficients(&self, derivative: usize, dt: f64) -> Vec<f64> {
        self.try_coefficients(derivative, dt).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`SavGol::coefficients`] with errors instead of panics.
    pub fn try_coefficients(&self, derivative: usize, dt: f64) -> Result<Vec<f64>, PreprocessError> {
        self.validate()?;
        check_dt(dt)?;
        Ok(weights_at(&self.fit_operator(), 0.0, derivative, self.time_scale(dt)))
    }

    /// Smoothed signal (derivative 0), same length as `y`.
    ///
    /// # Panics
    /// If the filter is invalid or `y` is shorter than the window; see [`SavGol::try_smooth`].
    pub fn smooth(&self, y: &[f64]) -> Vec<f64> {
        self.try_smooth(y).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`SavGol::smooth`] with errors instead of panics.
    pub fn try_smooth(&self, y: &[f64]) -> Result<Vec<f64>, PreprocessError> {
        self.filter(y, 0, 1.0)
    }

    /// First time derivative of `y` sampled every `dt` seconds, same length as `y`.
    /// With `order` 0 it is identically 0 (as scipy).
    ///
    /// # Panics
    /// If the filter is invalid, `dt` is not finite and positive or `y` is shorter than the
    /// window; see [`SavGol::try_derivative`].
    pub fn derivative(&self, y: &[f64], dt: f64) -> Vec<f64> {
        self.try_derivative(y, dt).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`SavGol::derivative`] with errors instead of panics.
    pub fn try_derivative(&self, y: &[f64], dt: f64) -> Result<Vec<f64>, PreprocessError> {
        self.filter(y, 1, dt)
    }

    /// The `derivative`-th time derivative (0: smoothing) of `y` sampled every `dt` seconds,
    /// same length as `y`, with the edge handling described in the module documentation.
    /// Equals scipy's `savgol_filter(y, window, order, deriv=derivative, delta=dt,
    /// mode="interp")`.
    pub fn filter(&self, y: &[f64], derivative: usize, dt: f64) -> Result<Vec<f64>, PreprocessError> {
        self.validate()?;
        check_dt(dt)?;
        let (n, window, h) = (y.len(), self.window, self.half_window());
        if n < window {
            return Err(PreprocessError::SignalTooShort { len: n, window });
        }
        let fit = self.fit_operator();
        let scale = self.time_scale(dt);
        let dot = |w: &[f64], start: usize| w.iter().zip(&y[start..start + window]).map(|(a, b)| a * b).sum::<f64>();

        let mut out = vec![0.0; n];
        let centre = weights_at(&fit, 0.0, derivative, scale);
        for i in h..n - h {
            out[i] = dot(&centre, i - h);
        }
        // Edges: the polynomial of the first (last) full window, evaluated off-centre at the
        // scaled abscissa s = (i − centre)/h of each edge sample.
        for i in 0..h {
            let s = (i as f64 - h as f64) / h as f64;
            out[i] = dot(&weights_at(&fit, s, derivative, scale), 0);
        }
        for i in n - h..n {
            let s = (i as f64 - (n - 1 - h) as f64) / h as f64;
            out[i] = dot(&weights_at(&fit, s, derivative, scale), n - window);
        }
        Ok(out)
    }

    /// ds/dt: the fit's abscissa is s = (sample offset)/h, time is (sample offset)·dt.
    fn time_scale(&self, dt: f64) -> f64 {
        1.0 / (self.half_window() as f64 * dt)
    }

    /// The least-squares operator P, (order + 1) × window: the coefficients of the fitted
    /// polynomial p(s) = Σ_m a_m s^m, s = (j − h)/h, are a = P y_window. P = R⁻¹ Qᵀ for the QR
    /// factorisation of the Vandermonde matrix V[j][m] = s_j^m.
    fn fit_operator(&self) -> DMatrix<f64> {
        let h = self.half_window() as f64;
        let vandermonde = DMatrix::from_fn(self.window, self.order + 1, |j, m| ((j as f64 - h) / h).powi(m as i32));
        let qr = vandermonde.qr();
        qr.r()
            .solve_upper_triangular(&qr.q().transpose())
            .expect("a Vandermonde matrix on distinct nodes with more rows than columns has full column rank")
    }
}

/// Weights w such that w · y_window is the `derivative`-th time derivative of the fitted
/// polynomial at scaled abscissa `s0`: d^k/dt^k Σ_m a_m s^m = scale^k Σ_{m ≥ k} m!/(m−k)! a_m s^(m−k).
fn weights_at(fit: &DMatrix<f64>, s0: f64, derivative: usize, scale: f64) -> Vec<f64> {
    let (terms, window) = fit.shape();
    let mut w = vec![0.0; window];
    for m in derivative..terms {
        let falling: f64 = (m - derivative + 1..=m).map(|v| v as f64).product();
        let factor = falling * s0.powi((m - derivative) as i32) * scale.powi(derivative as i32);
        for (wj, pj) in w.iter_mut().zip(fit.row(m).iter()) {
            *wj += factor * pj;
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation() {
        assert_eq!(SavGol::new(1, 0), Err(PreprocessError::WindowTooSmall { window: 1 }));
        assert_eq!(SavGol::new(4, 2), Err(PreprocessError::WindowEven { window: 4 }));
        assert_eq!(
            SavGol::new(5, 5),
            Err(PreprocessError::OrderTooHigh { window: 5, order: 5 })
        );
        assert!(SavGol::new(5, 4).is_ok());
        let sg = SavGol::new(5, 2).unwrap();
        assert_eq!(
            sg.try_derivative(&[0.0; 10], 0.0),
            Err(PreprocessError::InvalidStep { dt: 0.0 })
        );
        assert_eq!(
            sg.try_smooth(&[0.0; 4]),
            Err(PreprocessError::SignalTooShort { len: 4, window: 5 })
        );
        let invalid = SavGol { window: 6, order: 2 };
        assert_eq!(
            invalid.try_smooth(&[0.0; 10]),
            Err(PreprocessError::WindowEven { window: 6 })
        );
    }

    /// The classic 5-point quadratic coefficients (Savitzky & Golay 1964, table I):
    /// smoothing (−3, 12, 17, 12, −3)/35, first derivative (−2, −1, 0, 1, 2)/10.
    #[test]
    fn five_point_quadratic_table() {
        let sg = SavGol::new(5, 2).unwrap();
        let smooth = sg.coefficients(0, 1.0);
        for (c, e) in smooth.iter().zip([-3.0, 12.0, 17.0, 12.0, -3.0]) {
            assert!((c - e / 35.0).abs() < 1e-15, "{smooth:?}");
        }
        let d1 = sg.coefficients(1, 0.5);
        for (c, e) in d1.iter().zip([-2.0, -1.0, 0.0, 1.0, 2.0]) {
            assert!((c - e / 10.0 / 0.5).abs() < 1e-15, "{d1:?}");
        }
        assert_eq!(sg.coefficients(3, 1.0), vec![0.0; 5]);
    }
}
