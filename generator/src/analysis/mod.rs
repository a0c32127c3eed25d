//! Where a model's predictions part from flight data: generic signal and regime analysis of
//! prediction residuals (the "where" part of `uavgen diagnose`).
//!
//! [`analyse`] takes sample-aligned residual series with the logged states and inputs
//! ([`WhereInput`]) and computes, per residual channel: RMSE and bias with an
//! autocorrelation-aware standard error ([`summary`]); the breakdown by flight regime
//! ([`regimes`]); Welch spectra, band powers and input coherence ([`bands`], [`spectrum`]);
//! Ljung-Box whiteness ([`whiteness`]); input → residual cross-correlation and input → response
//! lags ([`xcorr`]); data quality ([`quality`]). [`WhereReport::findings`] phrases the largest
//! gaps in words ([`findings`]); [`write_plots`] draws them ([`plots`]). Every statistic and JSON
//! field is documented in `docs/diagnose-where.md`.
//!
//! Lags, autocorrelations and spectra never pair samples across a segment boundary. Residuals
//! may contain NaN (unavailable): those samples are left out of every statistic.

pub mod bands;
pub mod findings;
pub mod plots;
pub mod quality;
pub mod regimes;
pub mod spectrum;
pub mod stats;
pub mod summary;
pub mod whiteness;
pub mod xcorr;

pub use bands::{ChannelSpectrum, CoherenceReport, SpectrumReport};
pub use plots::write_plots;
pub use quality::{DataQuality, SegmentStale, StaleSplit};
pub use regimes::{Regime, RegimeBin, RegimeChannel, RegimeStats};
pub use summary::{ChannelStats, OwnState};
pub use whiteness::Whiteness;
pub use xcorr::{CrossCorrelation, Prewhitened, ResponseLag};

use crate::logs::{INPUT_COLUMNS, STATE_COLUMNS};
use serde::Serialize;
use std::ops::Range;

/// Everything the analysis needs, all series sample-aligned, concatenated over segments.
#[derive(Clone, Debug, Default)]
pub struct WhereInput {
    /// Sample period (s).
    pub dt: f64,
    /// Index where each segment starts (first = 0); lags and spectra never cross a boundary.
    pub segment_starts: Vec<usize>,
    /// Residual channel names, e.g. `["vx","vy","vz","roll_rate","pitch_rate","yaw_rate"]`. A name
    /// that is a state name (LOG_FORMAT.md) links the channel to that state.
    pub channels: Vec<String>,
    /// Per channel: one-step derivative residual (measured ẋ − model f(x, u)), per sample.
    pub one_step: Vec<Vec<f64>>,
    /// Per channel: residual (measured − predicted) at the end of an N-sample free run started N
    /// samples earlier (NaN where unavailable).
    pub horizon: Option<Vec<Vec<f64>>>,
    /// Logged states: x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate.
    pub states: Vec<[f64; 12]>,
    /// Logged inputs: u_vz u_roll u_pitch u_yaw_rate.
    pub inputs: Vec<[f64; 4]>,
    /// Seconds since the segment start.
    pub time_in_flight: Vec<f64>,
    pub battery_voltage: Option<Vec<f64>>,
    /// The row repeats the previous row's states (sample-and-hold).
    pub stale: Vec<bool>,
    /// Data-quality findings already phrased by the log reader, included verbatim.
    pub quality_notes: Vec<String>,
}

