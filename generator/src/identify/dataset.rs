//! Identification data: flight-log segments with Savitzky-Golay smoothed states
//! and derivatives, optionally low-passed (the paper's λ/(s+λ)), ready for the
//! SINDy and PD fits and for evaluation.

use super::preprocess::{try_columnwise, LowPass, PreprocessError, SavGol};
use super::response::InputResponse;
use crate::logs::FlightLog;

/// How logs become identification data.
#[derive(Clone, Debug)]
pub struct DatasetOptions {
    /// Smoothing and differentiation of the states (and smoothing of nothing else).
    pub savgol: SavGol,
    /// The paper's first-order low-pass, applied identically to states, inputs and
    /// derivatives (the PD fit uses it; SINDy does not by default).
    pub lowpass: Option<LowPass>,
    /// Drop the half-window at both ends of every segment, where the
    /// Savitzky-Golay fit is extrapolated.
    pub trim_edges: bool,
    /// Use the smoothed states (true) or the logged ones (false) as regressors.
    pub smooth_states: bool,
    /// Pure delay of each input channel (s, LOG_FORMAT.md input order): the sample at k is paired
    /// with the input logged round(delay/Δt) samples earlier, u_j(t − d_j), so the fitted model is
    /// ẋ = f(x, u(t − d)); the first max_j d_j samples of each segment are dropped. Ignored
    /// when `response` is given.
    pub input_delay: [f64; 4],
    /// Delay and first-order lag per input channel, applied as the Savitzky-Golay derivatives
    /// see them ([`InputResponse::regressors`]: fractional delays, centred on the sample
    /// instants); the first [`InputResponse::warmup`] samples of each segment are dropped.
    /// `None`: the inputs as logged (shifted by `input_delay`).
    pub response: Option<InputResponse>,
    /// What the regression's targets are: Savitzky-Golay derivatives at the samples, or the
    /// integral form over each sample interval ([`Targets::Trapezoid`]).
    pub targets: Targets,
}

/// The regression targets of the identification data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Targets {
    /// ẋ(t_k) by Savitzky-Golay differentiation; the library at (x_k, u_k).
    #[default]
    SavGol,
    /// The integral form over one sample interval, with no differentiation:
    /// (x_{k+1} − x_k)/Δt = (1/Δt)∫ f(x, u) dt ≈ ½[Θ(x_k, ū_k) + Θ(x_{k+1}, ū_k)] ξ, ū_k the input
    /// the interval sees (zero-order hold, delayed and lagged: [`InputResponse::interval_inputs`]).
    /// The trapezoid's bias on a mode s is s·(sΔt)²/12 (1.3 % for the 12 rad/s attitude loops at
    /// 30 Hz), where the Savitzky-Golay derivative of a loop driven by steps is smeared across
    /// the step; measurement noise enters target and regressor with zero covariance.
    Trapezoid,
}

impl Default for DatasetOptions {
    fn default() -> Self {
        Self {
            savgol: SavGol { window: 9, order: 3 },
            lowpass: None,
            trim_edges: true,
            smooth_states: false,
            input_delay: [0.0; 4],
            response: None,
            targets: Targets::SavGol,
        }
    }
}

/// One uniformly sampled stretch of flight.
#[derive(Clone, Debug, Default)]
pub struct SegmentData {
    /// Which log (index into the input list) and which segment of it.
    pub log: usize,
    pub segment: usize,
    /// Sample period used for differentiation (the segment's median Δt).
    pub dt: f64,
    pub t: Vec<f64>,
    pub x: Vec<[f64; 12]>,
    pub u: Vec<[f64; 4]>,
    /// ẋ estimated by Savitzky-Golay differentiation of the logged states, or with
    /// [`Targets::Trapezoid`] the interval's mean slope (x_{k+1} − x_k)/Δt.
    pub dx: Vec<[f64; 12]>,
    /// With [`Targets::Trapezoid`]: x_{k+1}, the end of each sample's interval (else empty).
    pub x_next: Vec<[f64; 12]>,
}

/// All segments of all logs.
#[derive(Clone, Debug, Default)]
pub struct Dataset {
    pub segments: Vec<SegmentData>,
}

