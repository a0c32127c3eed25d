//! The tracking report: metrics per axis and overall, solve times, statuses; Markdown and JSON.

use super::verdict::{judge, Verdict, VerdictRules};
use super::{Flight, StepAnswer};
use crate::metrics::{d1, mae, overall, rmse};
use serde::Serialize;
use std::collections::BTreeMap;

/// One closed-loop sample.
#[derive(Clone, Debug)]
pub struct TrackSample {
    pub t: f64,
    /// The trajectory's position at t.
    pub reference: [f64; 3],
    /// What the controller saw (sensor noise, stale samples).
    pub measured: [f64; 12],
    /// The plant's true state.
    pub truth: [f64; 12],
    pub answer: StepAnswer,
}

/// RMSE, MAE and d₁ of one axis (or overall: √(mean RMSE²), mean MAE, mean d₁).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AxisMetrics {
    pub rmse: f64,
    pub mae: f64,
    pub d1: f64,
}

/// Median and maximum of a time in µs.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Times {
    pub median_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
}

/// Everything `uavgen track` reports.
#[derive(Clone, Debug, Serialize)]
pub struct TrackReport {
    pub model: String,
    pub plant: String,
    pub trajectory: String,
    pub solver: String,
    pub duration_s: f64,
    pub samples: usize,
    pub seed: u64,
    /// `tracked`, `did not track` or `diverged` (docs/track.md), and the sentence that says why.
    pub verdict: Verdict,
    pub verdict_reason: String,
    /// The thresholds judged against (`--max-rmse`, `--max-distance`), m.
    pub max_rmse: f64,
    pub max_distance: f64,
    /// The samples the duration asked for (more than `samples` if the flight was lost) and the
    /// time it was lost at (null if it was not).
    pub planned_samples: usize,
    pub lost_at_s: Option<f64>,
    /// Tracking error of the true position against the trajectory, per axis x, y, z.
    pub axes: BTreeMap<String, AxisMetrics>,
    pub overall: AxisMetrics,
    /// Final-half metrics (after the approach from the start state).
    pub overall_second_half: AxisMetrics,
    /// Feedback (measurement → input) and preparation times per sample.
    pub feedback: Times,
    pub prepare: Times,
    pub statuses: BTreeMap<String, usize>,
    /// Controller errors other than `-`, by kind.
    pub controller_errors: BTreeMap<String, usize>,
    pub max_qp_iterations: usize,
    /// Inputs outside [u_min, u_max] (must be 0) and the largest excess.
    pub inputs_out_of_bounds: usize,
    pub max_bound_excess: f64,
    /// Fraction of samples with an input at a bound (|u − bound| < 1e-9).
    pub saturated_fraction: f64,
    /// Input activity over the second half, per input: mean |uₖ − uₖ₋₁| as a fraction of the
    /// input's range u_max − u_min (docs/track.md "Chatter").
    pub input_chatter: BTreeMap<String, f64>,
    /// Whether an input chatters: its `input_chatter` is above [`CHATTER_LIMIT`].
    pub chattering: bool,
}

/// An input whose mean change per sample over the second half exceeds this fraction of its range
/// chatters. Smooth loops stay below 0.01 (a nominal-plant model flying that plant: 0.006 on
/// roll); a loop that bangs between the bounds every other sample is near 1.
pub const CHATTER_LIMIT: f64 = 0.10;

/// The standard inputs' names (the samples CSV's columns), `u[j]` beyond them.
fn input_name(j: usize) -> String {
    ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"]
        .get(j)
        .map_or_else(|| format!("u[{j}]"), |n| n.to_string())
}

