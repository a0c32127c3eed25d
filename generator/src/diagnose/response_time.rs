//! How each command channel answers, in the base model and in the corrected one: the step
//! response of the channel's driven state — u_vz → vz, u_roll → roll, u_pitch → pitch,
//! u_yaw_rate → yaw_rate — from rest (all states 0 at 5 m height, inputs 0), with the named
//! effects (delays, lags, gains, loop mismatch) stepped exactly ([`super::augmented`]).
//!
//! ```text
//! y(t)  = driven state after a step δ_j of input j at t = 0, minus the same run without the step
//! gain  = y(T)/δ_j                       (T = 4 s: the loops have settled)
//! t63   = the first t with |y(t)| ≥ 0.632 |y(T)|  (linear between samples)
//! ```
//!
//! For a first-order-plus-dead-time response t63 = d + τ exactly: the "total response time" of a
//! channel. The difference corrected − base is what the aircraft adds to the model's own response
//! (what a user with a simulator needs: "the roll loop answers 0.06 s later than your model").

use super::augmented::{Augmented, Lags};
use super::catalogue::inputs::delayed;
use super::problem::{Problem, State};
use serde::Serialize;

/// Driven state per input (u_vz → vz, u_roll → roll, u_pitch → pitch, u_yaw_rate → yaw_rate).
pub const OUTPUT: [usize; 4] = [8, 3, 4, 11];
/// The acceleration row each input drives (vz, roll_rate, pitch_rate, yaw_rate; 0 = vx).
pub const DRIVEN_ROW: [usize; 4] = [2, 3, 4, 5];
/// Step size per input (in the input's unit: m/s, rad, rad, rad/s).
pub const STEP: [f64; 4] = [0.5, 0.05, 0.05, 0.3];
/// Length of the simulated response, s.
pub const SETTLE: f64 = 4.0;

/// One channel's step response figures.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Response {
    /// Time to 63 % of the final value, s (None: no response).
    pub t63: Option<f64>,
    /// Final value over the step.
    pub gain: f64,
}

/// Base and corrected response of one channel.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelTime {
    pub input: String,
    pub output: String,
    pub base: Response,
    pub corrected: Response,
    /// The response time the named delays and lags of this channel add by themselves, s: the
    /// fitted delay, the change of the input's lag and the lag of the driven acceleration row.
    /// A slow-down beyond it is what [`super::physical::slowdowns`] judges.
    pub delays_and_lags: f64,
}

impl ChannelTime {
    /// The sentence of the report, e.g. "u_roll → roll: 63 % in 0.21 s (base model 0.14 s, +0.07 s),
    /// steady gain 0.98 (base 1.00)".
    pub fn sentence(&self) -> String {
        let t = |r: &Response| r.t63.map_or("—".to_string(), |t| format!("{t:.3} s"));
        let diff = match (self.corrected.t63, self.base.t63) {
            (Some(c), Some(b)) if b > 0.0 => format!(", {:+.3} s, {:.2}× the model's", c - b, c / b),
            _ => String::new(),
        };
        format!(
            "{} → {}: 63 % in {} (base model {}{diff}); steady gain {:.3} (base {:.3})",
            self.input,
            self.output,
            t(&self.corrected),
            t(&self.base),
            self.corrected.gain,
            self.base.gain
        )
    }
}

