//! The residuals broken down by flight regime: quantile bins of each regime variable, per bin and
//! channel the count, RMSE and mean residual, and how much of the residual the regime explains.

use super::stats::{self, quantile_sorted};
use super::summary::ChannelStats;
use super::{WhereInput, WhereOptions};
use serde::Serialize;

/// One regime variable with its bins and the per-channel breakdown.
#[derive(Clone, Debug, Serialize)]
pub struct Regime {
    /// Key: `speed`, `tilt`, `height`, `vertical_speed`, `yaw_rate`, `time_in_flight`,
    /// `battery_voltage`.
    pub variable: String,
    /// What it is, e.g. "horizontal speed √(vx² + vy²)".
    pub label: String,
    pub unit: String,
    pub bins: Vec<RegimeBin>,
    /// Per channel, the one-step residual.
    pub one_step: Vec<RegimeChannel>,
    /// Per channel, the horizon residual (`None` without horizon residuals).
    pub horizon: Option<Vec<RegimeChannel>>,
}

/// A bin [lo, hi) of a regime variable (the last bin includes hi).
#[derive(Clone, Debug, Serialize)]
pub struct RegimeBin {
    pub lo: f64,
    pub hi: f64,
    /// Median of the variable over the bin's samples (the bin's midpoint if it is empty).
    pub median: f64,
    /// Samples in the bin.
    pub count: usize,
}

/// One channel's residual over the bins of one regime variable.
#[derive(Clone, Debug, Serialize)]
pub struct RegimeChannel {
    pub channel: String,
    #[serde(flatten)]
    pub stats: RegimeStats,
}

/// Per-bin figures and dependence statistics of one residual on one regime variable.
#[derive(Clone, Debug, Serialize)]
pub struct RegimeStats {
    /// Finite residual samples per bin.
    pub count: Vec<usize>,
    /// RMSE per bin (`None` for an empty bin).
    pub rmse: Vec<Option<f64>>,
    /// Mean residual per bin.
    pub mean: Vec<Option<f64>>,
    /// η²: the fraction of the residual's variance explained by the bin means.
    pub eta_squared: f64,
    /// η² of the squared residual: how much of the variation of the error magnitude the bins explain.
    pub eta_squared_ms: f64,
    /// Expected η² by chance: (bins − 1) / (n_eff − 1), n_eff of the residual's mean.
    pub eta_squared_null: f64,
    /// Pearson correlation of the residual with the variable.
    pub r: Option<f64>,
    /// Pearson correlation of |residual| with the variable.
    pub r_abs: Option<f64>,
    /// RMSE of the last bin / RMSE of the first bin.
    pub rmse_ratio: Option<f64>,
}

impl RegimeStats {
    /// The dependence score used to rank regimes: max(η², η² of the squared residual).
    pub fn explained(&self) -> f64 {
        self.eta_squared.max(self.eta_squared_ms)
    }
}

/// The regime variables of the input: (key, label, unit, values).
pub fn regime_variables(input: &WhereInput) -> Vec<(&'static str, &'static str, &'static str, Vec<f64>)> {
    let col = |f: &dyn Fn(&[f64; 12]) -> f64| input.states.iter().map(f).collect::<Vec<f64>>();
    let mut v = vec![
        (
            "speed",
            "horizontal speed √(vx² + vy²)",
            "m/s",
            col(&|x| x[6].hypot(x[7])),
        ),
        (
            "tilt",
            "tilt acos(cos roll · cos pitch)",
            "rad",
            col(&|x| (x[3].cos() * x[4].cos()).clamp(-1.0, 1.0).acos()),
        ),
        ("height", "height z", "m", col(&|x| x[2])),
        ("vertical_speed", "vertical speed vz", "m/s", col(&|x| x[8])),
        ("yaw_rate", "|yaw rate|", "rad/s", col(&|x| x[11].abs())),
        ("time_in_flight", "time in flight", "s", input.time_in_flight.clone()),
    ];
    if let Some(b) = &input.battery_voltage {
        v.push(("battery_voltage", "battery voltage", "V", b.clone()));
    }
    v
}