impl Dataset {
    /// Number of samples over all segments.
    pub fn len(&self) -> usize {
        self.segments.iter().map(|s| s.t.len()).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Iterate over (x, u, ẋ) samples of all segments.
    pub fn samples(&self) -> impl Iterator<Item = (&[f64; 12], &[f64; 4], &[f64; 12])> {
        self.segments
            .iter()
            .flat_map(|s| s.x.iter().zip(&s.u).zip(&s.dx).map(|((x, u), dx)| (x, u, dx)))
    }

    /// Is this integral-form data ([`Targets::Trapezoid`]: every segment has its `x_next`)?
    pub fn is_interval_form(&self) -> bool {
        !self.segments.is_empty() && self.segments.iter().all(|s| s.x_next.len() == s.x.len())
    }

    /// The interval ends x_{k+1} in [`samples`](Self::samples) order (integral-form data only).
    pub fn interval_ends(&self) -> impl Iterator<Item = &[f64; 12]> {
        self.segments.iter().flat_map(|s| s.x_next.iter())
    }
}

/// Why a dataset could not be built.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{file}: segment {segment}: {error}")]
    Filter {
        file: String,
        segment: usize,
        error: PreprocessError,
    },
    #[error("{files}: no segment is long enough for the Savitzky-Golay window {window} and the input delays (the longest has {longest} samples)")]
    Empty {
        files: String,
        window: usize,
        longest: usize,
    },
}

/// Build the dataset; segments shorter than the window are skipped.
pub fn build(logs: &[FlightLog], options: &DatasetOptions) -> Result<Dataset, DatasetError> {
    build_with(logs, options, true)
}

/// The integral form ([`Targets::Trapezoid`], whatever `options.targets` says) without its
/// targets: every segment's `dx` is left empty. What free runs over the sample intervals read
/// (the states, the interval ends x_{k+1} and the inputs each interval sees), at 96 bytes per
/// sample less than [`build`]'s.
pub fn build_for_free_runs(logs: &[FlightLog], options: &DatasetOptions) -> Result<Dataset, DatasetError> {
    build_with(
        logs,
        &DatasetOptions {
            targets: Targets::Trapezoid,
            ..options.clone()
        },
        false,
    )
}

/// The rule by which the fit (and the delay scan, `pipeline::delays`) takes a segment: long enough
/// for the Savitzky-Golay window of `window` samples (and at least 3); then its step, the median
/// of t_{k+1} − t_k.
pub(crate) fn usable_step(t: &[f64], window: usize) -> Option<f64> {
    if t.len() < window.max(3) {
        return None;
    }
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(|a, b| a.total_cmp(b));
    Some(steps[steps.len() / 2])
}

fn build_with(logs: &[FlightLog], options: &DatasetOptions, slopes: bool) -> Result<Dataset, DatasetError> {
    let mut segments = Vec::new();
    for (li, log) in logs.iter().enumerate() {
        for (si, seg) in log.segments.iter().enumerate() {
            let Some(dt) = usable_step(&seg.t, options.savgol.window) else {
                continue;
            };
            let err = |error| DatasetError::Filter {
                file: log.source.clone(),
                segment: si,
                error,
            };
            if options.targets == Targets::Trapezoid {
                if let Some(data) = interval_segment(li, si, dt, &seg.t, &seg.x, &seg.u, options, slopes) {
                    segments.push(data);
                }
                continue;
            }
            // What is computed over the whole segment (derivatives, smoothed or low-passed
            // series) is trimmed in place; the logged states are copied once, trimmed.
            let dx = try_columnwise(&seg.x, |y| options.savgol.try_derivative(y, dt)).map_err(err)?;
            let smoothed = if options.smooth_states {
                Some(try_columnwise(&seg.x, |y| options.savgol.try_smooth(y)).map_err(err)?)
            } else {
                None
            };
            let (u, max_shift) = match &options.response {
                Some(r) => (r.regressors(&seg.u, dt), r.warmup(dt)),
                None => shifted_inputs(&seg.u, &options.input_delay, dt),
            };
            let (x, mut u, mut dx) = match &options.lowpass {
                Some(lp) => {
                    let x = smoothed.unwrap_or_else(|| seg.x.clone());
                    let x = try_columnwise(&x, |y| lp.try_apply(y, dt)).map_err(err)?;
                    let u = try_columnwise(&u, |y| lp.try_apply(y, dt)).map_err(err)?;
                    let dx = try_columnwise(&dx, |y| lp.try_apply(y, dt)).map_err(err)?;
                    (Some(x), u, dx)
                }
                None => (smoothed, u, dx),
            };
            let (start, end) = if options.trim_edges {
                let h = options.savgol.half_window();
                (h.max(max_shift), seg.t.len() - h)
            } else {
                (max_shift, seg.t.len())
            };
            if start >= end {
                continue;
            }
            let x = match x {
                Some(mut x) => {
                    trim(&mut x, start, end);
                    x
                }
                None => seg.x[start..end].to_vec(),
            };
            trim(&mut u, start, end);
            trim(&mut dx, start, end);
            segments.push(SegmentData {
                log: li,
                segment: si,
                dt,
                t: seg.t[start..end].to_vec(),
                x,
                u,
                dx,
                x_next: Vec::new(),
            });
        }
    }
    if segments.is_empty() {
        return Err(DatasetError::Empty {
            files: logs.iter().map(|l| l.source.as_str()).collect::<Vec<_>>().join(", "),
            window: options.savgol.window,
            longest: logs
                .iter()
                .flat_map(|l| &l.segments)
                .map(|s| s.t.len())
                .max()
                .unwrap_or(0),
        });
    }
    Ok(Dataset { segments })
}