/// The step response of input j under `aug`.
fn respond(aug: &Augmented, j: usize, dt: f64, substeps: usize) -> Response {
    // The step comes after `pre` samples at rest, so that a delay delays it (the delayed input
    // holds its first value before the log starts).
    let pre = 1 + (aug.transform.total_delay(j) / dt).ceil() as usize;
    let n = pre + (SETTLE / dt).ceil() as usize + 1;
    let run = |delta: f64| -> Vec<f64> {
        let col: Vec<f64> = (0..n).map(|m| if m >= pre { delta } else { 0.0 }).collect();
        let v = delayed(&col, dt, aug.transform.total_delay(j));
        let mut x = [0.0; 12];
        x[2] = 5.0;
        let u0 = [0.0; 4];
        let b = aug.transform.model_f(aug.base, &x, &u0);
        let mut s: Lags = [0.0; 10];
        s[4..10].copy_from_slice(&b[6..12]);
        let mut out = Vec::with_capacity(n);
        for (m, vm) in v.iter().enumerate() {
            out.push(x[OUTPUT[j]]);
            let mut u = [0.0; 4];
            u[j] = *vm;
            let (xn, sn) = aug.step(&x, &s, m as f64 * dt, &u, dt, substeps);
            if !xn.iter().all(|v| v.is_finite()) {
                break;
            }
            x = xn;
            s = sn;
        }
        out
    };
    let (with, without) = (run(STEP[j]), run(0.0));
    let y: Vec<f64> = with.iter().zip(&without).skip(pre).map(|(a, b)| a - b).collect();
    let last = y.last().copied().unwrap_or(0.0);
    let gain = last / STEP[j];
    let level = 0.632 * last.abs();
    let t63 = (last.abs() > 1e-6 * STEP[j].abs()).then(|| {
        y.iter().position(|v| v.abs() >= level).map(|k| {
            if k == 0 {
                0.0
            } else {
                let (a, b) = (y[k - 1].abs(), y[k].abs());
                let frac = if b > a { (level - a) / (b - a) } else { 1.0 };
                (k as f64 - 1.0 + frac) * dt
            }
        })
    });
    Response {
        t63: t63.flatten(),
        gain,
    }
}

/// Base and corrected step responses of every input channel.
pub(crate) fn compare(p: &Problem, state: &State) -> Vec<ChannelTime> {
    let dt = p.dt();
    if dt <= 0.0 {
        return Vec::new();
    }
    let base_substeps = p.base.substeps(dt, "").unwrap_or(4);
    let plain = Augmented::plain(p.base, p.ctx);
    let corrected = p.augmented(state, p.final_fit());
    let names = crate::logs::STATE_COLUMNS;
    let (tp, tc) = (&plain.transform, &corrected.transform);
    (0..4)
        .map(|j| ChannelTime {
            input: crate::logs::INPUT_COLUMNS[j].to_string(),
            output: names[OUTPUT[j]].to_string(),
            base: respond(&plain, j, dt, base_substeps),
            corrected: respond(&corrected, j, dt, corrected.substeps(dt, base_substeps)),
            delays_and_lags: (tc.total_delay(j) - tp.total_delay(j))
                + (tc.lag[j].unwrap_or(0.0) - tp.lag[j].unwrap_or(0.0))
                + (tc.accel_lag[DRIVEN_ROW[j]].unwrap_or(0.0) - tp.accel_lag[DRIVEN_ROW[j]].unwrap_or(0.0)),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::catalogue::inputs::InputTransform;
    use crate::diagnose::catalogue::linear::Context;
    use crate::diagnose::residuals::Base;
    use crate::model::parse;

    /// A first-order yaw-rate loop ṙ = (u − r)/0.2 has t63 = 0.2 s and gain 1; with a delay of
    /// 0.1 s and an input gain of 1.5, t63 = 0.3 s and gain 1.5 (to the sample interpolation).
    #[test]
    fn first_order_plus_delay() {
        let text = r#"{"format": "uavgen-model/1", "kind": "sindy", "name": "t",
            "library": ["yaw_rate", "u_yaw_rate"],
            "kinematic": [["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
            "coefficients": [
              {"state": "yaw_rate", "term": "yaw_rate", "coefficient": -5},
              {"state": "yaw_rate", "term": "u_yaw_rate", "coefficient": 5}]}"#;
        let model = parse(text, "t.json").unwrap();
        let base = Base::new(&model, Some(4), None);
        let ctx = Context {
            gravity: 9.81,
            rotor_radius: 0.2,
        };
        let dt = 1.0 / 30.0;
        let plain = Augmented::plain(&base, ctx);
        let r = respond(&plain, 3, dt, 4);
        assert!((r.t63.unwrap() - 0.2).abs() < 2e-3, "{r:?}");
        assert!((r.gain - 1.0).abs() < 1e-6, "{r:?}");
        let mut transform = InputTransform::default();
        transform.delay[3] = 0.1;
        transform.gain[3] = Some(1.5);
        let slow = Augmented {
            base: &base,
            ctx,
            linear: Vec::new(),
            transform,
        };
        let r = respond(&slow, 3, dt, 4);
        assert!((r.t63.unwrap() - 0.3).abs() < 2e-3, "{r:?}");
        assert!((r.gain - 1.5).abs() < 1e-6, "{r:?}");
    }
}
