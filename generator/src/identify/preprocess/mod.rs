//! Preprocessing of flight data for identification: Savitzky-Golay smoothing and
//! differentiation ([`SavGol`]) and the paper's first-order low-pass λ/(s+λ)
//! ([`LowPass`]).
//!
//! Both work on plain slices of uniformly sampled data (one signal at a time) and return a
//! vector of the same length. [`columnwise`] and [`try_columnwise`] apply such a filter to
//! every column of row-major data `&[[f64; N]]` (one row per sample):
//!
//! ```
//! use uavgen::identify::preprocess::{columnwise, try_columnwise, LowPass, SavGol};
//! let rows: Vec<[f64; 2]> = (0..50).map(|k| [k as f64, (k as f64).powi(2)]).collect();
//! let dt = 0.1;
//! let sg = SavGol::new(7, 2).unwrap();
//! let rates = try_columnwise(&rows, |y| sg.try_derivative(y, dt)).unwrap();
//! assert!((rates[10][0] - 10.0).abs() < 1e-9); // d/dt of t/dt
//! let filtered = columnwise(&rates, |y| LowPass::default().apply(y, dt));
//! assert_eq!(filtered.len(), rows.len());
//! ```
//!
//! Non-finite samples are not checked: they propagate through the filters.

mod lowpass;
mod savgol;

pub use lowpass::{LowPass, PAPER_LAMBDA};
pub use savgol::SavGol;

/// An invalid filter parameter or a signal the filter cannot process.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PreprocessError {
    #[error("Savitzky-Golay window must be odd, got {window}")]
    WindowEven { window: usize },
    #[error("Savitzky-Golay window must be at least 3, got {window}")]
    WindowTooSmall { window: usize },
    #[error("Savitzky-Golay polynomial order {order} must be less than the window {window}")]
    OrderTooHigh { window: usize, order: usize },
    #[error("sample interval must be finite and positive, got {dt}")]
    InvalidStep { dt: f64 },
    #[error("signal of {len} samples is shorter than the Savitzky-Golay window {window}")]
    SignalTooShort { len: usize, window: usize },
    #[error("low-pass bandwidth lambda must be finite and positive, got {lambda} rad/s")]
    InvalidLambda { lambda: f64 },
}

pub(crate) fn check_dt(dt: f64) -> Result<(), PreprocessError> {
    if dt.is_finite() && dt > 0.0 {
        Ok(())
    } else {
        Err(PreprocessError::InvalidStep { dt })
    }
}

/// Apply `filter` to every column of `data` (one row per sample) and reassemble the rows.
///
/// # Panics
/// If `filter` returns a vector whose length differs from the number of rows.
pub fn columnwise<const N: usize>(data: &[[f64; N]], mut filter: impl FnMut(&[f64]) -> Vec<f64>) -> Vec<[f64; N]> {
    match try_columnwise(data, |y| Ok::<_, std::convert::Infallible>(filter(y))) {
        Ok(out) => out,
        Err(never) => match never {},
    }
}

/// Like [`columnwise`] for a fallible filter: the first error is returned.
///
/// # Panics
/// If `filter` returns a vector whose length differs from the number of rows.
pub fn try_columnwise<const N: usize, E>(
    data: &[[f64; N]],
    mut filter: impl FnMut(&[f64]) -> Result<Vec<f64>, E>,
) -> Result<Vec<[f64; N]>, E> {
    let mut out = vec![[0.0; N]; data.len()];
    let mut column = Vec::with_capacity(data.len());
    for j in 0..N {
        column.clear();
        column.extend(data.iter().map(|row| row[j]));
        let filtered = filter(&column)?;
        assert_eq!(
            filtered.len(),
            data.len(),
            "column filter returned {} samples for {} rows (column {j})",
            filtered.len(),
            data.len()
        );
        for (row, v) in out.iter_mut().zip(filtered) {
            row[j] = v;
        }
    }
    Ok(out)
}
