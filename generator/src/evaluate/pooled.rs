//! Streaming [`metrics::compare`](crate::metrics::compare): the metrics of a pooled series of
//! (predicted, observed) rows accumulated one row at a time, with no row stored, so that
//! `evaluate`'s memory does not grow with the number of predictions (a horizon of H samples makes
//! H predictions per logged sample).
//!
//! RMSE and MAE are sums in sample order, as `compare` computes them, so they are the same numbers
//! to the bit. Willmott's d₁ needs the mean of the observations in its denominator
//! Σ(|Pᵢ − Ō| + |Oᵢ − Ō|), which is known only at the end: a [`Stat`] accumulates that denominator
//! about a *provisional* mean given in advance, and computes the exact mean (as `compare` does,
//! O₁ + Σ(Oᵢ − O₁)/n) alongside. When the two agree bit for bit the d₁ is `compare`'s; when they
//! do not, [`MeanBook`] says so and `evaluate` runs again with the exact means (a second pass over
//! the same deterministic predictions). The first provisional means come from a cheap pass that
//! assumes every prediction is kept; they are exact unless some prediction diverged.

use crate::metrics::{overall, Metrics, MetricsError, Series};

/// The provisional means of the [`Stat`]s of one evaluation, in the order they are created, and
/// the exact means found for them.
#[derive(Clone, Debug, Default)]
pub(crate) struct MeanBook {
    given: Vec<Vec<f64>>,
    found: Vec<Option<Vec<f64>>>,
}

impl MeanBook {
    /// A book whose stats use `given` (by creation order) as their provisional means.
    pub fn with_means(given: Vec<Vec<f64>>) -> Self {
        Self {
            given,
            found: Vec::new(),
        }
    }

    /// A new stat over `width` states, with the next provisional mean (zeros if none is given).
    pub fn stat(&mut self, width: usize) -> Stat {
        let id = self.found.len();
        self.found.push(None);
        let mean = self
            .given
            .get(id)
            .filter(|m| m.len() == width)
            .cloned()
            .unwrap_or_else(|| vec![0.0; width]);
        Stat::new(id, mean)
    }

    /// Record a stat's exact mean (called as it is finished).
    fn record(&mut self, stat: &Stat) {
        if let Some(slot) = self.found.get_mut(stat.id) {
            *slot = Some(stat.exact_mean());
        }
    }

    /// Whether every stat's provisional mean was its exact one, bit for bit (stats never finished
    /// or with no rows do not count).
    pub fn exact(&self) -> bool {
        self.found.iter().enumerate().all(|(id, found)| match found {
            None => true,
            Some(m) => self
                .given
                .get(id)
                .is_some_and(|g| g.len() == m.len() && g.iter().zip(m).all(|(a, b)| a.to_bits() == b.to_bits())),
        })
    }

    /// The exact means found, in creation order (zeros where a stat was never finished).
    pub fn found(&self) -> Vec<Vec<f64>> {
        self.found.iter().map(|m| m.clone().unwrap_or_default()).collect()
    }
}

/// The running sums of one pooled series (see the module documentation).
#[derive(Clone, Debug)]
pub(crate) struct Stat {
    id: usize,
    n: usize,
    /// The first observation, O₁ (empty before the first row).
    first: Vec<f64>,
    /// Σ (Oᵢ − O₁).
    offset_sum: Vec<f64>,
    /// Σ (Pᵢ − Oᵢ)².
    sse: Vec<f64>,
    /// Σ |Pᵢ − Oᵢ|.
    sae: Vec<f64>,
    /// The provisional mean and Σ (|Pᵢ − m| + |Oᵢ − m|) about it.
    mean: Vec<f64>,
    spread: Vec<f64>,
    /// The first non-finite value of each series: (sample, state, value).
    bad_predicted: Option<(usize, usize, f64)>,
    bad_observed: Option<(usize, usize, f64)>,
}

impl Stat {
    fn new(id: usize, mean: Vec<f64>) -> Self {
        let w = mean.len();
        // Sums start where `Iterator::sum` of f64 does.
        let zero = vec![-0.0; w];
        Self {
            id,
            n: 0,
            first: Vec::new(),
            offset_sum: zero.clone(),
            sse: zero.clone(),
            sae: zero.clone(),
            mean,
            spread: zero,
            bad_predicted: None,
            bad_observed: None,
        }
    }

