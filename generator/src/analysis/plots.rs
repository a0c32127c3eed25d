//! SVG plots of the "where" report: residual RMSE by regime bin, residual PSD per channel, and the
//! cross-correlation of the strongest input → residual pairs.

use super::{CrossCorrelation, WhereInput, WhereReport};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(0, 0, 0),
];

fn colour(i: usize) -> RGBColor {
    COLOURS[i % COLOURS.len()]
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

fn err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> String + '_ {
    move |e| format!("{}: {e}", path.display())
}

/// (lo, hi) of the finite values with a 5 % margin (a unit span around a constant).
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let m = if hi > lo { 0.05 * (hi - lo) } else { 0.5 };
    (lo - m, hi + m)
}

/// Residual RMSE per regime bin relative to the channel's overall RMSE: one panel per regime
/// variable, one line per channel.
fn regimes(report: &WhereReport, path: &Path) -> Result<(), String> {
    let e = err(path);
    let root = SVGBackend::new(path, (1400, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let root = root
        .titled(
            "one-step residual RMSE by regime bin / overall RMSE (x: bin median)",
            ("sans-serif", 18),
        )
        .map_err(|x| e(&x))?;
    let cols = 4;
    let rows = report.regimes.len().div_ceil(cols).max(1);
    let panels = root.split_evenly((rows, cols));
    for (ri, (regime, area)) in report.regimes.iter().zip(&panels).enumerate() {
        let xs: Vec<f64> = regime.bins.iter().map(|b| b.median).collect();
        let rel: Vec<Vec<Option<f64>>> = regime
            .one_step
            .iter()
            .zip(&report.one_step)
            .map(|(rc, s)| {
                rc.stats
                    .rmse
                    .iter()
                    .map(|v| v.filter(|_| s.rmse > 0.0).map(|v| v / s.rmse))
                    .collect()
            })
            .collect();
        let (x0, x1) = span(xs.iter().copied());
        let (_, y1) = span(rel.iter().flatten().flatten().copied());
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{} ({})", regime.label, regime.unit), ("sans-serif", 13))
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(40)
            .build_cartesian_2d(x0..x1, 0.0..y1.max(1.2))
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_labels(5)
            .y_labels(5)
            .label_style(("sans-serif", 10))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(|x| e(&x))?;
        for (c, series) in rel.iter().enumerate() {
            let pts: Vec<(f64, f64)> = xs.iter().zip(series).filter_map(|(x, y)| y.map(|y| (*x, y))).collect();
            let col = colour(c);
            let s = chart
                .draw_series(LineSeries::new(pts.clone(), col.stroke_width(2)))
                .map_err(|x| e(&x))?;
            if ri == 0 {
                s.label(report.channels[c].clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], col.stroke_width(2)));
            }
            chart
                .draw_series(pts.iter().map(|p| Circle::new(*p, 3, col.filled())))
                .map_err(|x| e(&x))?;
        }
        if ri == 0 {
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 10))
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|x| e(&x))?;
        }
    }
    root.present().map_err(|x| e(&x))
}

fn psd_panel(area: &Area, report: &WhereReport, c: usize, path: &Path) -> Result<(), String> {
    let e = err(path);
    let Some(sp) = &report.spectrum else { return Ok(()) };
    let ch = &sp.channels[c];
    if ch.psd.is_empty() {
        return Ok(());
    }
    let pts: Vec<(f64, f64)> = sp
        .frequencies
        .iter()
        .zip(&ch.psd)
        .skip(1)
        .map(|(f, p)| (*f, *p))
        .collect();
    let hi = pts.iter().map(|p| p.1).fold(0.0, f64::max).max(1e-300);
    let lo = pts
        .iter()
        .map(|p| p.1)
        .filter(|p| *p > 0.0)
        .fold(hi, f64::min)
        .max(hi * 1e-8);
    let unit = report.one_step.get(c).map_or("", |s| s.unit.as_str());
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{} ({unit})²/Hz", ch.channel), ("sans-serif", 13))
        .margin(6)
        .x_label_area_size(28)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..sp.nyquist, (lo * 0.5..hi * 2.0).log_scale())
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_labels(6)
        .y_labels(5)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 10))
        .light_line_style(TRANSPARENT)
        .x_desc("Hz")
        .draw()
        .map_err(|x| e(&x))?;
    for [_, b] in sp.bands.iter().take(sp.bands.len().saturating_sub(1)) {
        chart
            .draw_series(LineSeries::new(
                [(*b, lo * 0.5), (*b, hi * 2.0)],
                RGBColor(180, 180, 180),
            ))
            .map_err(|x| e(&x))?;
    }
    chart
        .draw_series(LineSeries::new(
            pts.into_iter().map(|(f, p)| (f, p.max(lo))),
            colour(c).stroke_width(2),
        ))
        .map_err(|x| e(&x))?;
    Ok(())
}

