//! The "where" part: the base model's residuals on the training logs handed to
//! [`crate::analysis`] (docs/diagnose-where.md), which finds where they are large (regimes,
//! frequency bands, input correlations, data quality).
//!
//! Samples are the interior samples of every training segment (the Savitzky-Golay half window is
//! left out at both ends), concatenated. `one_step` is the filtered one-step residual of
//! [`super::residuals`] per dynamic channel; `horizon` the error x_k − x̂_k of vx..yaw_rate at the
//! end of a free run of N samples started at row k − N (NaN for the first N samples of each
//! segment, so that the analysis infers N from them; also NaN on the ground, like the one-step
//! residual there); `dt` the median sample
//! period over the segments; `time_in_flight` the time since the segment's first row.

use super::augmented::Augmented;
use super::catalogue::CHANNELS;
use super::data::SegData;
use super::shrink::run;
use crate::analysis::{analyse, WhereInput, WhereOptions, WhereReport};
use crate::logs::FlightLog;

/// Build the analysis input from the base model's residuals on `segs`.
pub(crate) fn where_input(base: &Augmented, segs: &[&SegData], horizon: usize, logs: &[FlightLog]) -> WhereInput {
    let mut input = WhereInput {
        channels: CHANNELS.iter().map(|s| s.to_string()).collect(),
        one_step: vec![Vec::new(); 6],
        horizon: Some(vec![Vec::new(); 6]),
        ..WhereInput::default()
    };
    let mut dts: Vec<f64> = segs.iter().map(|s| s.dt).collect();
    dts.sort_by(f64::total_cmp);
    input.dt = dts.get(dts.len() / 2).copied().unwrap_or(0.0);
    let with_voltage = segs.iter().all(|s| s.volt.is_some());
    // Every series is sized once (grown by doubling they would hold up to twice the samples).
    let total: usize = segs.iter().map(|s| s.interior().len()).sum();
    input.states.reserve_exact(total);
    input.inputs.reserve_exact(total);
    input.time_in_flight.reserve_exact(total);
    input.stale.reserve_exact(total);
    for c in 0..6 {
        input.one_step[c].reserve_exact(total);
        input.horizon.as_mut().expect("set above")[c].reserve_exact(total);
    }
    let mut volt = Vec::with_capacity(if with_voltage { total } else { 0 });
    for seg in segs {
        input.segment_starts.push(input.states.len());
        let seen = base.seen_inputs(seg);
        let hor = input.horizon.as_mut().expect("set above");
        for (i, k) in seg.interior().enumerate() {
            input.states.push(seg.x[k]);
            input.inputs.push(seg.u[k]);
            input.time_in_flight.push(seg.segment_time(k));
            input.stale.push(seg.stale[k]);
            if let Some(v) = &seg.volt {
                volt.push(v[k]);
            }
            let airborne = seg.airborne[i];
            for c in 0..6 {
                input.one_step[c].push(if airborne { seg.r[i][c] } else { f64::NAN });
            }
            let end = if airborne && k >= seg.h + horizon {
                let pred = run(base, seg, &seen, k - horizon, horizon);
                (pred.len() == horizon).then(|| pred[horizon - 1])
            } else {
                None
            };
            for c in 0..6 {
                hor[c].push(end.map_or(f64::NAN, |p| seg.x[k][6 + c] - p[6 + c]));
            }
        }
    }
    input.battery_voltage = with_voltage.then_some(volt);
    input.quality_notes = logs
        .iter()
        .flat_map(|l| {
            l.report
                .warnings()
                .into_iter()
                .map(move |w| format!("{}: {w}", l.source))
        })
        .collect();
    input
}

/// Run the analysis; `horizon` is the free-run length of the horizon residuals (it cannot be
/// inferred from them: they start after the Savitzky-Golay half window).
pub(crate) fn where_report(input: &WhereInput, horizon: usize) -> WhereReport {
    analyse(
        input,
        &WhereOptions {
            horizon_steps: Some(horizon),
            ..WhereOptions::default()
        },
    )
}
