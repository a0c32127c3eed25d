//! The logs prepared for the diagnosis: per segment the samples, the Savitzky-Golay derivative
//! targets, the base model's filtered one-step residuals ([`super::residuals`]), the stale rows and
//! the flight time; and the same with stale rows interpolated (the `stale_samples` augmentation).

use super::catalogue::inputs::InputTransform;
use super::residuals::{filter, impulse, kernel, Base, ResidualKind};
use super::DiagnoseError;
use crate::identify::preprocess::{try_columnwise, SavGol};
use crate::logs::stale::{destale, stale_flags};
use crate::logs::{median, FlightLog};
use std::borrow::Cow;

/// One stretch of data (a segment, or a part of one for cross-validation). The time stamps,
/// states, inputs and voltages are the log's own rows (borrowed; the states are a copy only with
/// stale rows interpolated).
#[derive(Clone, Debug)]
pub(crate) struct SegData<'a> {
    /// Index in the training or the held-out list.
    pub log: usize,
    pub holdout: bool,
    pub segment: usize,
    /// Part of the segment (cross-validation splits a lone segment), else 0.
    pub part: usize,
    /// The segment's median step, s.
    pub dt: f64,
    pub t: Cow<'a, [f64]>,
    pub x: Cow<'a, [[f64; 12]]>,
    pub u: Cow<'a, [[f64; 4]]>,
    pub volt: Option<Cow<'a, [f64]>>,
    /// Rows that repeat the previous row's states (as logged, also in the interpolated copy).
    pub stale: Vec<bool>,
    /// The time at which the log's flight time is 0 for this segment ([`SegData::flight_time`]).
    pub flight_origin: f64,
    /// The Savitzky-Golay half window: samples h..n−h are the interior ones.
    pub h: usize,
    /// The kernel w_μ of the derivative (length 2h).
    pub kernel: Vec<f64>,
    /// Savitzky-Golay derivative of vx..yaw_rate at the interior samples.
    pub dx: Vec<[f64; 6]>,
    /// The base model's f(x_m, u_m) at every row, its dynamic rows vx..yaw_rate (the kinematic
    /// rows are not needed: the residuals and corrections act on the dynamic ones).
    pub f: Vec<[f64; 6]>,
    /// The base model's filtered one-step residual of vx..yaw_rate at the interior samples.
    pub r: Vec<[f64; 6]>,
    /// RK4 substeps per sample of the base model.
    pub substeps: usize,
    /// Per interior sample: no row of its derivative window is on the ground (see
    /// [`crate::logs::GROUND_CLEARANCE`]); the others are left out of every fit and score.
    pub airborne: Vec<bool>,
    /// How `r` compares model and data (the kernel is the identity for `Pointwise`).
    pub residual: ResidualKind,
}

impl SegData<'_> {
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Interior samples (those with residuals).
    pub fn interior(&self) -> std::ops::Range<usize> {
        self.h..self.len() - self.h
    }

    /// Seconds since the first row of the log at row m (continued over segments; restarted
    /// consistently when a segment's clock restarts).
    pub fn flight_time(&self, m: usize) -> f64 {
        self.t[m] - self.flight_origin
    }

    /// Seconds since the first row of the segment at row m.
    pub fn segment_time(&self, m: usize) -> f64 {
        self.t[m] - self.t[0]
    }
}

/// The raw data and, if any row is stale, the copy with stale rows interpolated.
pub(crate) struct Prepared<'a> {
    pub raw: Vec<SegData<'a>>,
    pub destaled: Option<Vec<SegData<'a>>>,
}

impl<'a> Prepared<'a> {
    pub fn variant(&self, destaled: bool) -> &[SegData<'a>] {
        match (&self.destaled, destaled) {
            (Some(d), true) => d,
            _ => &self.raw,
        }
    }

    /// Stale rows in the training (false) or held-out (true) data.
    pub fn stale_rows(&self, holdout: bool) -> (usize, usize) {
        let segs = self.raw.iter().filter(|s| s.holdout == holdout);
        segs.fold((0, 0), |(st, n), s| {
            (st + s.stale.iter().filter(|b| **b).count(), n + s.len())
        })
    }
}

/// The dynamic rows vx..yaw_rate of a model's ẋ.
pub(crate) fn dynamic(f: &[f64; 12]) -> [f64; 6] {
    std::array::from_fn(|c| f[6 + c])
}

/// Per segment of `log`, the time at which its flight time is 0: the log's first row, continued
/// over segments; when a segment's clock goes back, it continues from the previous segment's end.
fn flight_origins(log: &FlightLog) -> Vec<f64> {
    let mut out = Vec::new();
    let mut origin = log.segments.first().and_then(|s| s.t.first()).copied().unwrap_or(0.0);
    let (mut prev_end, mut prev_flight) = (f64::NEG_INFINITY, 0.0);
    for seg in &log.segments {
        let Some(&t0) = seg.t.first() else {
            out.push(origin);
            continue;
        };
        if t0 <= prev_end {
            let step = median(&seg.t.windows(2).map(|w| w[1] - w[0]).collect::<Vec<_>>()).unwrap_or(0.0);
            origin = t0 - (prev_flight + step);
        }
        prev_end = *seg.t.last().unwrap_or(&t0);
        prev_flight = prev_end - origin;
        out.push(origin);
    }
    out
}

/// Everything of one stretch of rows except what is computed from the states.
struct Rows<'a> {
    source: &'a str,
    log: usize,
    holdout: bool,
    segment: usize,
    part: usize,
    t: &'a [f64],
    x: &'a [[f64; 12]],
    u: &'a [[f64; 4]],
    volt: Option<&'a [f64]>,
    flight_origin: f64,
}

