//! The paper's first-order low-pass filter λ/(s + λ), discretised exactly.
//!
//! The continuous filter is ẏ = λ (u − y). Holding the input constant over each sample
//! interval h (zero-order hold, the input seen as a staircase through its samples), the exact
//! solution over one interval is
//!
//! ```text
//! y[k+1] = a · y[k] + (1 − a) · u[k],   a = e^{−λh}
//! ```
//!
//! with no approximation of the exponential (unlike a forward-Euler or Tustin filter), for any
//! λh > 0; the DC gain is 1. The output at sample k depends on the inputs before it
//! (u[0..k]), so the filter adds one sample of delay on top of the continuous filter's lag
//! 1/λ. The paper applies the same filter to states, inputs and derivatives, so the lag is the
//! same in every filtered signal and the relations between them are preserved.
//!
//! Initial condition: y[0] = u[0], the filter starts in steady state on the first sample (no
//! start-up transient from an arbitrary initial value such as 0).

use super::{check_dt, PreprocessError};
use serde::{Deserialize, Serialize};

/// The paper's bandwidth: λ = 1 rad/s.
pub const PAPER_LAMBDA: f64 = 1.0;

/// First-order low-pass λ/(s + λ); [`Default`] is the paper's λ = 1 rad/s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LowPass {
    /// Bandwidth (corner frequency) in rad/s; finite and positive.
    pub lambda: f64,
}

impl Default for LowPass {
    fn default() -> Self {
        LowPass { lambda: PAPER_LAMBDA }
    }
}

impl LowPass {
    /// A validated filter.
    pub fn new(lambda: f64) -> Result<Self, PreprocessError> {
        let filter = LowPass { lambda };
        filter.validate()?;
        Ok(filter)
    }

    /// Check that λ is finite and positive.
    pub fn validate(&self) -> Result<(), PreprocessError> {
        if self.lambda.is_finite() && self.lambda > 0.0 {
            Ok(())
        } else {
            Err(PreprocessError::InvalidLambda { lambda: self.lambda })
        }
    }

    /// The discrete pole a = e^{−λ dt}.
    pub fn pole(&self, dt: f64) -> f64 {
        (-self.lambda * dt).exp()
    }

    /// Filter `y` (samples every `dt` seconds); same length (empty in, empty out).
    ///
    /// # Panics
    /// If λ or `dt` is not finite and positive; see [`LowPass::try_apply`].
    pub fn apply(&self, y: &[f64], dt: f64) -> Vec<f64> {
        self.try_apply(y, dt).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`LowPass::apply`] with errors instead of panics.
    pub fn try_apply(&self, y: &[f64], dt: f64) -> Result<Vec<f64>, PreprocessError> {
        self.validate()?;
        check_dt(dt)?;
        let a = self.pole(dt);
        let b = -(-self.lambda * dt).exp_m1(); // 1 − a, accurate for small λ dt
        let mut out = Vec::with_capacity(y.len());
        let mut state = match y.first() {
            Some(&first) => first,
            None => return Ok(out),
        };
        out.push(state);
        for &u in &y[..y.len() - 1] {
            state = a * state + b * u;
            out.push(state);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_and_trivial_inputs() {
        assert_eq!(LowPass::new(0.0), Err(PreprocessError::InvalidLambda { lambda: 0.0 }));
        assert!(LowPass::new(f64::NAN).is_err());
        assert_eq!(
            LowPass::default().try_apply(&[1.0], -1.0),
            Err(PreprocessError::InvalidStep { dt: -1.0 })
        );
        assert_eq!(LowPass::default().apply(&[], 0.1), Vec::<f64>::new());
        assert_eq!(LowPass::default().apply(&[2.5], 0.1), vec![2.5]);
        // A constant is a steady state (initial condition = first sample, DC gain 1).
        let out = LowPass::new(3.0).unwrap().apply(&[1.5; 20], 0.05);
        assert!(out.iter().all(|v| (v - 1.5).abs() < 1e-15), "{out:?}");
    }
}