/// Quantile bin edges (bins + 1 values, equal edges merged) of the finite values; empty when
/// there are none.
pub fn quantile_edges(values: &[f64], bins: usize) -> Vec<f64> {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() {
        return Vec::new();
    }
    sorted.sort_by(f64::total_cmp);
    let bins = bins.max(1);
    let mut edges: Vec<f64> = (0..=bins)
        .map(|i| quantile_sorted(&sorted, i as f64 / bins as f64))
        .collect();
    edges.dedup();
    if edges.len() == 1 {
        edges.push(edges[0]);
    }
    edges
}

/// The bin of `v` for `edges` (bins [e_i, e_{i+1}), the last one closed); `None` if not finite.
pub fn bin_of(edges: &[f64], v: f64) -> Option<usize> {
    if !v.is_finite() || edges.len() < 2 {
        return None;
    }
    Some(edges[1..edges.len() - 1].partition_point(|e| *e <= v))
}

/// Per-bin figures and dependence statistics of `residual` on the binned variable.
pub fn regime_stats(residual: &[f64], variable: &[f64], bin: &[Option<usize>], bins: usize, n_eff: f64) -> RegimeStats {
    let mut count = vec![0usize; bins];
    let (mut sum, mut sum_sq, mut sum_q, mut sum_q2) = (vec![0.0; bins], vec![0.0; bins], 0.0, 0.0);
    let mut pairs = (Vec::new(), Vec::new(), Vec::new());
    for ((r, b), v) in residual.iter().zip(bin).zip(variable) {
        if let (true, Some(b)) = (r.is_finite(), b) {
            count[*b] += 1;
            sum[*b] += r;
            sum_sq[*b] += r * r;
            sum_q += r * r;
            sum_q2 += r * r * r * r;
            pairs.0.push(*v);
            pairs.1.push(*r);
            pairs.2.push(r.abs());
        }
    }
    let n: usize = count.iter().sum();
    let nf = n as f64;
    let per_bin =
        |f: &dyn Fn(usize) -> f64| -> Vec<Option<f64>> { (0..bins).map(|b| (count[b] > 0).then(|| f(b))).collect() };
    let rmse = per_bin(&|b| (sum_sq[b] / count[b] as f64).sqrt());
    let mean = per_bin(&|b| sum[b] / count[b] as f64);
    // η² of the residual: Σ n_b (m_b − m)² / Σ (r − m)².
    let total_mean = sum.iter().sum::<f64>() / nf.max(1.0);
    let ss_total = sum_q - nf * total_mean * total_mean;
    let ss_between: f64 = (0..bins)
        .filter(|&b| count[b] > 0)
        .map(|b| count[b] as f64 * (sum[b] / count[b] as f64 - total_mean).powi(2))
        .sum();
    // η² of the squared residual, q = r²: bin means of q are sum_sq / count.
    let q_mean = sum_q / nf.max(1.0);
    let ss_q_total = sum_q2 - nf * q_mean * q_mean;
    let ss_q_between: f64 = (0..bins)
        .filter(|&b| count[b] > 0)
        .map(|b| count[b] as f64 * (sum_sq[b] / count[b] as f64 - q_mean).powi(2))
        .sum();
    let ratio = |a: f64, b: f64| if b > 0.0 { (a / b).clamp(0.0, 1.0) } else { 0.0 };
    let first = rmse.iter().flatten().next().copied();
    let last = rmse.iter().rev().flatten().next().copied();
    RegimeStats {
        eta_squared: ratio(ss_between, ss_total),
        eta_squared_ms: ratio(ss_q_between, ss_q_total),
        eta_squared_null: if n_eff > 1.0 {
            ((bins as f64 - 1.0) / (n_eff - 1.0)).min(1.0)
        } else {
            1.0
        },
        r: stats::pearson(&pairs.0, &pairs.1),
        r_abs: stats::pearson(&pairs.0, &pairs.2),
        rmse_ratio: match (first, last) {
            (Some(f), Some(l)) if f > 0.0 && bins > 1 => Some(l / f),
            _ => None,
        },
        count,
        rmse,
        mean,
    }
}

