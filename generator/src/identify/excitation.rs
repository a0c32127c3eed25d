//! What the logs excite: directions an identification cannot learn from them
//! (`uavgen identify`, docs/identification.md "Unexcited directions").
//!
//! Two kinds of direction are detected, pooled over every segment of every log:
//!
//! - **A still heading.** The yaw samples, taken on the circle, fit in an arc narrower than
//!   [`ExcitationOptions::heading_arc`] (0.5 rad by default; the arc is 2π minus the largest gap
//!   between the sorted headings, so a heading that wraps across ±π counts as still). Over such an
//!   arc sin ψ and cos ψ are nearly constant: any `a·cos ψ` term is collinear with the plain `a`,
//!   and a fit may split one coefficient into a large pair that cancels on the logs and explodes at
//!   another heading. The terms with ψ are then left out of SINDy's library, and the horizon check
//!   starts its trials within the logged arc ([`Excitation::yaw_range`]).
//! - **A silent input channel.** A command carries a signal when it moves more than what the
//!   feedback noise of a held loop gives. Per channel, with σ_u the standard deviation of the
//!   command (each segment about its own mean) and σ_y that of the quantity it commands (u_vz → vz,
//!   u_roll → roll, u_pitch → pitch, u_yaw_rate → yaw_rate), the channel is silent when
//!   σ_u < [`ExcitationOptions::state_share`] · σ_y (0.1: the commanded quantity moves ten times
//!   more than the command, so its motion is noise and disturbance, not response), or
//!   σ_u < [`ExcitationOptions::bound_share`] · its MPC bound (1 %: a command that never leaves
//!   the neighbourhood of its trim). A held heading's yaw-rate command is the controller's answer
//!   to gyro noise: on a simulated nano flight σ_u = 0.0008 rad/s against σ_y = 0.026 rad/s.
//!   Terms of a silent channel are left out of SINDy's library, PD holds its gain at the unit
//!   static gain (the commanded quantity follows the command) instead of fitting 0, and no delay
//!   is estimated for it.
//!
//! [`channel_gains`] gives each channel's identified static gain (the commanded quantity per unit
//! command); a commanded channel whose gain is below [`ZERO_GAIN`] is warned about.

use crate::discretize::Envelope;
use crate::ir::ModelIr;
use crate::logs::FlightLog;
use crate::model::Model;
use std::f64::consts::PI;

/// The input channels (LOG_FORMAT.md order).
pub const INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];
/// The state each channel commands (vz, roll, pitch, yaw_rate).
pub const COMMANDED: [usize; 4] = [8, 3, 4, 11];
/// The row each channel drives (vz, roll_rate, pitch_rate, yaw_rate): the delay scan's.
pub use super::response::DRIVEN_ROW;
/// State names (log order).
const STATE_NAMES: [&str; 12] = crate::model::DEFAULT_STATES;
/// |static gain| below which a commanded channel is said to have no effect.
pub const ZERO_GAIN: f64 = 0.05;
/// The margin added on each side of the logged heading arc for the horizon check's start yaw.
pub const YAW_MARGIN: f64 = 0.1;
/// The horizon check flies each input within ± this factor times its largest logged |command|
/// ([`Excitation::check_inputs`]).
pub const INPUT_MARGIN_FACTOR: f64 = 1.5;

/// Thresholds of the detector (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ExcitationOptions {
    /// A heading whose samples fit in a narrower arc (rad) is still.
    pub heading_arc: f64,
    /// Silent: σ_u below this share of σ of the commanded quantity …
    pub state_share: f64,
    /// … or below this share of the channel's MPC bound.
    pub bound_share: f64,
    /// The channels' MPC bounds (u_vz, u_roll, u_pitch, u_yaw_rate).
    pub bounds: [f64; 4],
}

impl Default for ExcitationOptions {
    /// Arc 0.5 rad, state share 0.1, bound share 0.01, the MPC's default input bounds.
    fn default() -> Self {
        Self {
            heading_arc: 0.5,
            state_share: 0.1,
            bound_share: 0.01,
            bounds: Envelope::default().inputs,
        }
    }
}

/// One channel's excitation.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelExcitation {
    pub input: &'static str,
    /// The commanded quantity.
    pub commanded: &'static str,
    /// σ of the command and of the commanded quantity (each segment about its own mean).
    pub sd: f64,
    pub commanded_sd: f64,
    pub bound: f64,
    pub silent: bool,
    /// The largest |command| logged.
    pub max_abs: f64,
}

