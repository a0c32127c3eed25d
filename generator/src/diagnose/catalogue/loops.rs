//! `loop_mismatch`: the aircraft's attitude or yaw loop is not the base model's.
//!
//! A base model identified in a simulator (or written from physics) carries that simulator's
//! autopilot in its rate rows: its bandwidth, and its couplings between channels (a simulated
//! autopilot that builds its attitude reference in the frame of an integrated yaw set-point couples
//! the yaw-rate command into roll and pitch). For each loop ℓ (roll_rate, pitch_rate, yaw_rate; the
//! model format's `LOOPS`) the base row b_ℓ(x, u) splits into
//!
//! ```text
//! own_ℓ(x, u)      = b_ℓ(x, u) with every state and input outside the loop set to 0
//!                    (roll: roll, roll_rate, u_roll; pitch: pitch, pitch_rate, u_pitch;
//!                     yaw: yaw_rate, u_yaw_rate)
//! coupling_ℓ(x, u) = b_ℓ(x, u) − own_ℓ(x, u)
//! ```
//!
//! and the aircraft's row is `gain_ℓ · own_ℓ + coupling_ℓ · coupling_ℓ` — linear in
//! θ = (gain − 1, coupling − 1), fitted by least squares on the row's filtered residual. For a
//! second-order attitude loop φ̈ = K_p(u − φ) − K_d φ̇ a gain ρ scales the natural frequency by
//! √ρ: `gain` 0.4 is a loop with 63 % of the model's bandwidth.

use super::super::residuals::Base;
use crate::model::corrections::LOOPS;

/// Number of loops.
pub const NLOOPS: usize = 3;

/// The dynamic channel (0 = vx … 5 = yaw_rate) of loop `l`.
pub const fn channel(l: usize) -> usize {
    3 + l
}

/// The loop's rate state name.
pub fn name(l: usize) -> &'static str {
    LOOPS[l].0
}

/// A loop's parameters: (gain, coupling), 1 and 1 for the base model.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LoopParams {
    pub gain: f64,
    pub coupling: f64,
}

/// `x`, `u` with every variable outside loop `l` set to 0.
fn own_point(l: usize, x: &[f64; 12], u: &[f64; 4]) -> ([f64; 12], [f64; 4]) {
    let (_, states, input) = LOOPS[l];
    let names = crate::logs::STATE_COLUMNS;
    let xo = std::array::from_fn(|k| if states.contains(&names[k]) { x[k] } else { 0.0 });
    let uo = std::array::from_fn(|j| if j == input { u[j] } else { 0.0 });
    (xo, uo)
}

/// (own, coupling) of loop `l` at (x, u); `b` is the base model's f there.
pub(crate) fn parts(base: &Base, l: usize, x: &[f64; 12], u: &[f64; 4], b: &[f64; 12]) -> (f64, f64) {
    let (xo, uo) = own_point(l, x, u);
    let row = 6 + channel(l);
    let own = base.f(&xo, &uo)[row];
    (own, b[row] - own)
}

/// Apply `loops` to the base model's f at (x, u) (the inputs it sees), in place.
pub(crate) fn apply(base: &Base, loops: &[Option<LoopParams>; NLOOPS], x: &[f64; 12], u: &[f64; 4], f: &mut [f64; 12]) {
    for (l, p) in loops.iter().enumerate() {
        if let Some(p) = p {
            let (own, coupling) = parts(base, l, x, u, f);
            f[6 + channel(l)] = p.gain * own + p.coupling * coupling;
        }
    }
}

/// A loop's bandwidth relative to the base model's, √gain (a second-order loop).
pub fn bandwidth_ratio(gain: f64) -> f64 {
    gain.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::parse;

    /// own + coupling = the row; own ignores the other channels.
    #[test]
    fn parts_split_the_row() {
        let text = r#"{"format": "uavgen-model/1", "kind": "sindy", "name": "t",
            "library": ["roll", "roll_rate", "u_roll", "pitch*u_yaw_rate", "1"],
            "kinematic": [["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
            "coefficients": [
              {"state": "roll_rate", "term": "roll", "coefficient": -80},
              {"state": "roll_rate", "term": "roll_rate", "coefficient": -10},
              {"state": "roll_rate", "term": "u_roll", "coefficient": 80},
              {"state": "roll_rate", "term": "pitch*u_yaw_rate", "coefficient": -40},
              {"state": "roll_rate", "term": "1", "coefficient": 0.5}]}"#;
        let model = parse(text, "t.json").unwrap();
        let base = Base::new(&model, Some(1), None);
        let mut x = [0.0; 12];
        x[3] = 0.1;
        x[9] = 0.2;
        x[4] = 0.3;
        let u = [1.0, 0.05, -0.2, 0.5];
        let b = base.f(&x, &u);
        let (own, coupling) = parts(&base, 0, &x, &u, &b);
        assert!((own - (-8.0 - 2.0 + 4.0 + 0.5)).abs() < 1e-12, "own {own}");
        assert!((coupling - (-40.0 * 0.3 * 0.5)).abs() < 1e-12, "coupling {coupling}");
        let mut f = b;
        apply(
            &base,
            &[
                Some(LoopParams {
                    gain: 0.5,
                    coupling: 0.0,
                }),
                None,
                None,
            ],
            &x,
            &u,
            &mut f,
        );
        assert!((f[9] - 0.5 * own).abs() < 1e-12);
        assert_eq!(f[10], b[10]);
    }
}
