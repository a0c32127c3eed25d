//! The before/after bar chart: held-out RMSE per dynamic channel, one-step (top row) and over the
//! horizon (bottom row), the base model in grey and the model with the named effects in red
//! (plotters, SVG; like generator/src/evaluate/plot.rs).

use super::catalogue::CHANNELS;
use super::shrink::Shrink;
use plotters::prelude::*;
use std::path::Path;

fn unit(row: usize, name: &str) -> &'static str {
    match (row, name) {
        (0, "vx" | "vy" | "vz") => "m/s²",
        (0, _) => "rad/s²",
        (_, "vx" | "vy" | "vz") => "m/s",
        _ => "rad/s",
    }
}

/// Write the chart to `path`.
pub(crate) fn before_after(shrink: &Shrink, path: &Path) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let root = SVGBackend::new(path, (1500, 620)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let effects = if shrink.effects.is_empty() {
        "none".to_string()
    } else {
        shrink.effects.join(" + ")
    };
    let title = format!("held-out RMSE: base model (grey) vs with {effects} (red)");
    let root = root.titled(&title, ("sans-serif", 20)).map_err(|e| err(&e))?;
    let panels = root.split_evenly((2, 6));
    for (p, area) in panels.iter().enumerate() {
        let (row, ch) = (p / 6, p % 6);
        let name = CHANNELS[ch];
        let st = shrink.per_state.iter().find(|s| s.state == name);
        let (b, a) = match (row, st) {
            (0, Some(s)) => (s.one_step_rmse_before, s.one_step_rmse_after),
            (_, Some(s)) => (s.horizon_rmse_before, s.horizon_rmse_after),
            _ => (None, None),
        };
        let (b, a) = (b.unwrap_or(0.0), a.unwrap_or(0.0));
        let top = b.max(a).max(1e-12) * 1.15;
        let kind = if row == 0 {
            "one-step".to_string()
        } else {
            format!("horizon {}", shrink.horizon)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{name} {kind} ({})", unit(row, name)), ("sans-serif", 14))
            .margin(8)
            .x_label_area_size(22)
            .y_label_area_size(52)
            .build_cartesian_2d(0.0..2.0, 0.0..top)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .light_line_style(TRANSPARENT)
            .x_labels(0)
            .y_labels(5)
            .label_style(("sans-serif", 11))
            .draw()
            .map_err(|e| err(&e))?;
        for (i, (v, colour)) in [(b, RGBColor(150, 150, 150)), (a, RED)].into_iter().enumerate() {
            let x0 = i as f64 + 0.15;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x0, 0.0), (x0 + 0.7, v)],
                    colour.filled(),
                )))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{v:.3}"),
                    (x0 + 0.1, v + 0.03 * top),
                    ("sans-serif", 11).into_font(),
                )))
                .map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