/// Residual PSD per channel, log scale, band edges in grey.
fn psd(report: &WhereReport, path: &Path) -> Result<(), String> {
    let e = err(path);
    let n = report.channels.len().max(1);
    let cols = n.min(3);
    let rows = n.div_ceil(cols);
    let root = SVGBackend::new(path, (1200, 330 * rows as u32 + 40)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let title = match &report.spectrum {
        Some(sp) => format!(
            "one-step residual PSD (Welch, {}-sample Hann windows, 50 % overlap)",
            sp.nperseg
        ),
        None => "one-step residual PSD: no segment long enough".to_string(),
    };
    let root = root.titled(&title, ("sans-serif", 18)).map_err(|x| e(&x))?;
    for (c, area) in root
        .split_evenly((rows, cols))
        .iter()
        .enumerate()
        .take(report.channels.len())
    {
        psd_panel(area, report, c, path)?;
    }
    root.present().map_err(|x| e(&x))
}

fn strength(x: &CrossCorrelation) -> f64 {
    (x.peak_rho.abs() / x.bound).max(x.prewhitened.peak_rho.abs() / x.prewhitened.bound)
}

/// Cross-correlation vs lag of the strongest input → residual pairs, raw (blue) and prewhitened
/// (red), with their ±bound lines.
fn xcorr(report: &WhereReport, pairs: usize, path: &Path) -> Result<(), String> {
    let e = err(path);
    let mut order: Vec<&CrossCorrelation> = report.cross_correlation.iter().collect();
    order.sort_by(|a, b| strength(b).total_cmp(&strength(a)));
    order.truncate(pairs.max(1));
    let cols = order.len().clamp(1, 3);
    let rows = order.len().div_ceil(cols).max(1);
    let root = SVGBackend::new(path, (1200, 300 * rows as u32 + 40)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let root = root
        .titled(
            "input → one-step residual cross-correlation, raw (blue) and prewhitened (red); lag > 0: input leads; \
             ±2/√N_eff dashed",
            ("sans-serif", 16),
        )
        .map_err(|x| e(&x))?;
    for (x, area) in order.iter().zip(root.split_evenly((rows, cols)).iter()) {
        let l = x.max_lag as f64;
        let pw = &x.prewhitened;
        let top = x
            .rho
            .iter()
            .chain(&pw.rho)
            .fold(x.bound.max(pw.bound), |a, v| a.max(v.abs()))
            * 1.1;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!(
                    "{} → {} (peaks {:+} raw, {:+} prewhitened)",
                    x.input, x.channel, x.peak_lag, pw.peak_lag
                ),
                ("sans-serif", 13),
            )
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(40)
            .build_cartesian_2d(-l..l, -top..top)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_labels(7)
            .y_labels(5)
            .label_style(("sans-serif", 10))
            .light_line_style(TRANSPARENT)
            .x_desc("lag (samples)")
            .draw()
            .map_err(|x| e(&x))?;
        for (rho, bound, col) in [(&x.rho, x.bound, colour(0)), (&pw.rho, pw.bound, colour(1))] {
            for b in [bound, -bound] {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(-l, b), (l, b)],
                        4,
                        4,
                        col.mix(0.6).stroke_width(1),
                    ))
                    .map_err(|x| e(&x))?;
            }
            let pts: Vec<(f64, f64)> = rho.iter().enumerate().map(|(i, r)| (i as f64 - l, *r)).collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), col.stroke_width(2)))
                .map_err(|x| e(&x))?;
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, col.filled())))
                .map_err(|x| e(&x))?;
        }
    }
    root.present().map_err(|x| e(&x))
}

/// Write `where_regimes.svg`, `where_psd.svg` and `where_xcorr.svg` into `dir` (created if
/// needed); returns the files written.
pub fn write_plots(report: &WhereReport, _input: &WhereInput, dir: &Path) -> Result<Vec<PathBuf>, String> {
    // Everything drawn is in the report; the input is in the signature for plots of raw series.
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let files = [
        dir.join("where_regimes.svg"),
        dir.join("where_psd.svg"),
        dir.join("where_xcorr.svg"),
    ];
    regimes(report, &files[0])?;
    psd(report, &files[1])?;
    xcorr(report, report.options.plot_pairs, &files[2])?;
    Ok(files.to_vec())
}
