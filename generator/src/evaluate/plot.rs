//! SVG plots of measured vs predicted states (12 panels), like the paper's Fig. 3-4.

use super::{traces, EvaluateError, EvaluateOptions, SegmentTraces};
use crate::logs::FlightLog;
use crate::model::Model;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Which prediction a plot shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlotKind {
    /// The free run over the whole segment from its first sample.
    WholeFlight,
    /// Free runs over the horizon, restarted from the measured state every `horizon` samples.
    Horizon,
}

impl PlotKind {
    fn suffix(self) -> &'static str {
        match self {
            PlotKind::WholeFlight => "free_run",
            PlotKind::Horizon => "horizon",
        }
    }
}

/// Plot the two kinds for every segment of `log` into `dir`: `<stem>_free_run.svg` and
/// `<stem>_horizon.svg`, where stem is the log's file stem (plus `_s<i>` for segment i when
/// the log has more than one). Returns the files written.
pub fn plot_states(
    model: &Model,
    log: &FlightLog,
    options: &EvaluateOptions,
    dir: &Path,
) -> Result<Vec<PathBuf>, EvaluateError> {
    let log = &log.with_stale(options.stale);
    let all = traces(model, log, options)?;
    let stem = Path::new(&log.source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "log".to_string());
    let mut files = Vec::new();
    for tr in &all {
        let seg = if log.segments.len() > 1 {
            format!("_s{}", tr.segment)
        } else {
            String::new()
        };
        for kind in [PlotKind::WholeFlight, PlotKind::Horizon] {
            let path = dir.join(format!("{stem}{seg}_{}.svg", kind.suffix()));
            let what = match kind {
                PlotKind::WholeFlight => "free run over the whole flight".to_string(),
                PlotKind::Horizon => format!("free runs over {} samples, restarted from the log", tr.horizon),
            };
            let title = format!(
                "{} on {}{}: measured (black) vs predicted (red), {}",
                model.name, stem, seg, what
            );
            write_svg(tr, model.base_states(), &title, kind, &path)?;
            files.push(path);
        }
    }
    Ok(files)
}

/// The plotted y range of one state: the measured range with a margin; predictions may
/// extend it by at most one measured span on each side (values beyond are drawn at the edge).
fn y_range(measured: &[f64], predicted: &[f64]) -> (f64, f64) {
    let lo = measured.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = measured.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = (hi - lo).max(1e-3 * (1.0 + lo.abs().max(hi.abs())));
    let (cap_lo, cap_hi) = (lo - span, hi + span);
    let plo = predicted.iter().copied().fold(lo, f64::min).max(cap_lo);
    let phi = predicted.iter().copied().fold(hi, f64::max).min(cap_hi);
    let margin = 0.05 * (phi - plo);
    (plo - margin, phi + margin)
}

/// Write one SVG: a 4 × 3 grid (positions, angles, velocities, angular rates), measured in
/// black and the predictions of `kind` in red, one panel per state named in `names`.
pub fn write_svg(
    tr: &SegmentTraces,
    names: &[String],
    title: &str,
    kind: PlotKind,
    path: &Path,
) -> Result<(), EvaluateError> {
    let err = |e: &dyn std::fmt::Display| EvaluateError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    // Predicted series as (time, state) polylines.
    let runs: Vec<(usize, &[[f64; 12]])> = match kind {
        PlotKind::WholeFlight => vec![(0, &tr.free_run[..])],
        PlotKind::Horizon => tr.horizon_runs.iter().map(|(k, r)| (*k, &r[..])).collect(),
    };
    let (t0, t1) = (tr.t[0], tr.t[tr.t.len() - 1].max(tr.t[0] + 1e-9));

    let root = SVGBackend::new(path, (1500, 1050)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root.titled(title, ("sans-serif", 20)).map_err(|e| err(&e))?;
    let panels = root.split_evenly((4, 3));
    for (i, area) in panels.iter().enumerate().take(names.len().min(12)) {
        let measured: Vec<f64> = tr.measured.iter().map(|x| x[i]).collect();
        let predicted: Vec<f64> = runs.iter().flat_map(|(_, r)| r.iter().map(move |x| x[i])).collect();
        let (lo, hi) = y_range(&measured, &predicted);
        let caption = match crate::analysis::state_unit(&names[i]) {
            "" => names[i].clone(),
            u => format!("{} ({u})", names[i]),
        };
        let mut chart = ChartBuilder::on(area)
            .caption(caption, ("sans-serif", 15))
            .margin(6)
            .margin_right(20)
            .x_label_area_size(30)
            .y_label_area_size(48)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_labels(6)
            .y_labels(5)
            .label_style(("sans-serif", 11))
            .light_line_style(TRANSPARENT)
            .x_desc("t (s)")
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(LineSeries::new(
                tr.t.iter().copied().zip(measured),
                BLACK.stroke_width(1),
            ))
            .map_err(|e| err(&e))?;
        for (k, run) in &runs {
            let pts = run.iter().enumerate().map(|(j, x)| (tr.t[k + j], x[i].clamp(lo, hi)));
            chart
                .draw_series(LineSeries::new(pts, RED.stroke_width(1)))
                .map_err(|e| err(&e))?;
        }
        if let (PlotKind::WholeFlight, Some(d)) = (kind, tr.diverged_at) {
            let td = tr.t[d];
            chart
                .draw_series(LineSeries::new([(td, lo), (td, hi)], BLUE.stroke_width(1)))
                .map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