/// Mean |uₖ − uₖ₋₁| / (u_max − u_min) per input over `samples`.
fn input_chatter(samples: &[TrackSample], bounds: &(Vec<f64>, Vec<f64>)) -> BTreeMap<String, f64> {
    let steps = samples.len().saturating_sub(1).max(1) as f64;
    (0..bounds.0.len())
        .map(|j| {
            let range = bounds.1[j] - bounds.0[j];
            let total: f64 = samples
                .windows(2)
                .map(|w| {
                    (w[1].answer.u.get(j).copied().unwrap_or(0.0) - w[0].answer.u.get(j).copied().unwrap_or(0.0)).abs()
                })
                .filter(|d| d.is_finite())
                .sum();
            (input_name(j), total / steps / range)
        })
        .collect()
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn times(ns: impl Iterator<Item = f64>) -> Times {
    let mut v: Vec<f64> = ns.map(|n| n / 1000.0).collect();
    v.sort_by(f64::total_cmp);
    Times {
        median_us: percentile(&v, 0.5),
        p99_us: percentile(&v, 0.99),
        max_us: v.last().copied().unwrap_or(f64::NAN),
    }
}

fn axis_metrics(samples: &[TrackSample]) -> (Vec<AxisMetrics>, AxisMetrics) {
    let per: Vec<AxisMetrics> = (0..3)
        .map(|i| {
            let p: Vec<f64> = samples.iter().map(|s| s.truth[i]).collect();
            let o: Vec<f64> = samples.iter().map(|s| s.reference[i]).collect();
            AxisMetrics {
                rmse: rmse(&p, &o),
                mae: mae(&p, &o),
                d1: d1(&p, &o),
            }
        })
        .collect();
    let o = overall(
        &per.iter().map(|m| m.rmse).collect::<Vec<_>>(),
        &per.iter().map(|m| m.mae).collect::<Vec<_>>(),
        &per.iter().map(|m| m.d1).collect::<Vec<_>>(),
    );
    (
        per,
        AxisMetrics {
            rmse: o.rmse,
            mae: o.mae,
            d1: o.d1,
        },
    )
}

impl TrackReport {
    /// Build the report of a run; `bounds` = (u_min, u_max). `flight.samples` must not be empty
    /// (`fly` always flies the first sample).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model: &str,
        plant: &str,
        trajectory: &str,
        solver: &str,
        seed: u64,
        dt: f64,
        flight: &Flight,
        bounds: &(Vec<f64>, Vec<f64>),
        rules: &VerdictRules,
    ) -> Self {
        let samples = &flight.samples[..];
        let (per, all) = axis_metrics(samples);
        let (verdict, verdict_reason) = judge(flight.lost.as_ref().map(|(t, why)| (why.as_str(), *t)), all.rmse, rules);
        let (_, second) = axis_metrics(&samples[samples.len() / 2..]);
        let chatter = input_chatter(&samples[samples.len() / 2..], bounds);
        let mut statuses = BTreeMap::new();
        let mut errors = BTreeMap::new();
        let (mut out, mut excess, mut saturated) = (0, 0.0f64, 0);
        for s in samples {
            *statuses.entry(s.answer.status.clone()).or_insert(0) += 1;
            if s.answer.error != "-" {
                *errors.entry(s.answer.error.clone()).or_insert(0) += 1;
            }
            let mut at_bound = false;
            for (j, u) in s.answer.u.iter().enumerate() {
                let (lo, hi) = (bounds.0[j], bounds.1[j]);
                let e = (lo - u).max(u - hi);
                if e > 0.0 || !u.is_finite() {
                    out += 1;
                    excess = excess.max(if u.is_finite() { e } else { f64::INFINITY });
                }
                at_bound |= (u - lo).abs() < 1e-9 || (u - hi).abs() < 1e-9;
            }
            saturated += at_bound as usize;
        }
        TrackReport {
            model: model.into(),
            plant: plant.into(),
            trajectory: trajectory.into(),
            solver: solver.into(),
            duration_s: samples.len() as f64 * dt,
            samples: samples.len(),
            seed,
            verdict,
            verdict_reason,
            max_rmse: rules.max_rmse,
            max_distance: rules.max_distance,
            planned_samples: flight.planned,
            lost_at_s: flight.lost.as_ref().map(|(t, _)| *t),
            axes: ["x", "y", "z"].iter().map(|s| s.to_string()).zip(per).collect(),
            overall: all,
            overall_second_half: second,
            feedback: times(samples.iter().map(|s| s.answer.feedback_ns)),
            prepare: times(samples.iter().map(|s| s.answer.prepare_ns)),
            statuses,
            controller_errors: errors,
            max_qp_iterations: samples.iter().map(|s| s.answer.qp_iterations).max().unwrap_or(0),
            inputs_out_of_bounds: out,
            max_bound_excess: excess,
            saturated_fraction: saturated as f64 / samples.len().max(1) as f64,
            chattering: chatter.values().any(|c| *c > CHATTER_LIMIT),
            input_chatter: chatter,
        }
    }

    /// The human-readable report.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "# Tracking report: {} on {}\n\n- model: `{}`\n- plant: `{}`\n- solver: {}\n- {} samples ({:.1} s), plant seed {}\n\n",
            self.trajectory, self.plant, self.model, self.plant, self.solver, self.samples, self.duration_s, self.seed
        );
        s += &format!("**Verdict: {}** — {}.\n\n", self.verdict, self.verdict_reason);
        if self.lost_at_s.is_some() {
            s += &format!(
                "The flight stopped there: {} of {} samples flown; the metrics below cover them.\n\n",
                self.samples, self.planned_samples
            );
        }
        s += "Tracking error of the true position against the reference (whole flight, from the start state (3, 3, 5)):\n\n";
        s += "| axis | RMSE (m) | MAE (m) | d₁ |\n|---|---:|---:|---:|\n";
        for (k, m) in &self.axes {
            s += &format!("| {k} | {:.4} | {:.4} | {:.4} |\n", m.rmse, m.mae, m.d1);
        }
        s += &format!(
            "| overall | {:.4} | {:.4} | {:.4} |\n| overall, second half | {:.4} | {:.4} | {:.4} |\n\n",
            self.overall.rmse,
            self.overall.mae,
            self.overall.d1,
            self.overall_second_half.rmse,
            self.overall_second_half.mae,
            self.overall_second_half.d1
        );
        s += &format!(
            "Solve times per sample: feedback median {:.1} µs, p99 {:.1} µs, max {:.1} µs; preparation median {:.1} µs, max {:.1} µs (wall clock on this machine, not a benchmark: see `uavgen bench`).\n\n",
            self.feedback.median_us, self.feedback.p99_us, self.feedback.max_us, self.prepare.median_us, self.prepare.max_us
        );
        s += &format!(
            "QP solver statuses (how each sample's QP ended, not whether the loop tracked): {}. Controller errors: {}. Max QP iterations {}.\n\n",
            join_map(&self.statuses),
            if self.controller_errors.is_empty() {
                "none".into()
            } else {
                join_map(&self.controller_errors)
            },
            self.max_qp_iterations
        );
        s += &format!(
            "Inputs outside their bounds: {} (largest excess {:.3e}); samples with an input at a bound: {:.1} %.\n",
            self.inputs_out_of_bounds,
            self.max_bound_excess,
            100.0 * self.saturated_fraction
        );
        s += &format!(
            "\nInput activity over the second half (mean change per sample, share of the input's range): {}.{}\n",
            self.input_chatter
                .iter()
                .map(|(k, v)| format!("{k} {:.1} %", 100.0 * v))
                .collect::<Vec<_>>()
                .join(", "),
            match self.chatter_warning() {
                Some(w) => format!(" **{w}**"),
                None => String::new(),
            }
        );
        s
    }

    /// "the inputs chatter: …" when an input's activity is above [`CHATTER_LIMIT`].
    pub fn chatter_warning(&self) -> Option<String> {
        if !self.chattering {
            return None;
        }
        let worst: Vec<String> = self
            .input_chatter
            .iter()
            .filter(|(_, v)| **v > CHATTER_LIMIT)
            .map(|(k, v)| format!("{k} moves {:.0} % of its range per sample", 100.0 * v))
            .collect();
        Some(format!(
            "The inputs chatter ({}; limit {:.0} %): the loop holds the path with commands no aircraft should get — the model's loops, delays or the measurement noise do not match the plant's (docs/track.md \"Chatter\")",
            worst.join(", "),
            100.0 * CHATTER_LIMIT
        ))
    }
}

