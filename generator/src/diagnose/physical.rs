//! Checks that keep a diagnosis physical (docs/diagnose.md#physical-checks):
//!
//! 1. **Plausible ranges** ([`implausible`]): a linear correction whose fitted value is outside
//!    what a real effect of its kind can produce is not a finding of that effect — a force bias
//!    of more than [`MAX_FORCE_BIAS_G`] g, a thrust gain outside [[`THRUST_GAIN_MIN`],
//!    [`THRUST_GAIN_MAX`]].
//! 2. **Identifiability** ([`cancelling`]): two named linear effects whose contributions cancel on
//!    the data (each alone larger than the whole gap of the channel, together less than
//!    [`CANCEL_RATIO`] of the larger) describe one thing the data cannot split between them
//!    (force_bias z against thrust_gain·g at hover); the second is not named.
//! 3. **Slow-down** ([`slowdowns`]): a correction that makes a command channel's step response
//!    more than [`SLOWDOWN`] × slower than the base model's is flagged as suspicious.

use super::catalogue::linear::columns;
use super::catalogue::EffectKind;
use super::design::Design;
use super::response_time::ChannelTime;

/// Largest plausible force bias per unit mass, as a fraction of g, horizontally (‖(b_x, b_y)‖)
/// and vertically (|b_z|). A steady horizontal force is held by a steady tilt atan(b/g): 0.3 g
/// needs 17°, near the set-point limit of attitude autopilots (20° on the nano class, 20–35°
/// typical), and is the force of a 6 m/s wind at a rotor drag of 0.5 1/s (the highest of the
/// project's aircraft: nano 0.35, RotorPy's Crazyflie 0.27 xy / 0.53 z, M100 0.08); a trim or
/// c.g. offset of 5° gives 0.09 g. Vertically, a thrust mismatch scales with the thrust
/// (`thrust_gain`); a constant vertical force is an updraft on the rotor drag (5 m/s × 0.5 1/s =
/// 0.25 g).
pub const MAX_FORCE_BIAS_G: f64 = 0.3;

/// Plausible thrust gain κ (thrust per command × (1 + κ) = m_model/m_aircraft): from an aircraft
/// carrying its own mass again (1 + κ = 0.5: at a thrust-to-weight ratio of 2, typical, there is
/// no control margin left) to one of half the model's mass (1 + κ = 2). A battery's sag, (V/V₀)²
/// from 4.2 to 3.5 V per cell, is 0.69: inside.
pub const THRUST_GAIN_MIN: f64 = -0.5;
/// See [`THRUST_GAIN_MIN`].
pub const THRUST_GAIN_MAX: f64 = 1.0;

/// Two linear effects cancel on a channel when their summed contribution's RMS is below this
/// fraction of the larger one's (and that one is larger than the whole gap of the channel).
pub const CANCEL_RATIO: f64 = 0.5;

/// A command channel whose corrected step response (t63) is more than this many times the base
/// model's is flagged.
pub const SLOWDOWN: f64 = 2.0;

/// Why the parameters `values` of `kind` are not physical (empty when they are). `g` in m/s².
pub(crate) fn implausible(kind: EffectKind, values: &[f64], g: f64) -> Vec<String> {
    let mut out = Vec::new();
    match kind {
        EffectKind::ForceBias if values.len() == 3 => {
            let lim = MAX_FORCE_BIAS_G * g;
            let h = values[0].hypot(values[1]);
            if h.is_nan() || h > lim {
                out.push(format!(
                    "force_bias horizontal {h:.3} m/s² is above the plausible {lim:.2} m/s² ({MAX_FORCE_BIAS_G} g)"
                ));
            }
            if values[2].is_nan() || values[2].abs() > lim {
                out.push(format!(
                    "force_bias.z {:.3} m/s² is outside the plausible ±{lim:.2} m/s² (±{MAX_FORCE_BIAS_G} g)",
                    values[2]
                ));
            }
        }
        EffectKind::ThrustGain if values.len() == 1 && !(THRUST_GAIN_MIN..=THRUST_GAIN_MAX).contains(&values[0]) => {
            out.push(format!(
                "thrust_gain {:.3} is outside the plausible [{THRUST_GAIN_MIN}, {THRUST_GAIN_MAX}] (thrust per command × 0.5 … 2)",
                values[0]
            ));
        }
        _ => {}
    }
    out
}