impl WhereInput {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// Panics with a message naming the first series whose length or shape is wrong.
    pub fn check(&self) {
        let n = self.len();
        assert!(
            self.dt.is_finite() && self.dt > 0.0,
            "WhereInput: dt = {} is not a positive period",
            self.dt
        );
        assert_eq!(
            self.one_step.len(),
            self.channels.len(),
            "WhereInput: one_step needs one series per channel"
        );
        for (c, s) in self.channels.iter().zip(&self.one_step) {
            assert_eq!(
                s.len(),
                n,
                "WhereInput: one_step `{c}` has {} samples, states {n}",
                s.len()
            );
        }
        if let Some(h) = &self.horizon {
            assert_eq!(
                h.len(),
                self.channels.len(),
                "WhereInput: horizon needs one series per channel"
            );
            for (c, s) in self.channels.iter().zip(h) {
                assert_eq!(
                    s.len(),
                    n,
                    "WhereInput: horizon `{c}` has {} samples, states {n}",
                    s.len()
                );
            }
        }
        assert_eq!(
            self.inputs.len(),
            n,
            "WhereInput: inputs has {} samples, states {n}",
            self.inputs.len()
        );
        assert_eq!(
            self.time_in_flight.len(),
            n,
            "WhereInput: time_in_flight has {} samples, states {n}",
            self.time_in_flight.len()
        );
        assert_eq!(
            self.stale.len(),
            n,
            "WhereInput: stale has {} samples, states {n}",
            self.stale.len()
        );
        if let Some(v) = &self.battery_voltage {
            assert_eq!(
                v.len(),
                n,
                "WhereInput: battery_voltage has {} samples, states {n}",
                v.len()
            );
        }
    }
}

/// Settings of the analysis. `Default` gives the values documented in `docs/diagnose-where.md`.
#[derive(Clone, Debug, Serialize)]
pub struct WhereOptions {
    /// Quantile bins per regime variable.
    pub bins: usize,
    /// Lags m of the Ljung-Box test.
    pub whiteness_lags: usize,
    /// Largest lag L (samples) of the cross-correlations.
    pub max_lag: usize,
    /// Requested Welch window length (samples); rounded down to a power of two that fits the
    /// longest segment.
    pub welch_segment: usize,
    /// Inner band edges (Hz): bands [0, e₁), [e₁, e₂), …, [e_last, Nyquist]. Edges at or above
    /// Nyquist are dropped.
    pub band_edges: Vec<f64>,
    /// Longest lag of the autocorrelations used for effective sample sizes.
    pub acf_lags: usize,
    /// Order of the AR model that prewhitens each input for the response-lag test.
    pub prewhiten_order: usize,
    /// Stale-row fraction above which findings warn.
    pub stale_warning: f64,
    /// Smallest explained fraction (η²) for a regime dependence to be reported as a finding.
    pub min_explained: f64,
    /// Input → channel pairs drawn in the cross-correlation plot.
    pub plot_pairs: usize,
    /// N of the horizon residuals (samples per free run); `None`: inferred from the leading
    /// unavailable (NaN) horizon samples of the segments.
    pub horizon_steps: Option<usize>,
}

impl Default for WhereOptions {
    fn default() -> Self {
        Self {
            bins: 5,
            whiteness_lags: 20,
            max_lag: 15,
            welch_segment: 128,
            band_edges: vec![0.5, 2.0, 5.0],
            acf_lags: 300,
            prewhiten_order: 4,
            stale_warning: 0.03,
            min_explained: 0.02,
            plot_pairs: 6,
            horizon_steps: None,
        }
    }
}

/// The "where" report (under `"where"` in report.json; fields in `docs/diagnose-where.md`).
#[derive(Clone, Debug, Serialize)]
pub struct WhereReport {
    pub samples: usize,
    pub segments: usize,
    pub dt: f64,
    pub channels: Vec<String>,
    pub inputs: Vec<String>,
    pub options: WhereOptions,
    /// N of the horizon residuals: `options.horizon_steps`, else inferred from the leading
    /// unavailable samples of each segment.
    pub horizon_steps: Option<usize>,
    pub one_step: Vec<ChannelStats>,
    pub horizon: Option<Vec<ChannelStats>>,
    pub regimes: Vec<Regime>,
    pub own_state: Vec<OwnState>,
    pub spectrum: Option<SpectrumReport>,
    pub whiteness: Vec<Whiteness>,
    pub cross_correlation: Vec<CrossCorrelation>,
    pub response_lags: Vec<ResponseLag>,
    pub quality: DataQuality,
}

impl WhereReport {
    /// Plain-English sentences with figures, largest gap first (see [`findings`]).
    pub fn findings(&self) -> Vec<String> {
        findings::findings(self)
    }
}

/// Index of a state by name (LOG_FORMAT.md order).
pub fn state_index(name: &str) -> Option<usize> {
    STATE_COLUMNS.iter().position(|s| *s == name)
}