fn join_map(m: &BTreeMap<String, usize>) -> String {
    m.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
}

/// The samples as CSV: t, reference, true and measured position, inputs, status, times.
pub fn samples_csv(samples: &[TrackSample]) -> String {
    let mut s = String::from(
        "t,x_ref,y_ref,z_ref,x,y,z,x_measured,y_measured,z_measured,u_vz,u_roll,u_pitch,u_yaw_rate,status,feedback_us,prepare_us\n",
    );
    for p in samples {
        let u: Vec<String> = p.answer.u.iter().map(|v| format!("{v}")).collect();
        s += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{:.3},{:.3}\n",
            p.t,
            p.reference[0],
            p.reference[1],
            p.reference[2],
            p.truth[0],
            p.truth[1],
            p.truth[2],
            p.measured[0],
            p.measured[1],
            p.measured[2],
            u.join(","),
            p.answer.status,
            p.answer.feedback_ns / 1000.0,
            p.answer.prepare_ns / 1000.0
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::backend::StepAnswer;

    fn sample(u: &[f64]) -> TrackSample {
        TrackSample {
            t: 0.0,
            reference: [0.0; 3],
            measured: [0.0; 12],
            truth: [0.0; 12],
            answer: StepAnswer {
                u: u.to_vec(),
                status: "Solved".into(),
                qp_iterations: 1,
                feedback_ns: 0.0,
                prepare_ns: 0.0,
                error: "-".into(),
            },
        }
    }

    #[test]
    fn chatter_is_the_mean_change_per_sample_over_the_range() {
        // Input 0 (range 2) alternates between its bounds: |Δu| = 2 every step, 100 % of the range.
        // Input 1 (range 4) ramps by 0.2 per step: 5 %.
        let samples: Vec<TrackSample> = (0..5)
            .map(|k| sample(&[if k % 2 == 0 { -1.0 } else { 1.0 }, 0.2 * k as f64]))
            .collect();
        let bounds = (vec![-1.0, -2.0], vec![1.0, 2.0]);
        let c = input_chatter(&samples, &bounds);
        assert!((c["u_vz"] - 1.0).abs() < 1e-12, "{c:?}");
        assert!((c["u_roll"] - 0.05).abs() < 1e-12, "{c:?}");
        // One sample: no change, no division by zero.
        let one = input_chatter(&samples[..1], &bounds);
        assert_eq!(one["u_vz"], 0.0);
    }
}