/// Why the joint parameters `theta` of the linear effects `kinds` are not physical: (effect,
/// reason prefixed by "implausible: ").
pub(crate) fn implausible_all(kinds: &[EffectKind], theta: &[f64], g: f64) -> Vec<(EffectKind, String)> {
    let mut at = 0;
    let mut out = Vec::new();
    for &k in kinds {
        let n = columns(k);
        if at + n > theta.len() {
            break;
        }
        out.extend(
            implausible(k, &theta[at..at + n], g)
                .into_iter()
                .map(|s| (k, format!("implausible: {s}"))),
        );
        at += n;
    }
    out
}

/// What adding an effect makes implausible: the violations of `after` (the named linear effects
/// and the candidate, jointly fitted) by effects that were within range in `before`.
pub(crate) fn implausible_added(
    before: (&[EffectKind], &[f64]),
    after: (&[EffectKind], &[f64]),
    g: f64,
) -> Vec<String> {
    let was: Vec<EffectKind> = implausible_all(before.0, before.1, g)
        .into_iter()
        .map(|(k, _)| k)
        .collect();
    implausible_all(after.0, after.1, g)
        .into_iter()
        .filter(|(k, _)| !was.contains(k))
        .map(|(_, s)| s)
        .collect()
}

/// One pair of linear effects that cancel on a channel.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Cancel {
    pub a: EffectKind,
    pub b: EffectKind,
    /// 0 = vx, 1 = vy, 2 = vz.
    pub channel: usize,
    /// RMS of each contribution, of their sum and of the gap (the residual without linear
    /// effects) on the channel.
    pub rms_a: f64,
    pub rms_b: f64,
    pub rms_sum: f64,
    pub rms_gap: f64,
}

impl Cancel {
    pub fn sentence(&self) -> String {
        let ch = ["vx", "vy", "vz"][self.channel];
        format!(
            "not identifiable: {} and {} cancel on {ch} (RMS {:.3} and {:.3} alone, {:.3} together, against a gap of {:.3}): \
             the data cannot tell them apart, so they are not both named",
            self.a, self.b, self.rms_a, self.rms_b, self.rms_sum, self.rms_gap
        )
    }
}

/// The designs of segment s, a piece at a time: `designs(s, f)` calls `f(first sample, design)`
/// for consecutive pieces of the segment's interior samples (with the columns of the kinds asked
/// for).
pub(crate) type Designs<'a> = dyn Fn(usize, &mut dyn FnMut(usize, &Design)) + 'a;