/// The unit of a state.
pub fn state_unit(name: &str) -> &'static str {
    match name {
        "x" | "y" | "z" => "m",
        "roll" | "pitch" | "yaw" => "rad",
        "vx" | "vy" | "vz" => "m/s",
        "roll_rate" | "pitch_rate" | "yaw_rate" => "rad/s",
        _ => "",
    }
}

/// The unit of a state's time derivative (the one-step residual's unit).
pub fn derivative_unit(name: &str) -> &'static str {
    match name {
        "x" | "y" | "z" => "m/s",
        "roll" | "pitch" | "yaw" => "rad/s",
        "vx" | "vy" | "vz" => "m/s²",
        "roll_rate" | "pitch_rate" | "yaw_rate" => "rad/s²",
        _ => "",
    }
}

/// Shared precomputation: segment ranges, per-segment demeaned series and their autocorrelations.
pub(crate) struct Prepared {
    pub ranges: Vec<Range<usize>>,
    pub one_step: Vec<Vec<f64>>,
    pub one_step_acf: Vec<Vec<f64>>,
    pub inputs: Vec<Vec<f64>>,
    pub inputs_acf: Vec<Vec<f64>>,
}

impl Prepared {
    fn new(input: &WhereInput, options: &WhereOptions) -> Self {
        let n = input.len();
        let ranges = stats::segment_ranges(&input.segment_starts, n);
        let acf_lags = options.acf_lags.min(n.saturating_sub(1));
        let acf = |x: &[f64]| stats::autocorrelation(x, &ranges, acf_lags).0;
        let one_step: Vec<Vec<f64>> = input
            .one_step
            .iter()
            .map(|r| stats::demean_by_segment(r, &ranges))
            .collect();
        let inputs: Vec<Vec<f64>> = (0..4)
            .map(|j| {
                let u: Vec<f64> = input.inputs.iter().map(|u| u[j]).collect();
                stats::demean_by_segment(&u, &ranges)
            })
            .collect();
        Self {
            one_step_acf: one_step.iter().map(|x| acf(x)).collect(),
            inputs_acf: inputs.iter().map(|x| acf(x)).collect(),
            ranges,
            one_step,
            inputs,
        }
    }
}

/// Effective sample size N / τ from a precomputed autocorrelation (see [`stats::integrated_time`]).
pub(crate) fn n_eff_from_acf(acf: &[f64], n: usize) -> f64 {
    if n < 2 || acf.len() < 2 {
        return n as f64;
    }
    let tau = stats::integrated_time(|k| acf[k], acf.len() - 1, n as f64);
    n as f64 / tau
}

/// Bartlett's effective sample size for the correlation of two series from their autocorrelations.
pub(crate) fn n_eff_pair_from_acfs(a: &[f64], b: &[f64], n: usize) -> f64 {
    let len = a.len().min(b.len());
    if n < 2 || len < 2 {
        return n as f64;
    }
    let tau = stats::integrated_time(|k| a[k] * b[k], len - 1, n as f64);
    n as f64 / tau
}

/// Analyse the residuals of `input` (panics if its series have inconsistent lengths).
pub fn analyse(input: &WhereInput, options: &WhereOptions) -> WhereReport {
    input.check();
    let prepared = Prepared::new(input, options);
    let horizon_steps = options
        .horizon_steps
        .or_else(|| summary::horizon_steps(input, &prepared.ranges));
    let one_step = summary::one_step(input, &prepared);
    let horizon = summary::horizon(input, &prepared, options, horizon_steps);
    WhereReport {
        samples: input.len(),
        segments: prepared.ranges.len(),
        dt: input.dt,
        channels: input.channels.clone(),
        inputs: INPUT_COLUMNS.iter().map(|s| s.to_string()).collect(),
        options: options.clone(),
        horizon_steps,
        regimes: regimes::regimes(input, options, &one_step, horizon.as_deref()),
        own_state: summary::own_state(input, &prepared),
        spectrum: bands::spectrum(input, &prepared, options),
        whiteness: whiteness::whiteness(input, &prepared, options),
        cross_correlation: xcorr::cross_correlations(input, &prepared, options),
        response_lags: xcorr::response_lags(input, &prepared, options),
        quality: quality::quality(input, &prepared),
        one_step,
        horizon,
    }
}
