//! The effects that are linear in their parameters: Δv̇ = Φ(x, T, t) θ on the vx, vy, vz rows.
//!
//! Each column of Φ is a 3-vector (the vx, vy, vz components); with v the velocity, T = v̇_base +
//! g e_z, s = √(‖v‖² + ε²), ρ² = (R/4)² / (z² + (R/4)²) and t the flight time:
//!
//! ```text
//! linear_drag     columns  (−vx, −vy, 0)       (0, 0, −vz)          θ = (d, d_z)
//! quadratic_drag  columns  (−s vx, −s vy, 0)   (0, 0, −s vz)        θ = (c, c_z)
//! force_bias      columns  e_x  e_y  e_z                            θ = (b_x, b_y, b_z)
//! thrust_gain     column   T                                        θ = κ
//! thrust_decay    column   t T                                      θ = c
//! ground_effect   column   (0, 0, T_z ρ²)                           θ = k
//! ```

use super::EffectKind;
use crate::model::corrections::QUADRATIC_DRAG_EPSILON;

/// What the regressors need besides the sample.
#[derive(Clone, Copy, Debug)]
pub struct Context {
    /// g in m/s² (the PD model's gravity, else 9.81).
    pub gravity: f64,
    /// Rotor radius R of the ground effect, in m.
    pub rotor_radius: f64,
}

/// One sample's inputs to the regressors.
#[derive(Clone, Copy, Debug)]
pub struct Sample<'a> {
    pub x: &'a [f64; 12],
    /// The base model's v̇ (rows vx, vy, vz) with the inputs the model sees.
    pub base_acc: [f64; 3],
    /// Flight time in s.
    pub flight_time: f64,
}

/// Number of parameters (columns) of a linear effect; 0 for the others.
pub fn columns(kind: EffectKind) -> usize {
    match kind {
        EffectKind::LinearDrag | EffectKind::QuadraticDrag => 2,
        EffectKind::ForceBias => 3,
        EffectKind::ThrustGain | EffectKind::ThrustDecay | EffectKind::GroundEffect => 1,
        _ => 0,
    }
}

/// The parameter names, in column order (the keys of the `corrections` block where it has keys).
pub fn parameter_names(kind: EffectKind) -> &'static [&'static str] {
    match kind {
        EffectKind::LinearDrag | EffectKind::QuadraticDrag => &["xy", "z"],
        EffectKind::ForceBias => &["x", "y", "z"],
        EffectKind::ThrustGain => &["gain"],
        EffectKind::ThrustDecay => &["per_second"],
        EffectKind::GroundEffect => &["gain"],
        _ => &[],
    }
}

/// The linear effects, in catalogue order.
pub fn linear_kinds() -> impl Iterator<Item = EffectKind> {
    EffectKind::ALL.into_iter().filter(|k| columns(*k) > 0)
}

/// The smooth speed √(‖v‖² + ε²) of the quadratic drag.
pub fn smooth_speed(v: &[f64]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + QUADRATIC_DRAG_EPSILON * QUADRATIC_DRAG_EPSILON).sqrt()
}

/// ρ² = (R/4)² / (z² + (R/4)²) of the ground effect at height z.
pub fn ground_factor(z: f64, rotor_radius: f64) -> f64 {
    let q = (rotor_radius / 4.0).powi(2);
    q / (z * z + q)
}

/// Write the columns of `kind` at one sample into `out` (length [`columns`]).
pub fn regressors(kind: EffectKind, s: &Sample, ctx: &Context, out: &mut [[f64; 3]]) {
    let v = &s.x[6..9];
    let thrust = [s.base_acc[0], s.base_acc[1], s.base_acc[2] + ctx.gravity];
    match kind {
        EffectKind::LinearDrag => {
            out[0] = [-v[0], -v[1], 0.0];
            out[1] = [0.0, 0.0, -v[2]];
        }
        EffectKind::QuadraticDrag => {
            let sp = smooth_speed(v);
            out[0] = [-sp * v[0], -sp * v[1], 0.0];
            out[1] = [0.0, 0.0, -sp * v[2]];
        }
        EffectKind::ForceBias => {
            out[0] = [1.0, 0.0, 0.0];
            out[1] = [0.0, 1.0, 0.0];
            out[2] = [0.0, 0.0, 1.0];
        }
        // Vertical only: behind an autopilot that holds the commanded vertical speed, a thrust or
        // mass mismatch shows in the vertical response; the horizontal acceleration at a given
        // tilt is g·tan(tilt) once the vertical loop has compensated (docs/model-format.md).
        EffectKind::ThrustGain => out[0] = [0.0, 0.0, thrust[2]],
        EffectKind::ThrustDecay => out[0] = [0.0, 0.0, s.flight_time * thrust[2]],
        EffectKind::GroundEffect => out[0] = [0.0, 0.0, thrust[2] * ground_factor(s.x[2], ctx.rotor_radius)],
        _ => {}
    }
}

