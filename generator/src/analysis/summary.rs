//! Per-channel summaries: RMSE, bias with an autocorrelation-aware standard error, the error
//! normalised by the no-change prediction and each channel's share; the correlation of each
//! residual with its own state (drag shows as residual ∝ −v).

use super::stats::{self, Moments};
use super::{derivative_unit, n_eff_from_acf, n_eff_pair_from_acfs, state_index, state_unit, Prepared, WhereInput};
use super::{WhereOptions, STATE_COLUMNS};
use serde::Serialize;
use std::ops::Range;

/// Summary of one residual channel.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelStats {
    pub channel: String,
    pub unit: String,
    /// Finite residual samples.
    pub n: usize,
    pub rmse: f64,
    /// Mean residual (bias).
    pub mean: f64,
    /// Standard deviation (1/n).
    pub std: f64,
    /// Effective sample size of the mean, N / τ.
    pub n_eff: f64,
    /// Standard error of the mean: std / √n_eff.
    pub std_error: f64,
    /// mean / std_error (`None` if std_error is 0).
    pub t: Option<f64>,
    /// mean² / rmse²: the part of the mean-square error that is bias.
    pub bias_fraction: f64,
    /// RMS error of the no-change prediction (`None` when the channel is not a state name).
    pub scale: Option<f64>,
    /// rmse / scale.
    pub normalised_rmse: Option<f64>,
    /// normalised_rmse² / Σ normalised_rmse² over the channels that have one.
    pub share: Option<f64>,
}

/// The correlation of a channel's one-step residual with its own (signed) state.
#[derive(Clone, Debug, Serialize)]
pub struct OwnState {
    pub channel: String,
    pub state: String,
    /// Pearson correlation of residual and state.
    pub r: f64,
    /// Least-squares residual ≈ intercept + slope · state.
    pub slope: f64,
    pub intercept: f64,
    /// Bartlett effective sample size of the pair.
    pub n_eff: f64,
    /// 2 / √n_eff: |r| above it is significant at about 5 %.
    pub bound: f64,
}

fn channel_stats(channel: &str, unit: &str, residual: &[f64], acf: &[f64], scale: Option<f64>) -> ChannelStats {
    let Moments { n, mean, rms, std } = stats::moments(residual.iter().copied());
    let n_eff = n_eff_from_acf(acf, n);
    let std_error = if n_eff > 0.0 { std / n_eff.sqrt() } else { 0.0 };
    let scale = scale.filter(|s| *s > 0.0 && s.is_finite());
    ChannelStats {
        channel: channel.to_string(),
        unit: unit.to_string(),
        n,
        rmse: rms,
        mean,
        std,
        n_eff,
        std_error,
        t: (std_error > 0.0).then(|| mean / std_error),
        bias_fraction: if rms > 0.0 { (mean * mean) / (rms * rms) } else { 0.0 },
        scale,
        normalised_rmse: scale.map(|s| rms / s),
        share: None,
    }
}

fn set_shares(stats: &mut [ChannelStats]) {
    let total: f64 = stats.iter().filter_map(|s| s.normalised_rmse).map(|v| v * v).sum();
    if total > 0.0 {
        for s in stats.iter_mut() {
            s.share = s.normalised_rmse.map(|v| v * v / total);
        }
    }
}

fn state_series(input: &WhereInput, i: usize) -> Vec<f64> {
    input.states.iter().map(|x| x[i]).collect()
}

/// RMS of the measured derivative of state `i` (central differences within segments, one-sided
/// at the ends) over the samples where `mask` is finite: the error of predicting ẋ = 0.
fn derivative_scale(input: &WhereInput, ranges: &[Range<usize>], i: usize, mask: &[f64]) -> Option<f64> {
    let s = state_series(input, i);
    let mut d = vec![f64::NAN; s.len()];
    for r in ranges {
        if r.len() < 2 {
            continue;
        }
        for k in r.clone() {
            let (a, b) = (k.saturating_sub(1).max(r.start), (k + 1).min(r.end - 1));
            d[k] = (s[b] - s[a]) / ((b - a) as f64 * input.dt);
        }
    }
    let m = stats::moments(d.iter().zip(mask).filter(|(_, m)| m.is_finite()).map(|(v, _)| *v));
    (m.n > 0).then_some(m.rms)
}

