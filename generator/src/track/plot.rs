//! SVG plots of a tracking run: the 3D path against the reference (the paper's Fig. 5–7) and the
//! position errors over time (Fig. 8).

use super::TrackSample;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(1e-3);
    (lo - pad, hi + pad)
}

fn err<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> String + '_ {
    move |e| format!("{}: {e}", path.display())
}

/// The 3D path (true position) and the reference.
pub fn path_3d(samples: &[TrackSample], title: &str, path: &Path) -> Result<(), String> {
    let root = SVGBackend::new(path, (900, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let all = || {
        samples
            .iter()
            .flat_map(|s| [s.reference, [s.truth[0], s.truth[1], s.truth[2]]])
    };
    let (x0, x1) = range(all().map(|p| p[0]));
    let (y0, y1) = range(all().map(|p| p[1]));
    let (z0, z1) = range(all().map(|p| p[2]));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(20)
        .build_cartesian_3d(x0..x1, z0..z1, y0..y1)
        .map_err(err(path))?;
    chart.with_projection(|mut p| {
        p.pitch = 0.45;
        p.yaw = 0.6;
        p.scale = 0.85;
        p.into_matrix()
    });
    chart.configure_axes().draw().map_err(err(path))?;
    chart
        .draw_series(LineSeries::new(
            samples.iter().map(|s| (s.reference[0], s.reference[2], s.reference[1])),
            &BLUE,
        ))
        .map_err(err(path))?
        .label("reference")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .draw_series(LineSeries::new(
            samples.iter().map(|s| (s.truth[0], s.truth[2], s.truth[1])),
            &RED,
        ))
        .map_err(err(path))?
        .label("flown (true position)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(err(path))?;
    root.present().map_err(err(path))
}

/// Position error (true − reference) per axis over time.
pub fn errors(samples: &[TrackSample], title: &str, path: &Path) -> Result<(), String> {
    let root = SVGBackend::new(path, (900, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let root = root.titled(title, ("sans-serif", 20)).map_err(err(path))?;
    let panels = root.split_evenly((3, 1));
    let t1 = samples.last().map_or(1.0, |s| s.t.max(1e-3));
    for (i, (panel, name)) in panels.iter().zip(["x", "y", "z"]).enumerate() {
        let e: Vec<(f64, f64)> = samples.iter().map(|s| (s.t, s.truth[i] - s.reference[i])).collect();
        let (lo, hi) = range(e.iter().map(|p| p.1));
        let mut chart = ChartBuilder::on(panel)
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t1, lo..hi)
            .map_err(err(path))?;
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc(format!("{name} error (m)"))
            .draw()
            .map_err(err(path))?;
        chart.draw_series(LineSeries::new(e, &RED)).map_err(err(path))?;
    }
    root.present().map_err(err(path))
}

/// Both plots into `dir`; the files written.
pub fn write(samples: &[TrackSample], label: &str, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let a = dir.join("path_3d.svg");
    path_3d(samples, &format!("{label}: 3D path"), &a)?;
    let b = dir.join("position_errors.svg");
    errors(samples, &format!("{label}: position error"), &b)?;
    Ok(vec![a, b])
}