/// Per-sample contribution of each linear effect of `kinds` (θ concatenated) on the masked
/// samples of `segs`, and the cancelling pairs among them that involve `only` (all pairs when
/// `None`).
pub(crate) fn cancelling(
    designs: &Designs,
    segs: &[usize],
    mask: &[Vec<bool>],
    kinds: &[EffectKind],
    theta: &[f64],
    only: Option<EffectKind>,
) -> Vec<Cancel> {
    let mut offsets = Vec::new();
    let mut at = 0;
    for &k in kinds {
        offsets.push(at);
        at += columns(k);
    }
    if at > theta.len() || kinds.len() < 2 {
        return Vec::new();
    }
    let n = kinds.len();
    // Σ a², Σ (a+b)² per pair and channel; Σ gap² per channel.
    let mut sq = vec![[0.0; 3]; n];
    let mut pair = vec![vec![[0.0; 3]; n]; n];
    let mut gap = [0.0; 3];
    let mut count = 0usize;
    let mut contrib = vec![[0.0; 3]; n];
    for &s in segs {
        designs(s, &mut |k0, d| {
            for (k, r) in d.r0.iter().enumerate() {
                if !mask[s].get(k0 + k).copied().unwrap_or(false) {
                    continue;
                }
                count += 1;
                for (e, &kind) in kinds.iter().enumerate() {
                    let mut c3 = [0.0; 3];
                    for (q, col) in d.columns_of(kind).iter().enumerate() {
                        let th = theta[offsets[e] + q];
                        for c in 0..3 {
                            c3[c] += col[k][c] * th;
                        }
                    }
                    contrib[e] = c3;
                }
                for c in 0..3 {
                    gap[c] += r[c] * r[c];
                    for a in 0..n {
                        sq[a][c] += contrib[a][c] * contrib[a][c];
                        for b in a + 1..n {
                            let v = contrib[a][c] + contrib[b][c];
                            pair[a][b][c] += v * v;
                        }
                    }
                }
            }
        });
    }
    if count == 0 {
        return Vec::new();
    }
    let rms = |v: f64| (v / count as f64).sqrt();
    let mut out = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            if only.is_some_and(|o| o != kinds[a] && o != kinds[b]) {
                continue;
            }
            for c in 0..3 {
                let (ra, rb, rs, rg) = (rms(sq[a][c]), rms(sq[b][c]), rms(pair[a][b][c]), rms(gap[c]));
                let big = ra.max(rb);
                if big > rg && rs < CANCEL_RATIO * big {
                    out.push(Cancel {
                        a: kinds[a],
                        b: kinds[b],
                        channel: c,
                        rms_a: ra,
                        rms_b: rb,
                        rms_sum: rs,
                        rms_gap: rg,
                    });
                }
            }
        }
    }
    out
}

