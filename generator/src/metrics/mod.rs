//! Agreement between a predicted and an observed multivariate series: per-state and overall
//! RMSE, MAE and Willmott's modified index of agreement d₁ (the paper's "Concordance
//! Index"). See docs/metrics.md.
//!
//! For state j with predictions Pᵢ and observations Oᵢ, i = 1..n, and Ō the mean of the
//! observations:
//!
//! ```text
//! RMSE_j = √( Σ (Pᵢ − Oᵢ)² / n )
//! MAE_j  = Σ |Pᵢ − Oᵢ| / n
//! d₁_j   = 1 − Σ |Pᵢ − Oᵢ| / Σ ( |Pᵢ − Ō| + |Oᵢ − Ō| )
//! ```
//!
//! Overall (the paper's row "x"): RMSE = √(mean_j RMSE_j²) (the RMSE over all entries pooled,
//! as every state has n samples), MAE = mean_j MAE_j, d₁ = mean_j d₁_j. This reproduces the
//! overall row of the paper's identification table from its per-state rows.
//!
//! d₁ lies in [0, 1] (triangle inequality). Its denominator is 0 only when every Oᵢ and every
//! Pᵢ equal Ō, i.e. a constant observation predicted exactly: d₁ is then defined as 1. A
//! constant observation predicted inexactly gets d₁ = 0 from the formula itself (the
//! denominator equals the numerator). Ō is computed as O₁ + mean(Oᵢ − O₁), which is exact for
//! a constant series.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Per-state and overall agreement of a prediction with observations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// State names, in the order of the per-state vectors.
    pub names: Vec<String>,
    /// Number of samples compared.
    pub samples: usize,
    pub rmse: Vec<f64>,
    pub mae: Vec<f64>,
    /// Willmott's modified index of agreement d₁ ("Concordance Index"), in [0, 1].
    pub d1: Vec<f64>,
    /// √(mean of rmse²).
    pub overall_rmse: f64,
    /// Mean of mae.
    pub overall_mae: f64,
    /// Mean of d1.
    pub overall_d1: f64,
}

/// The overall row computed from per-state values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Overall {
    /// √(mean of the per-state RMSE²).
    pub rmse: f64,
    /// Mean of the per-state MAE.
    pub mae: f64,
    /// Mean of the per-state d₁.
    pub d1: f64,
}

/// Which of the two series a [`MetricsError`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Series {
    Predicted,
    Observed,
}

impl fmt::Display for Series {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Series::Predicted => "predicted",
            Series::Observed => "observed",
        })
    }
}

/// Why two series cannot be compared. Sample indices are 0-based.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricsError {
    #[error("no samples to compare")]
    Empty,
    #[error("no states: the list of state names is empty")]
    NoStates,
    #[error("{predicted} predicted samples but {observed} observed samples")]
    SampleCountMismatch { predicted: usize, observed: usize },
    #[error("{series} sample {sample} has {len} values, expected {expected} (one per state name)")]
    StateCountMismatch {
        series: Series,
        sample: usize,
        len: usize,
        expected: usize,
    },
    #[error("{series} sample {sample}, state `{state}`: non-finite value {value}")]
    NonFinite {
        series: Series,
        sample: usize,
        state: String,
        value: f64,
    },
}

/// Compare `predicted` with `observed`, both one vector per sample with one value per entry of
/// `names`.
///
/// Errors: no samples, no names, different sample counts, a sample with the wrong number of
/// values, a non-finite value (naming the series, sample and state).
pub fn compare<P, O, S>(predicted: &[P], observed: &[O], names: &[S]) -> Result<Metrics, MetricsError>
where
    P: AsRef<[f64]>,
    O: AsRef<[f64]>,
    S: AsRef<str>,
{
    if names.is_empty() {
        return Err(MetricsError::NoStates);
    }
    if predicted.len() != observed.len() {
        return Err(MetricsError::SampleCountMismatch {
            predicted: predicted.len(),
            observed: observed.len(),
        });
    }
    if predicted.is_empty() {
        return Err(MetricsError::Empty);
    }
    check_series(Series::Predicted, predicted, names)?;
    check_series(Series::Observed, observed, names)?;

    let nx = names.len();
    let (mut rmse_j, mut mae_j, mut d1_j) = (Vec::with_capacity(nx), Vec::with_capacity(nx), Vec::with_capacity(nx));
    let (mut p, mut o) = (Vec::with_capacity(predicted.len()), Vec::with_capacity(observed.len()));
    for j in 0..nx {
        p.clear();
        o.clear();
        p.extend(predicted.iter().map(|s| s.as_ref()[j]));
        o.extend(observed.iter().map(|s| s.as_ref()[j]));
        rmse_j.push(rmse(&p, &o));
        mae_j.push(mae(&p, &o));
        d1_j.push(d1(&p, &o));
    }
    let all = overall(&rmse_j, &mae_j, &d1_j);
    Ok(Metrics {
        names: names.iter().map(|s| s.as_ref().to_string()).collect(),
        samples: predicted.len(),
        rmse: rmse_j,
        mae: mae_j,
        d1: d1_j,
        overall_rmse: all.rmse,
        overall_mae: all.mae,
        overall_d1: all.d1,
    })
}