    /// Samples pushed.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Add a row. `yaw`: the column holding yaw, if any: its prediction is taken as observed +
    /// the wrapped difference (errors in (−π, π]).
    pub fn push(&mut self, predicted: &[f64], observed: &[f64], yaw: Option<usize>) {
        let w = self.mean.len();
        if self.n == 0 {
            self.first = observed[..w].to_vec();
        }
        for j in 0..w {
            let o = observed[j];
            let p = match yaw {
                Some(y) if y == j => o + super::wrap_angle(predicted[j] - o),
                _ => predicted[j],
            };
            if !p.is_finite() && self.bad_predicted.is_none() {
                self.bad_predicted = Some((self.n, j, p));
            }
            if !o.is_finite() && self.bad_observed.is_none() {
                self.bad_observed = Some((self.n, j, o));
            }
            let d = p - o;
            self.offset_sum[j] += o - self.first[j];
            self.sse[j] += d * d;
            self.sae[j] += d.abs();
            let m = self.mean[j];
            self.spread[j] += (p - m).abs() + (o - m).abs();
        }
        self.n += 1;
    }

    /// The observations' mean as `compare` computes it: O₁ + Σ(Oᵢ − O₁)/n (empty for no rows).
    pub fn exact_mean(&self) -> Vec<f64> {
        if self.n == 0 {
            return Vec::new();
        }
        self.first
            .iter()
            .zip(&self.offset_sum)
            .map(|(o0, s)| o0 + s / self.n as f64)
            .collect()
    }

    fn check(&self, names: &[String]) -> Result<(), MetricsError> {
        if names.is_empty() {
            return Err(MetricsError::NoStates);
        }
        for (series, bad) in [
            (Series::Predicted, self.bad_predicted),
            (Series::Observed, self.bad_observed),
        ] {
            if let Some((sample, j, value)) = bad {
                return Err(MetricsError::NonFinite {
                    series,
                    sample,
                    state: names.get(j).cloned().unwrap_or_default(),
                    value,
                });
            }
        }
        Ok(())
    }

    /// The overall RMSE alone (all states pooled), `None` for no rows: needs no mean.
    pub fn overall_rmse(&self, names: &[String]) -> Result<Option<f64>, MetricsError> {
        if self.n == 0 {
            return Ok(None);
        }
        self.check(names)?;
        let rmse: Vec<f64> = self.sse.iter().map(|s| (s / self.n as f64).sqrt()).collect();
        let n = rmse.len() as f64;
        Ok(Some((rmse.iter().map(|r| r * r).sum::<f64>() / n).sqrt()))
    }