/// The command channels whose corrected response is more than [`SLOWDOWN`] × slower than the
/// base model's once the time the named delays and lags of the channel add by themselves is taken
/// off (a measured delay of 0.1 s on a 0.09 s loop doubles its t63 and is what the aircraft does;
/// a rescaled loop that answers 4× slower is not): one warning each.
pub fn slowdowns(times: &[ChannelTime]) -> Vec<String> {
    times
        .iter()
        .filter_map(|t| {
            let (b, c) = (t.base.t63?, t.corrected.t63?);
            let rest = c - t.delays_and_lags.max(0.0);
            (b > 0.0 && c > SLOWDOWN * b && rest > SLOWDOWN * b).then(|| {
                format!(
                    "SUSPICIOUS, not recommended: the corrections make {} → {} answer {:.1}× slower than the base model \
                     (63 % in {c:.3} s against {b:.3} s, of which named delays and lags add {:.3} s; more than {SLOWDOWN}× \
                     is not what a physical effect of the catalogue does to a model of the same aircraft class) — check \
                     the named effects before using corrected.json",
                    t.input,
                    t.output,
                    c / b,
                    t.delays_and_lags
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::response_time::Response;

    fn design(n: usize, thrust_z: impl Fn(usize) -> f64, gap: impl Fn(usize) -> f64) -> Design<'static> {
        Design {
            r0: (0..n)
                .map(|k| [0.0, 0.0, gap(k), 0.0, 0.0, 0.0])
                .collect::<Vec<_>>()
                .into(),
            cols: vec![
                (
                    EffectKind::ForceBias,
                    vec![
                        vec![[1.0, 0.0, 0.0]; n],
                        vec![[0.0, 1.0, 0.0]; n],
                        vec![[0.0, 0.0, 1.0]; n],
                    ],
                ),
                (
                    EffectKind::ThrustGain,
                    vec![(0..n).map(|k| [0.0, 0.0, thrust_z(k)]).collect()],
                ),
            ],
        }
    }

    /// b_z = +8.3 and κ = −0.85 on T_z = 9.81 + a small wave: each moves vz by ~8.3 m/s², together
    /// by 0.85 × the wave; the gap is 1 m/s². They cancel. A real pair (wind and payload of the
    /// same sign) does not.
    #[test]
    fn force_bias_against_thrust_gain_cancels() {
        let n = 400;
        let d = design(n, |k| 9.81 + 0.5 * (k as f64 * 0.1).sin(), |k| (k as f64 * 0.1).sin());
        let kinds = [EffectKind::ForceBias, EffectKind::ThrustGain];
        let mask = vec![vec![true; n]];
        let c = cancelling(&|_, f| f(0, &d), &[0], &mask, &kinds, &[0.0, 0.0, 8.3, -0.85], None);
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!(
            (c[0].channel, c[0].a, c[0].b),
            (2, EffectKind::ForceBias, EffectKind::ThrustGain)
        );
        assert!((c[0].rms_a - 8.3).abs() < 1e-9 && c[0].rms_sum < 0.5, "{c:?}");
        let c = cancelling(&|_, f| f(0, &d), &[0], &mask, &kinds, &[0.0, 0.0, 0.3, 0.05], None);
        assert!(c.is_empty(), "{c:?}");
        // Opposite signs but small against the gap: not flagged (neither alone exceeds the gap).
        let c = cancelling(&|_, f| f(0, &d), &[0], &mask, &kinds, &[0.0, 0.0, 0.3, -0.03], None);
        assert!(c.is_empty(), "{c:?}");
        // Restricted to another effect: nothing.
        let c = cancelling(
            &|_, f| f(0, &d),
            &[0],
            &mask,
            &kinds,
            &[0.0, 0.0, 8.3, -0.85],
            Some(EffectKind::LinearDrag),
        );
        assert!(c.is_empty());
    }

    #[test]
    fn ranges() {
        let g = 9.81;
        assert!(implausible(EffectKind::ForceBias, &[0.4, -0.3, 0.3], g).is_empty());
        assert_eq!(implausible(EffectKind::ForceBias, &[0.0, 0.0, 8.3], g).len(), 1);
        assert_eq!(implausible(EffectKind::ForceBias, &[2.5, 2.5, 0.0], g).len(), 1);
        assert!(implausible(EffectKind::ThrustGain, &[-0.12], g).is_empty());
        assert!(implausible(EffectKind::ThrustGain, &[1.0], g).is_empty());
        assert_eq!(implausible(EffectKind::ThrustGain, &[-0.85], g).len(), 1);
        assert_eq!(implausible(EffectKind::ThrustGain, &[f64::NAN], g).len(), 1);
        assert!(implausible(EffectKind::LinearDrag, &[5.0, 5.0], g).is_empty());
        let kinds = [EffectKind::LinearDrag, EffectKind::ThrustGain];
        let all = implausible_added((&kinds[..1], &[0.1, 0.2]), (&kinds, &[0.1, 0.2, -0.85]), g);
        assert_eq!(all.len(), 1);
        assert!(all[0].starts_with("implausible: thrust_gain -0.850"), "{all:?}");
        // A violation that was there before is not the candidate's.
        let kinds = [EffectKind::ThrustGain, EffectKind::LinearDrag];
        assert!(implausible_added((&kinds[..1], &[-0.9]), (&kinds, &[-0.85, 0.1, 0.2]), g).is_empty());
    }

    #[test]
    fn a_fourfold_slowdown_is_flagged() {
        let ch = |base: f64, corrected: f64, delays_and_lags: f64| ChannelTime {
            input: "u_vz".into(),
            output: "vz".into(),
            base: Response {
                t63: Some(base),
                gain: 1.0,
            },
            corrected: Response {
                t63: Some(corrected),
                gain: 1.0,
            },
            delays_and_lags,
        };
        let w = slowdowns(&[ch(0.42, 1.67, 0.0), ch(0.163, 0.209, 0.04)]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("u_vz → vz answer 4.0× slower"), "{w:?}");
        assert!(slowdowns(&[ch(0.2, 0.4, 0.0)]).is_empty());
        // A 0.1 s delay on a 0.09 s loop: 2.1× slower, all of it the delay.
        assert!(slowdowns(&[ch(0.09, 0.19, 0.1)]).is_empty());
        // A 0.05 s delay that comes with a 3× slower loop is flagged.
        assert_eq!(slowdowns(&[ch(0.1, 0.35, 0.05)]).len(), 1);
    }
}