/// What the logs excite.
#[derive(Clone, Debug, PartialEq)]
pub struct Excitation {
    /// The narrowest arc (rad) holding every logged heading, and its centre.
    pub heading_arc: f64,
    pub heading_centre: f64,
    pub heading_still: bool,
    pub channels: Vec<ChannelExcitation>,
}

impl Excitation {
    /// Indices (in the 16 states-then-inputs variables) that the fit must not use: yaw when the
    /// heading is still, the silent inputs.
    pub fn excluded_vars(&self) -> Vec<usize> {
        let mut v = Vec::new();
        if self.heading_still {
            v.push(5);
        }
        v.extend(
            self.channels
                .iter()
                .enumerate()
                .filter(|(_, c)| c.silent)
                .map(|(j, _)| 12 + j),
        );
        v
    }

    pub fn silent(&self) -> [bool; 4] {
        core::array::from_fn(|j| self.channels.get(j).is_some_and(|c| c.silent))
    }

    /// Nothing unexcited.
    pub fn complete(&self) -> bool {
        !self.heading_still && self.channels.iter().all(|c| !c.silent)
    }

    /// The start yaw range of the horizon check: the logged arc widened by [`YAW_MARGIN`] on each
    /// side; `None` (anywhere) when that covers the circle.
    pub fn yaw_range(&self) -> Option<(f64, f64)> {
        let half = 0.5 * self.heading_arc + YAW_MARGIN;
        (half < PI).then_some((self.heading_centre - half, self.heading_centre + half))
    }

    /// The horizon check's input bounds: per channel ± [`INPUT_MARGIN_FACTOR`] × the largest logged
    /// |command| (the commands the data supports, widened by half), at most the channel's MPC bound
    /// (the MPC never commands more) and at least [`ExcitationOptions::bound_share`] of it (a
    /// channel that never moved still gets a sliver of range).
    pub fn check_inputs(&self) -> [f64; 4] {
        let floor = ExcitationOptions::default().bound_share;
        core::array::from_fn(|j| match self.channels.get(j) {
            Some(c) if c.max_abs.is_finite() => (INPUT_MARGIN_FACTOR * c.max_abs).clamp(floor * c.bound, c.bound),
            Some(c) => c.bound,
            None => Envelope::default().inputs[j],
        })
    }

    /// The warnings to print (empty when everything is excited).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.heading_still {
            w.push(format!(
                "the heading did not move (every yaw within an arc of {:.3} rad around {:.3} rad, below {:.3} rad): terms of sin/cos(yaw) are left out of the fit and the horizon check starts within the logged arc; the model is valid near this heading only",
                self.heading_arc,
                self.heading_centre,
                ExcitationOptions::default().heading_arc
            ));
        }
        for c in self.channels.iter().filter(|c| c.silent) {
            w.push(format!(
                "{} carries no signal (σ {:.4} against σ {:.4} of {} and its bound {:.3}): no delay is estimated for it, SINDy leaves its terms out and PD holds its gain at the unit static gain",
                c.input, c.sd, c.commanded_sd, c.commanded, c.bound
            ));
        }
        w
    }

    /// The record for the model's provenance.
    pub fn to_json(&self, options: &ExcitationOptions) -> serde_json::Value {
        let channels: serde_json::Map<String, serde_json::Value> = self
            .channels
            .iter()
            .map(|c| {
                (
                    c.input.to_string(),
                    serde_json::json!({
                        "sd": c.sd,
                        "commanded": c.commanded,
                        "commanded_sd": c.commanded_sd,
                        "bound": c.bound,
                        "silent": c.silent,
                        "max_abs": c.max_abs,
                    }),
                )
            })
            .collect();
        serde_json::json!({
            "heading": {
                "arc": self.heading_arc,
                "centre": self.heading_centre,
                "still": self.heading_still,
                "threshold": options.heading_arc,
            },
            "channels": channels,
            "horizon_check_inputs": self.check_inputs(),
            "rule": format!(
                "heading still: every yaw within an arc < {} rad; a channel is silent when σ_u < {} σ of the quantity it commands or < {} of its bound",
                options.heading_arc, options.state_share, options.bound_share
            ),
        })
    }
}