/// Keep `v[start..end]`, in place (no second copy of the series).
fn trim<T>(v: &mut Vec<T>, start: usize, end: usize) {
    v.truncate(end);
    v.drain(..start);
}

/// u_j(t − d_j): each channel shifted by its delay in whole samples (the first sample repeated
/// before the segment), and the largest shift.
fn shifted_inputs(u: &[[f64; 4]], delay: &[f64; 4], dt: f64) -> (Vec<[f64; 4]>, usize) {
    let shift: [usize; 4] = core::array::from_fn(|j| (delay[j].max(0.0) / dt).round() as usize);
    let max_shift = shift.iter().copied().max().unwrap_or(0);
    let shifted = (0..u.len())
        .map(|k| core::array::from_fn(|j| u[k.saturating_sub(shift[j])][j]))
        .collect();
    (shifted, max_shift)
}

/// One segment in the integral form ([`Targets::Trapezoid`]): sample k stands for the interval
/// [t_k, t_{k+1}], its input is what the interval sees, its target the mean slope (with `slopes`;
/// else `dx` is empty). `None` when the input delays leave no interval.
#[allow(clippy::too_many_arguments)]
fn interval_segment(
    log: usize,
    segment: usize,
    dt: f64,
    t: &[f64],
    x: &[[f64; 12]],
    u: &[[f64; 4]],
    options: &DatasetOptions,
    slopes: bool,
) -> Option<SegmentData> {
    let (mut u, start) = match &options.response {
        Some(r) => (r.interval_inputs(u, dt), r.warmup(dt)),
        None => shifted_inputs(u, &options.input_delay, dt),
    };
    let end = t.len().saturating_sub(1);
    if start >= end {
        return None;
    }
    trim(&mut u, start, end);
    let dx = (start..end)
        .filter(|_| slopes)
        .map(|k| {
            let h = t[k + 1] - t[k];
            core::array::from_fn(|i| (x[k + 1][i] - x[k][i]) / h)
        })
        .collect();
    Some(SegmentData {
        log,
        segment,
        dt,
        t: t[start..end].to_vec(),
        x: x[start..end].to_vec(),
        u,
        dx,
        x_next: x[start + 1..end + 1].to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::logs::parse_log;

    /// Free runs' integral form is [`build`]'s with `Targets::Trapezoid`, without the slopes.
    #[test]
    fn free_runs_form_is_the_integral_form_without_slopes() {
        let header = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate";
        let mut csv = format!("# rate_hz: 50\n{header}\n");
        for k in 0..120 {
            let t = k as f64 / 50.0;
            let row: Vec<String> = std::iter::once(format!("{t}"))
                .chain((0..16).map(|c| format!("{:e}", (t * (1.0 + c as f64)).sin() + if c == 2 { 5.0 } else { 0.0 })))
                .collect();
            csv.push_str(&row.join(","));
            csv.push('\n');
        }
        let log = parse_log(&csv, "test.csv").unwrap();
        let options = DatasetOptions {
            response: Some(InputResponse {
                delay: [0.04, 0.0, 0.02, 0.0],
                lag: [Some(0.05), None, None, None],
            }),
            ..DatasetOptions::default()
        };
        let full = build(
            std::slice::from_ref(&log),
            &DatasetOptions {
                targets: Targets::Trapezoid,
                ..options.clone()
            },
        )
        .unwrap();
        let runs = build_for_free_runs(std::slice::from_ref(&log), &options).unwrap();
        assert!(runs.is_interval_form());
        assert_eq!(full.segments.len(), runs.segments.len());
        for (a, b) in full.segments.iter().zip(&runs.segments) {
            assert!(!a.dx.is_empty() && b.dx.is_empty());
            assert_eq!((&a.t, &a.x, &a.u, &a.x_next, a.dt), (&b.t, &b.x, &b.u, &b.x_next, b.dt));
        }
    }
}