    /// The metrics `compare` gives on the rows pushed (`None` for none), with d₁ about the
    /// provisional mean; the exact mean is recorded in `book`, which tells whether they agreed.
    pub fn metrics(&self, names: &[String], book: &mut MeanBook) -> Result<Option<Metrics>, MetricsError> {
        if self.n == 0 {
            return Ok(None);
        }
        self.check(names)?;
        book.record(self);
        let n = self.n as f64;
        let rmse: Vec<f64> = self.sse.iter().map(|s| (s / n).sqrt()).collect();
        let mae: Vec<f64> = self.sae.iter().map(|s| s / n).collect();
        let d1: Vec<f64> = self
            .sae
            .iter()
            .zip(&self.spread)
            .map(|(&num, &den)| {
                if den == 0.0 {
                    1.0
                } else {
                    (1.0 - num / den).clamp(0.0, 1.0)
                }
            })
            .collect();
        let all = overall(&rmse, &mae, &d1);
        Ok(Some(Metrics {
            names: names.to_vec(),
            samples: self.n,
            rmse,
            mae,
            d1,
            overall_rmse: all.rmse,
            overall_mae: all.mae,
            overall_d1: all.d1,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::compare;
    use proptest::prelude::*;

    fn names(w: usize) -> Vec<String> {
        (0..w).map(|j| format!("s{j}")).collect()
    }

    /// Push rows into a stat whose provisional mean came from a first pass, as evaluate does.
    fn two_pass(p: &[Vec<f64>], o: &[Vec<f64>], yaw: Option<usize>) -> (Option<Metrics>, bool, bool) {
        let w = o[0].len();
        let mut first = MeanBook::default();
        let mut s = first.stat(w);
        for (a, b) in p.iter().zip(o) {
            s.push(a, b, yaw);
        }
        s.metrics(&names(w), &mut first).unwrap();
        let mut book = MeanBook::with_means(first.found());
        let mut s = book.stat(w);
        for (a, b) in p.iter().zip(o) {
            s.push(a, b, yaw);
        }
        let m = s.metrics(&names(w), &mut book).unwrap();
        (m, first.exact(), book.exact())
    }

    #[test]
    fn a_hand_checked_case() {
        // P = [1, 2, 3], O = [1, 1, 4]: RMSE √(2/3), MAE 2/3, Ō = 2, d₁ = 1 − 2 / (1+1 + 0+1 + 1+2).
        let p = vec![vec![1.0], vec![2.0], vec![3.0]];
        let o = vec![vec![1.0], vec![1.0], vec![4.0]];
        let (m, first_exact, exact) = two_pass(&p, &o, None);
        let m = m.unwrap();
        assert!(!first_exact, "zeros are not the mean 2");
        assert!(exact);
        assert_eq!(m.samples, 3);
        assert!((m.rmse[0] - (2.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!((m.mae[0] - 2.0 / 3.0).abs() < 1e-15);
        assert!((m.d1[0] - (1.0 - 2.0 / 6.0)).abs() < 1e-15);
    }

    #[test]
    fn no_rows_no_metrics() {
        let mut book = MeanBook::default();
        let s = book.stat(3);
        assert_eq!(s.metrics(&names(3), &mut book).unwrap(), None);
        assert_eq!(s.overall_rmse(&names(3)).unwrap(), None);
        assert!(book.exact());
    }

    #[test]
    fn a_non_finite_prediction_is_named_as_compare_names_it() {
        let mut book = MeanBook::default();
        let mut s = book.stat(2);
        s.push(&[1.0, 2.0], &[1.0, 2.0], None);
        s.push(&[1.0, f64::NAN], &[1.0, 2.0], None);
        let e = s.metrics(&names(2), &mut book).unwrap_err();
        let want = compare(&[[1.0, 2.0], [1.0, f64::NAN]], &[[1.0, 2.0], [1.0, 2.0]], &names(2)).unwrap_err();
        // NaN ≠ NaN: compared as text.
        assert_eq!(format!("{e:?}"), format!("{want:?}"));
    }

    proptest! {
        /// Streamed with the exact means, the metrics are `compare`'s to the bit (yaw wrapped as
        /// evaluate's pools wrapped it).
        #[test]
        fn streamed_metrics_are_compares(
            rows in proptest::collection::vec(proptest::collection::vec(-50.0f64..50.0, 6), 1..60),
            yaw in proptest::option::of(0usize..3),
        ) {
            let p: Vec<Vec<f64>> = rows.iter().map(|r| r[..3].to_vec()).collect();
            let o: Vec<Vec<f64>> = rows.iter().map(|r| r[3..].to_vec()).collect();
            let wrapped: Vec<Vec<f64>> = p
                .iter()
                .zip(&o)
                .map(|(a, b)| {
                    let mut a = a.clone();
                    if let Some(j) = yaw {
                        a[j] = b[j] + crate::evaluate::wrap_angle(a[j] - b[j]);
                    }
                    a
                })
                .collect();
            let want = compare(&wrapped, &o, &names(3)).unwrap();
            let (got, _, exact) = two_pass(&p, &o, yaw);
            prop_assert!(exact);
            let got = got.unwrap();
            prop_assert_eq!(got.samples, want.samples);
            for (a, b) in [
                (&got.rmse, &want.rmse),
                (&got.mae, &want.mae),
                (&got.d1, &want.d1),
            ] {
                prop_assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()), "{:?} vs {:?}", a, b);
            }
            prop_assert_eq!(got.overall_rmse.to_bits(), want.overall_rmse.to_bits());
            prop_assert_eq!(got.overall_d1.to_bits(), want.overall_d1.to_bits());
        }
    }
}