/// The narrowest arc holding every angle of `yaw` (rad) and its centre: (arc, centre). An empty
/// input gives (0, 0).
pub fn heading_arc(yaw: &[f64]) -> (f64, f64) {
    let mut a: Vec<f64> = yaw
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.rem_euclid(2.0 * PI))
        .collect();
    if a.is_empty() {
        return (0.0, 0.0);
    }
    a.sort_by(f64::total_cmp);
    // The largest gap between neighbours on the circle; the arc is its complement.
    let (mut gap, mut after) = (a[0] + 2.0 * PI - a[a.len() - 1], a[0]);
    for w in a.windows(2) {
        if w[1] - w[0] > gap {
            gap = w[1] - w[0];
            after = w[1];
        }
    }
    let arc = (2.0 * PI - gap).max(0.0);
    let mut centre = (after + 0.5 * arc).rem_euclid(2.0 * PI);
    if centre > PI {
        centre -= 2.0 * PI;
    }
    (arc, centre)
}

/// σ of column `f` pooled over segments, each about its own mean.
fn pooled_sd(logs: &[FlightLog], f: &dyn Fn(&crate::logs::Segment, usize) -> f64) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for seg in logs.iter().flat_map(|l| &l.segments) {
        let len = seg.t.len();
        if len == 0 {
            continue;
        }
        let vals: Vec<f64> = (0..len).map(|k| f(seg, k)).filter(|v| v.is_finite()).collect();
        if vals.is_empty() {
            continue;
        }
        let mean = vals.iter().sum::<f64>() / vals.len() as f64;
        ss += vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        n += vals.len();
    }
    if n == 0 {
        0.0
    } else {
        (ss / n as f64).sqrt()
    }
}

/// Analyse `logs` (see the module documentation).
pub fn analyse(logs: &[FlightLog], options: &ExcitationOptions) -> Excitation {
    let yaw: Vec<f64> = logs
        .iter()
        .flat_map(|l| &l.segments)
        .flat_map(|s| s.x.iter().map(|x| x[5]))
        .collect();
    let (arc, centre) = heading_arc(&yaw);
    let channels = (0..4)
        .map(|j| {
            let sd = pooled_sd(logs, &|s, k| s.u[k][j]);
            let commanded_sd = pooled_sd(logs, &|s, k| s.x[k][COMMANDED[j]]);
            let bound = options.bounds[j];
            ChannelExcitation {
                input: INPUTS[j],
                commanded: STATE_NAMES[COMMANDED[j]],
                sd,
                commanded_sd,
                bound,
                silent: sd < options.state_share * commanded_sd || sd < options.bound_share * bound,
                max_abs: logs
                    .iter()
                    .flat_map(|l| &l.segments)
                    .flat_map(|s| s.u.iter().map(move |u| u[j].abs()))
                    .filter(|v| v.is_finite())
                    .fold(0.0, f64::max),
            }
        })
        .collect();
    Excitation {
        heading_arc: arc,
        heading_centre: centre,
        heading_still: !yaw.is_empty() && arc < options.heading_arc,
        channels,
    }
}

/// Each channel's identified static gain at hover (all 12 states and the inputs 0): with the
/// driven row's sensitivities a = ∂f/∂(commanded quantity) and b = ∂f/∂u, the gain is −b/a (the
/// commanded quantity per unit command once the loop settles: u_roll → roll through roll_rate's
/// row, …). Where a ≥ 0 (no restoring term: no settled value) it is `None` when b ≠ 0 (the command
/// acts), else 0. With an input lag state (`corrections.actuator_lag`), b is the row's sensitivity
/// to that state (it settles at the command). `None` for a model without the 12 standard states
/// and 4 inputs.
pub fn channel_gains(model: &Model) -> Option<[Option<f64>; 4]> {
    if model.base_states() != crate::model::DEFAULT_STATES || model.inputs != crate::model::DEFAULT_INPUTS {
        return None;
    }
    let ir = ModelIr::new(model);
    let x = vec![0.0; model.nx()];
    let u = vec![0.0; 4];
    let (a, b) = ir.eval_jacobian(&x, &u);
    Some(core::array::from_fn(|j| {
        let (row, y) = (DRIVEN_ROW[j], COMMANDED[j]);
        // Through an input lag state `<input>_lagged` (which settles at the command) when the model
        // has one.
        let lagged = model
            .states
            .iter()
            .position(|s| s.strip_suffix("_lagged") == Some(INPUTS[j]));
        let (ay, bu) = (a[row][y], lagged.map_or(b[row][j], |l| a[row][l]));
        if !(ay.is_finite() && bu.is_finite()) {
            return None;
        }
        if ay < 0.0 {
            Some(-bu / ay)
        } else if bu.abs() > 1e-12 {
            None
        } else {
            Some(0.0)
        }
    }))
}