/// RMS of s_k − s_{k−N} within segments over the samples where `mask` is finite: the error of
/// predicting that the state does not change over the horizon.
fn change_scale(input: &WhereInput, ranges: &[Range<usize>], i: usize, steps: usize, mask: &[f64]) -> Option<f64> {
    let s = state_series(input, i);
    let mut sq = Vec::new();
    for r in ranges {
        for k in (r.start + steps)..r.end {
            if mask[k].is_finite() {
                sq.push(s[k] - s[k - steps]);
            }
        }
    }
    let m = stats::moments(sq);
    (m.n > 0).then_some(m.rms)
}

/// The one-step summaries, one per channel.
pub(crate) fn one_step(input: &WhereInput, p: &Prepared) -> Vec<ChannelStats> {
    let mut out: Vec<ChannelStats> = input
        .channels
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let scale = state_index(name).and_then(|i| derivative_scale(input, &p.ranges, i, &input.one_step[c]));
            channel_stats(
                name,
                derivative_unit(name),
                &input.one_step[c],
                &p.one_step_acf[c],
                scale,
            )
        })
        .collect();
    set_shares(&mut out);
    out
}

/// N of the horizon residuals: the fewest leading samples without any finite horizon residual
/// over the segments that have one (`None` without horizon residuals or when it is 0).
pub(crate) fn horizon_steps(input: &WhereInput, ranges: &[Range<usize>]) -> Option<usize> {
    let h = input.horizon.as_ref()?;
    let available = |k: usize| h.iter().any(|s| s[k].is_finite());
    ranges
        .iter()
        .filter_map(|r| r.clone().position(available))
        .min()
        .filter(|&n| n > 0)
}

/// The horizon summaries (`None` without horizon residuals).
pub(crate) fn horizon(
    input: &WhereInput,
    p: &Prepared,
    options: &WhereOptions,
    steps: Option<usize>,
) -> Option<Vec<ChannelStats>> {
    let h = input.horizon.as_ref()?;
    let lags = options.acf_lags.min(input.len().saturating_sub(1));
    let mut out: Vec<ChannelStats> = input
        .channels
        .iter()
        .zip(h)
        .map(|(name, r)| {
            let acf = stats::autocorrelation(&stats::demean_by_segment(r, &p.ranges), &p.ranges, lags).0;
            let scale = match (state_index(name), steps) {
                (Some(i), Some(n)) => change_scale(input, &p.ranges, i, n, r),
                _ => None,
            };
            channel_stats(name, state_unit(name), r, &acf, scale)
        })
        .collect();
    set_shares(&mut out);
    Some(out)
}

/// The correlation of each one-step residual with the state of the same name.
pub(crate) fn own_state(input: &WhereInput, p: &Prepared) -> Vec<OwnState> {
    let lags = p.one_step_acf.first().map_or(0, |a| a.len().saturating_sub(1));
    input
        .channels
        .iter()
        .enumerate()
        .filter_map(|(c, name)| {
            let i = state_index(name)?;
            let s = state_series(input, i);
            let fit = stats::linear_fit(&s, &input.one_step[c])?;
            let s_acf = stats::autocorrelation(&stats::demean_by_segment(&s, &p.ranges), &p.ranges, lags).0;
            let n_eff = n_eff_pair_from_acfs(&p.one_step_acf[c], &s_acf, fit.n);
            Some(OwnState {
                channel: name.clone(),
                state: STATE_COLUMNS[i].to_string(),
                r: fit.r,
                slope: fit.slope,
                intercept: fit.intercept,
                n_eff,
                bound: 2.0 / n_eff.max(1.0).sqrt(),
            })
        })
        .collect()
}