fn check_series<R: AsRef<[f64]>, S: AsRef<str>>(series: Series, rows: &[R], names: &[S]) -> Result<(), MetricsError> {
    for (sample, row) in rows.iter().enumerate() {
        let row = row.as_ref();
        if row.len() != names.len() {
            return Err(MetricsError::StateCountMismatch {
                series,
                sample,
                len: row.len(),
                expected: names.len(),
            });
        }
        if let Some((j, &value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MetricsError::NonFinite {
                series,
                sample,
                state: names[j].as_ref().to_string(),
                value,
            });
        }
    }
    Ok(())
}

/// The overall row from per-state values: √(mean RMSE²), mean MAE, mean d₁ (NaN for no
/// states).
///
/// # Panics
/// If the three slices differ in length.
pub fn overall(rmse: &[f64], mae: &[f64], d1: &[f64]) -> Overall {
    assert!(
        rmse.len() == mae.len() && mae.len() == d1.len(),
        "per-state metrics of different lengths: {} RMSE, {} MAE, {} d1",
        rmse.len(),
        mae.len(),
        d1.len()
    );
    let n = rmse.len() as f64;
    Overall {
        rmse: (rmse.iter().map(|r| r * r).sum::<f64>() / n).sqrt(),
        mae: mae.iter().sum::<f64>() / n,
        d1: d1.iter().sum::<f64>() / n,
    }
}

fn check_pair(predicted: &[f64], observed: &[f64]) {
    assert!(
        predicted.len() == observed.len() && !predicted.is_empty(),
        "series must be non-empty and of equal length: {} predicted, {} observed",
        predicted.len(),
        observed.len()
    );
}

/// Root-mean-square error of one series.
///
/// # Panics
/// If the series are empty or differ in length ([`compare`] checks this and returns errors).
pub fn rmse(predicted: &[f64], observed: &[f64]) -> f64 {
    check_pair(predicted, observed);
    let sse: f64 = predicted.iter().zip(observed).map(|(p, o)| (p - o) * (p - o)).sum();
    (sse / predicted.len() as f64).sqrt()
}

/// Mean absolute error of one series.
///
/// # Panics
/// If the series are empty or differ in length.
pub fn mae(predicted: &[f64], observed: &[f64]) -> f64 {
    check_pair(predicted, observed);
    predicted.iter().zip(observed).map(|(p, o)| (p - o).abs()).sum::<f64>() / predicted.len() as f64
}

/// Willmott's modified index of agreement d₁ of one series, in [0, 1]; 1 for an exact
/// prediction of a constant series (0/0 in the formula).
///
/// # Panics
/// If the series are empty or differ in length.
pub fn d1(predicted: &[f64], observed: &[f64]) -> f64 {
    check_pair(predicted, observed);
    let o0 = observed[0];
    let mean = o0 + observed.iter().map(|o| o - o0).sum::<f64>() / observed.len() as f64;
    let numerator: f64 = predicted.iter().zip(observed).map(|(p, o)| (p - o).abs()).sum();
    let denominator: f64 = predicted
        .iter()
        .zip(observed)
        .map(|(p, o)| (p - mean).abs() + (o - mean).abs())
        .sum();
    if denominator == 0.0 {
        1.0
    } else {
        (1.0 - numerator / denominator).clamp(0.0, 1.0)
    }
}

impl fmt::Display for Metrics {
    /// A plain-text table: one row per state, then the overall row.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let width = self
            .names
            .iter()
            .map(|n| n.chars().count())
            .chain([7])
            .max()
            .unwrap_or(7);
        writeln!(f, "{:<width$}  {:>12}  {:>12}  {:>8}", "state", "RMSE", "MAE", "d1")?;
        for (j, name) in self.names.iter().enumerate() {
            writeln!(
                f,
                "{name:<width$}  {:>12.6}  {:>12.6}  {:>8.4}",
                self.rmse[j], self.mae[j], self.d1[j]
            )?;
        }
        write!(
            f,
            "{:<width$}  {:>12.6}  {:>12.6}  {:>8.4}",
            "overall", self.overall_rmse, self.overall_mae, self.overall_d1
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_observation() {
        // 0/0: exact prediction of a constant.
        assert_eq!(d1(&[0.1, 0.1, 0.1], &[0.1, 0.1, 0.1]), 1.0);
        // Constant observation, inexact prediction: numerator = denominator.
        assert_eq!(d1(&[0.1, 0.3, 0.1], &[0.1, 0.1, 0.1]), 0.0);
        // Exact prediction of a varying series.
        assert_eq!(d1(&[1.0, 2.0, 4.0], &[1.0, 2.0, 4.0]), 1.0);
    }
}