/// The channels whose gain is ~0 (|gain| < [`ZERO_GAIN`]) among `commanded`: (input, gain).
pub fn zero_gains(gains: &[Option<f64>; 4], commanded: [bool; 4]) -> Vec<(&'static str, f64)> {
    (0..4)
        .filter(|&j| commanded[j])
        .filter_map(|j| gains[j].filter(|g| g.abs() < ZERO_GAIN).map(|g| (INPUTS[j], g)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::logs::{FlightLog, QualityReport, Segment};

    fn log(n: usize, f: impl Fn(usize) -> ([f64; 12], [f64; 4])) -> FlightLog {
        let (x, u): (Vec<_>, Vec<_>) = (0..n).map(f).unzip();
        FlightLog {
            source: "t.csv".into(),
            metadata: Vec::new(),
            segments: vec![Segment {
                index: 0,
                t: (0..n).map(|k| k as f64 * 0.01).collect(),
                x,
                u,
                battery_voltage: None,
                first_line: 2,
            }],
            report: QualityReport {
                source: "t.csv".into(),
                rows: n,
                metadata_rate_hz: None,
                measured_period: None,
                nominal_period: None,
                segments: Vec::new(),
            },
        }
    }

    #[test]
    fn heading_arc_by_hand() {
        let (arc, c) = heading_arc(&[0.1, 0.3, 0.2]);
        assert!((arc - 0.2).abs() < 1e-12 && (c - 0.2).abs() < 1e-12, "{arc} {c}");
        // Across ±π: 3.1 and −3.1 are 0.083 rad apart, centred on π.
        let (arc, c) = heading_arc(&[3.1, -3.1]);
        assert!((arc - (2.0 * PI - 6.2)).abs() < 1e-9, "{arc}");
        assert!((c.abs() - PI).abs() < 1e-9, "{c}");
        // Unwrapped angles several turns away are the same heading.
        let (arc, _) = heading_arc(&[0.2, 0.2 + 4.0 * PI]);
        assert!(arc < 1e-9);
        // Three headings 120° apart: the arc is 240°.
        let (arc, _) = heading_arc(&[0.0, 2.0 * PI / 3.0, -2.0 * PI / 3.0]);
        assert!((arc - 4.0 * PI / 3.0).abs() < 1e-9);
        assert_eq!(heading_arc(&[]), (0.0, 0.0));
    }

    #[test]
    fn a_still_heading_and_a_silent_channel_are_found() {
        // Heading 2.45 ± 0.01 rad; u_yaw_rate ±0.001 while yaw_rate moves ±0.03 (noise);
        // u_roll commands roll and roll follows: excited.
        let l = log(2000, |k| {
            let s = (k as f64 * 0.37).sin();
            let c = (k as f64 * 0.011).sin();
            let mut x = [0.0; 12];
            x[5] = 2.45 + 0.01 * s;
            x[11] = 0.03 * (k as f64 * 1.3).sin();
            x[3] = 0.2 * c;
            x[8] = 0.5 * c;
            let u = [0.5 * c, 0.2 * c, 0.2 * c, 0.001 * s];
            (x, u)
        });
        let e = analyse(&[l], &ExcitationOptions::default());
        assert!(e.heading_still, "{e:?}");
        assert!((e.heading_centre - 2.45).abs() < 0.02);
        assert_eq!(e.silent(), [false, false, false, true]);
        assert_eq!(e.excluded_vars(), vec![5, 15]);
        assert!(!e.complete());
        let (lo, hi) = e.yaw_range().unwrap();
        assert!(lo < 2.44 - YAW_MARGIN + 1e-3 && hi > 2.46 + YAW_MARGIN - 1e-3 && hi - lo < 0.25);
        assert_eq!(e.warnings().len(), 2);
        let j = e.to_json(&ExcitationOptions::default());
        assert_eq!(j["channels"]["u_yaw_rate"]["silent"], true);
        assert_eq!(j["heading"]["still"], true);
        // The horizon check's inputs: 1.5 × the largest |command| (0.5, 0.2, 0.2 up to the sine's
        // largest sample), the silent u_yaw_rate (±0.001) at its floor, 1 % of its MPC bound.
        let b = e.check_inputs();
        let bound = ExcitationOptions::default().bounds[3];
        assert!(
            (b[0] - 0.75).abs() < 1e-3 && (b[1] - 0.3).abs() < 1e-3 && (b[2] - 0.3).abs() < 1e-3,
            "{b:?}"
        );
        assert_eq!(b[3], 0.01 * bound);
        let check = crate::identify::horizon_check::HorizonCheck::for_excitation(&e);
        assert_eq!(check.inputs, b);
        assert_eq!(check.yaw, e.yaw_range());
    }

    #[test]
    fn an_excited_flight_is_complete() {
        let l = log(3000, |k| {
            let t = k as f64 * 0.01;
            let mut x = [0.0; 12];
            x[5] = 0.8 * t;
            x[11] = 0.8 + 0.3 * (t * 2.0).sin();
            x[3] = 0.1 * (t * 3.0).sin();
            x[4] = 0.1 * (t * 2.5).sin();
            x[8] = 0.5 * (t * 1.1).sin();
            let u = [x[8], x[3], x[4], x[11]];
            (x, u)
        });
        let e = analyse(&[l], &ExcitationOptions::default());
        assert!(e.complete(), "{e:?}");
        assert!(e.yaw_range().is_none());
        assert!(e.warnings().is_empty());
        assert!(e.excluded_vars().is_empty());
    }

    #[test]
    fn a_channel_below_one_percent_of_its_bound_is_silent_even_when_the_state_is_still() {
        // Everything (states and commands) barely moves: u_vz σ 0.01 m/s against a 5 m/s bound.
        let l = log(500, |k| {
            let s = (k as f64 * 0.7).sin();
            let mut x = [0.0; 12];
            x[8] = 0.005 * s;
            (x, [0.014 * s, 0.0, 0.0, 0.0])
        });
        let e = analyse(&[l], &ExcitationOptions::default());
        assert!(e.channels[0].silent);
        assert!(e.channels[0].sd > e.channels[0].commanded_sd);
    }

    fn sindy(rows: &str) -> Model {
        let json = format!(
            r#"{{"format":"uavgen-model/1","kind":"sindy","name":"t",
            "library":["vz","u_vz","roll","roll_rate","u_roll","pitch","u_pitch","yaw_rate","u_yaw_rate"],
            "kinematic":[["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
            "coefficients":[{rows}]}}"#
        );
        crate::model::parse(&json, "t.json").unwrap()
    }

    #[test]
    fn static_gains_by_hand() {
        // vz' = −2 vz + 3 u_vz: gain 1.5. roll_rate' = −16 roll − 3 roll_rate + 8 u_roll: 0.5.
        // pitch_rate' = −3 pitch_rate + 2 u_pitch: no restoring term on pitch, the command acts:
        // None. yaw_rate' = −2 yaw_rate: gain 0.
        let m = sindy(
            r#"{"state":"vz","term":"vz","coefficient":-2.0},{"state":"vz","term":"u_vz","coefficient":3.0},
            {"state":"roll_rate","term":"roll","coefficient":-16.0},{"state":"roll_rate","term":"roll_rate","coefficient":-3.0},
            {"state":"roll_rate","term":"u_roll","coefficient":8.0},
            {"state":"pitch_rate","term":"u_pitch","coefficient":2.0},
            {"state":"yaw_rate","term":"yaw_rate","coefficient":-2.0}"#,
        );
        let g = channel_gains(&m).unwrap();
        assert!((g[0].unwrap() - 1.5).abs() < 1e-9, "{g:?}");
        assert!((g[1].unwrap() - 0.5).abs() < 1e-9, "{g:?}");
        assert_eq!(g[2], None);
        assert_eq!(g[3], Some(0.0));
        assert_eq!(zero_gains(&g, [true; 4]), vec![("u_yaw_rate", 0.0)]);
        // A channel that is not commanded (silent) is not reported here.
        assert!(zero_gains(&g, [true, true, true, false]).is_empty());
    }
}