/// The regime breakdown of every channel for every regime variable.
pub(crate) fn regimes(
    input: &WhereInput,
    options: &WhereOptions,
    one_step: &[ChannelStats],
    horizon: Option<&[ChannelStats]>,
) -> Vec<Regime> {
    regime_variables(input)
        .into_iter()
        .filter_map(|(key, label, unit, values)| {
            let edges = quantile_edges(&values, options.bins);
            if edges.is_empty() {
                return None;
            }
            let nb = edges.len() - 1;
            let bin: Vec<Option<usize>> = values.iter().map(|v| bin_of(&edges, *v)).collect();
            let bins = (0..nb)
                .map(|b| {
                    let mut inside: Vec<f64> = values
                        .iter()
                        .zip(&bin)
                        .filter(|(_, x)| **x == Some(b))
                        .map(|(v, _)| *v)
                        .collect();
                    inside.sort_by(f64::total_cmp);
                    RegimeBin {
                        lo: edges[b],
                        hi: edges[b + 1],
                        median: if inside.is_empty() {
                            0.5 * (edges[b] + edges[b + 1])
                        } else {
                            quantile_sorted(&inside, 0.5)
                        },
                        count: inside.len(),
                    }
                })
                .collect();
            let breakdown = |series: &[Vec<f64>], summaries: &[ChannelStats]| -> Vec<RegimeChannel> {
                input
                    .channels
                    .iter()
                    .zip(series)
                    .zip(summaries)
                    .map(|((name, r), s)| RegimeChannel {
                        channel: name.clone(),
                        stats: regime_stats(r, &values, &bin, nb, s.n_eff),
                    })
                    .collect()
            };
            Some(Regime {
                variable: key.to_string(),
                label: label.to_string(),
                unit: unit.to_string(),
                bins,
                one_step: breakdown(&input.one_step, one_step),
                horizon: match (&input.horizon, horizon) {
                    (Some(h), Some(s)) => Some(breakdown(h, s)),
                    _ => None,
                },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_edges_and_bins() {
        let v: Vec<f64> = (0..10).map(f64::from).collect();
        let e = quantile_edges(&v, 2);
        assert_eq!(e, vec![0.0, 4.5, 9.0]);
        assert_eq!(bin_of(&e, 0.0), Some(0));
        assert_eq!(bin_of(&e, 4.5), Some(1));
        assert_eq!(bin_of(&e, 9.0), Some(1));
        assert_eq!(bin_of(&e, f64::NAN), None);
        // Ties merge edges: a constant variable is one bin.
        assert_eq!(quantile_edges(&[2.0; 5], 4), vec![2.0, 2.0]);
        assert_eq!(bin_of(&[2.0, 2.0], 2.0), Some(0));
    }

    #[test]
    fn eta_squared_of_a_step() {
        // Residual = bin index exactly: the bins explain all of its variance.
        let var: Vec<f64> = (0..8).map(f64::from).collect();
        let res: Vec<f64> = var.iter().map(|v| if *v < 4.0 { -1.0 } else { 1.0 }).collect();
        let e = quantile_edges(&var, 2);
        let bins: Vec<Option<usize>> = var.iter().map(|v| bin_of(&e, *v)).collect();
        let s = regime_stats(&res, &var, &bins, 2, 8.0);
        assert_eq!(s.count, vec![4, 4]);
        assert_eq!(s.mean, vec![Some(-1.0), Some(1.0)]);
        assert!((s.eta_squared - 1.0).abs() < 1e-12);
        assert_eq!(s.eta_squared_ms, 0.0); // |r| is the same everywhere
        assert_eq!(s.rmse_ratio, Some(1.0));
        assert!((s.eta_squared_null - 1.0 / 7.0).abs() < 1e-12);
    }
}