/// Δv̇ of a linear effect with parameters θ at one sample.
pub fn delta(kind: EffectKind, theta: &[f64], s: &Sample, ctx: &Context) -> [f64; 3] {
    let mut cols = [[0.0; 3]; 3];
    let n = columns(kind);
    regressors(kind, s, ctx, &mut cols[..n]);
    let mut d = [0.0; 3];
    for (c, th) in cols[..n].iter().zip(theta) {
        for i in 0..3 {
            d[i] += c[i] * th;
        }
    }
    d
}

/// θ of a linear effect made valid for the model format; notes for clamped values.
pub(crate) fn clamp(kind: EffectKind, theta: &[f64]) -> (Vec<f64>, Vec<String>) {
    let mut out = theta.to_vec();
    let mut notes = Vec::new();
    let names = parameter_names(kind);
    let mut floor = |i: usize, lo: f64, strict: bool| {
        if out[i] < lo || (strict && out[i] <= lo) || !out[i].is_finite() {
            let to = if strict { lo + 0.01 } else { lo };
            notes.push(format!(
                "{kind}.{} fitted {:.4}, written as {to} (the model format requires {} {lo})",
                names[i],
                out[i],
                if strict { ">" } else { "≥" }
            ));
            out[i] = to;
        }
    };
    match kind {
        EffectKind::LinearDrag | EffectKind::QuadraticDrag => {
            floor(0, 0.0, false);
            floor(1, 0.0, false);
        }
        EffectKind::GroundEffect => floor(0, 0.0, false),
        EffectKind::ThrustGain => floor(0, -1.0, true),
        _ => {}
    }
    (out, notes)
}

/// The named linear effects with their (clamped) parameters from the concatenated θ.
pub(crate) fn linear_parameters(kinds: &[EffectKind], theta: &[f64]) -> (Vec<(EffectKind, Vec<f64>)>, Vec<String>) {
    let mut at = 0;
    let mut out = Vec::new();
    let mut notes = Vec::new();
    for &kind in kinds {
        let p = columns(kind);
        let (v, n) = clamp(kind, &theta[at..at + p]);
        at += p;
        out.push((kind, v));
        notes.extend(n);
    }
    (out, notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regressors_match_the_corrections_equations() {
        let mut x = [0.0; 12];
        x[2] = 0.3;
        x[6..9].copy_from_slice(&[1.0, -2.0, 0.5]);
        let s = Sample {
            x: &x,
            base_acc: [0.4, -0.2, 1.0],
            flight_time: 10.0,
        };
        let ctx = Context {
            gravity: 9.81,
            rotor_radius: 0.2,
        };
        let d = delta(EffectKind::LinearDrag, &[0.3, 0.5], &s, &ctx);
        assert_eq!(d, [-0.3, 0.6, -0.25]);
        let sp = (1.0f64 + 4.0 + 0.25 + 0.01).sqrt();
        let d = delta(EffectKind::QuadraticDrag, &[0.1, 0.2], &s, &ctx);
        assert!((d[0] + 0.1 * sp).abs() < 1e-15 && (d[2] + 0.2 * sp * 0.5).abs() < 1e-15);
        let d = delta(EffectKind::ThrustGain, &[0.1], &s, &ctx);
        assert!((d[2] - 0.1 * 10.81).abs() < 1e-12 && d[0] == 0.0 && d[1] == 0.0);
        let d = delta(EffectKind::ThrustDecay, &[-0.001], &s, &ctx);
        assert!((d[2] + 0.01 * 10.81).abs() < 1e-12);
        let d = delta(EffectKind::GroundEffect, &[1.0], &s, &ctx);
        let q = 0.05f64 * 0.05;
        assert!((d[2] - 10.81 * q / (0.09 + q)).abs() < 1e-12 && d[0] == 0.0);
    }
}
