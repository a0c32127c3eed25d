//! Whiteness of the residuals: the Ljung-Box portmanteau test within segments.

use super::stats::{autocorrelation, chi2_sf, demean_by_segment};
use super::{Prepared, WhereInput, WhereOptions};
use serde::Serialize;
use std::ops::Range;

/// The Ljung-Box test of one channel's one-step residual.
#[derive(Clone, Debug, Serialize)]
pub struct Whiteness {
    pub channel: String,
    /// Lags m tested (those with at least one pair).
    pub lags: usize,
    /// Q = n (n + 2) Σ_{k=1..m} ρ_k² / N_k.
    pub q: f64,
    /// P(χ²_m > Q): small means the residual is not white.
    pub p_value: f64,
    /// ρ_1.
    pub acf1: f64,
    /// ρ_1 … ρ_m.
    pub acf: Vec<f64>,
}

/// Ljung-Box Q over lags 1..=m of `x` (demeaned within segments here), its degrees of freedom
/// (lags that have pairs), the p-value and ρ_1 … ρ_m. ρ_k is the within-segment autocorrelation
/// and N_k its number of pairs (n − k for one segment).
pub fn ljung_box(x: &[f64], ranges: &[Range<usize>], m: usize) -> (f64, usize, f64, Vec<f64>) {
    let x = demean_by_segment(x, ranges);
    let n = x.iter().filter(|v| v.is_finite()).count() as f64;
    let (rho, pairs) = autocorrelation(&x, ranges, m);
    let (mut q, mut dof) = (0.0, 0);
    for k in 1..=m {
        if pairs[k] > 0 {
            q += rho[k] * rho[k] / pairs[k] as f64;
            dof += 1;
        }
    }
    q *= n * (n + 2.0);
    let p = if dof > 0 { chi2_sf(q, dof as f64) } else { 1.0 };
    (q, dof, p, rho[1..].to_vec())
}

pub(crate) fn whiteness(input: &WhereInput, p: &Prepared, options: &WhereOptions) -> Vec<Whiteness> {
    let m = options.whiteness_lags.max(1);
    input
        .channels
        .iter()
        .zip(&input.one_step)
        .map(|(name, r)| {
            let (q, lags, p_value, acf) = ljung_box(r, &p.ranges, m);
            Whiteness {
                channel: name.clone(),
                lags,
                q,
                p_value,
                acf1: acf.first().copied().unwrap_or(0.0),
                acf,
            }
        })
        .collect()
}