fn build<'a>(
    base: &Base,
    savgol: &SavGol,
    residual: ResidualKind,
    rows: &Rows<'a>,
    interpolate: bool,
) -> Result<SegData<'a>, DiagnoseError> {
    let n = rows.t.len();
    let steps: Vec<f64> = rows.t.windows(2).map(|w| w[1] - w[0]).collect();
    let dt = median(&steps).unwrap_or(0.0);
    let stale = stale_flags(rows.x);
    let x: Cow<'a, [[f64; 12]]> = if interpolate {
        Cow::Owned(destale(rows.t, rows.x, &stale))
    } else {
        Cow::Borrowed(rows.x)
    };
    let err = |e: crate::identify::preprocess::PreprocessError| DiagnoseError::Data {
        file: rows.source.to_string(),
        message: format!("segment {}: {e}", rows.segment),
    };
    let dx_all = try_columnwise(&x, |y| savgol.try_derivative(y, dt)).map_err(err)?;
    let h = savgol.half_window();
    let dx: Vec<[f64; 6]> = dx_all[h..n - h]
        .iter()
        .map(|d| std::array::from_fn(|c| d[6 + c]))
        .collect();
    let m = base.substeps(dt, rows.source)?;
    // The inputs the base model sees (its own delays and lags, if it has them).
    let seen = InputTransform::of_base(base).apply(rows.u, dt);
    let f: Vec<[f64; 6]> = x.iter().zip(&seen).map(|(x, u)| dynamic(&base.f(x, u))).collect();
    let (w, r) = match residual {
        ResidualKind::Matched => {
            // One-step errors (x_{m+1} − F(x_m, u_m))/Δt of vx..yaw_rate, m = 0..n−2.
            let mut e = vec![[0.0; 6]; n];
            for k in 0..n - 1 {
                let next = base.step(&x[k], &seen[k], dt, m);
                e[k] = std::array::from_fn(|c| (x[k + 1][6 + c] - next[6 + c]) / dt);
            }
            let w = kernel(savgol, dt);
            let r = filter(&w, &e, n);
            (w, r)
        }
        ResidualKind::Pointwise => {
            let r = (h..n - h)
                .map(|k| std::array::from_fn(|c| dx_all[k][6 + c] - f[k][c]))
                .collect();
            (impulse(h), r)
        }
    };
    let ground = crate::logs::on_ground(&x);
    let airborne = (h..n - h)
        .map(|k| !crate::logs::run_touches_ground(&ground, k - h, 2 * h))
        .collect();
    Ok(SegData {
        log: rows.log,
        holdout: rows.holdout,
        segment: rows.segment,
        part: rows.part,
        dt,
        t: Cow::Borrowed(rows.t),
        x,
        u: Cow::Borrowed(rows.u),
        volt: rows.volt.map(Cow::Borrowed),
        stale,
        flight_origin: rows.flight_origin,
        h,
        kernel: w,
        dx,
        f,
        r,
        substeps: m,
        airborne,
        residual,
    })
}

/// Prepare the training and held-out logs. Segments shorter than `min_rows` (at least the
/// Savitzky-Golay window + 1) are skipped; with `split` > 1 every training segment is cut into
/// that many parts (cross-validation on a single segment).
pub(crate) fn prepare<'a>(
    base: &Base,
    savgol: &SavGol,
    residual: ResidualKind,
    train: &'a [FlightLog],
    holdout: &'a [FlightLog],
    split: usize,
) -> Result<Prepared<'a>, DiagnoseError> {
    let min_rows = savgol.window + 2;
    let mut stretches = Vec::new();
    for (holdout_flag, logs) in [(false, train), (true, holdout)] {
        for (li, log) in logs.iter().enumerate() {
            let origins = flight_origins(log);
            for (si, seg) in log.segments.iter().enumerate() {
                let parts = if holdout_flag { 1 } else { split.max(1) };
                let len = seg.len() / parts;
                for p in 0..parts {
                    let lo = p * len;
                    let hi = if p + 1 == parts { seg.len() } else { lo + len };
                    if hi - lo < min_rows {
                        continue;
                    }
                    stretches.push((holdout_flag, li, log, si, p, lo..hi, origins[si]));
                }
            }
        }
    }
    // The rows of one stretch, built with or without its stale rows.
    let build_all = |drop_stale: bool| -> Result<Vec<_>, _> {
        stretches
            .iter()
            .map(|(holdout_flag, li, log, si, p, range, origin)| {
                let seg = &log.segments[*si];
                let rows = Rows {
                    source: &log.source,
                    log: *li,
                    holdout: *holdout_flag,
                    segment: *si,
                    part: *p,
                    t: &seg.t[range.clone()],
                    x: &seg.x[range.clone()],
                    u: &seg.u[range.clone()],
                    volt: seg.battery_voltage.as_deref().map(|v| &v[range.clone()]),
                    flight_origin: *origin,
                };
                build(base, savgol, residual, &rows, drop_stale)
            })
            .collect()
    };
    let raw = build_all(false)?;
    let any_stale = raw.iter().any(|d| d.stale.iter().any(|s| *s));
    let destaled = if any_stale { Some(build_all(true)?) } else { None };
    Ok(Prepared { raw, destaled })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flight_time_continues_over_a_clock_reset() {
        let text =
            "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate,segment\n\
            10,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0\n11,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0\n\
            20,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,1\n21,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,1\n\
            0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,2\n1,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,2\n";
        let log = crate::logs::parse_log(text, "t.csv").unwrap();
        let tf: Vec<Vec<f64>> = log
            .segments
            .iter()
            .zip(flight_origins(&log))
            .map(|(s, o)| s.t.iter().map(|t| t - o).collect())
            .collect();
        assert_eq!(tf, vec![vec![0.0, 1.0], vec![10.0, 11.0], vec![12.0, 13.0]]);
    }
}
