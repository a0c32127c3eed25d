//! The base model with named effects, stepped exactly (RK4 on an extended state) for the shrink
//! figures: what the corrected model file describes.
//!
//! Extended state z = [x (12), s (4 lag states, used for lagged inputs), t (flight time), ℓ (6 lag
//! states of the acceleration rows, used for lagged rows)]:
//!
//! ```text
//! ũ_j   = k_j (s_j if input j is lagged, else v_j)    (v: the delayed input, interval average;
//!                                                      k_j the input gain, 1 without one)
//! b     = f(x, ũ)                                     (the base model)
//! ẋ_i   = ℓ_c if row i = 6 + c is lagged, else b_i; then + Σ Δv̇(x, a, t) on vx vy vz, with a the
//!         (vx, vy, vz) rows after that replacement
//! ṡ_j   = (v_j − s_j)/τ_j
//! ℓ̇_c   = (b_{6+c} − ℓ_c)/τ_c
//! ṫ     = 1
//! ```
//!
//! A horizon run from the logged sample k starts at x_k, the lag states s_k that the log's inputs
//! give ([`super::catalogue::inputs::lag_states`]), the acceleration lag states ℓ_k that the
//! base model's rows along the log give (the same filter, ℓ₀ = b₀) and the flight time t_k.

use super::catalogue::inputs::{delayed, lag_states, row_lag, InputTransform};
use super::catalogue::linear::{delta, Context, Sample};
use super::catalogue::EffectKind;
use super::data::SegData;
use super::residuals::{rk4, Base};

/// Dimension of the extended state.
const NZ: usize = 23;
/// Offset of ℓ in the extended state.
const L0: usize = 17;

/// The lag states of a sample: s (inputs, 0..4) and ℓ (acceleration rows, 4..10).
pub(crate) type Lags = [f64; 10];

/// The base model and the named model effects with their parameters.
pub(crate) struct Augmented<'a> {
    pub base: &'a Base,
    pub ctx: Context,
    pub linear: Vec<(EffectKind, Vec<f64>)>,
    pub transform: InputTransform,
}

/// The inputs a segment's runs need: delayed inputs (interval averages) and lag states per row.
pub(crate) struct SeenInputs {
    pub v: Vec<[f64; 4]>,
    pub s: Vec<Lags>,
}

fn pack(x: &[f64; 12], s: &Lags, t: f64) -> [f64; NZ] {
    let mut z = [0.0; NZ];
    z[..12].copy_from_slice(x);
    z[12..16].copy_from_slice(&s[..4]);
    z[16] = t;
    z[L0..].copy_from_slice(&s[4..]);
    z
}

impl Augmented<'_> {
    /// The base model alone.
    pub fn plain<'a>(base: &'a Base, ctx: Context) -> Augmented<'a> {
        Augmented {
            base,
            ctx,
            linear: Vec::new(),
            transform: InputTransform::of_base(base),
        }
    }

    /// The inputs the base model sees at z under the delayed input v.
    fn effective(&self, z: &[f64; NZ], v: &[f64; 4]) -> [f64; 4] {
        let mut u = *v;
        for j in 0..4 {
            if self.transform.lag[j].is_some() {
                u[j] = z[12 + j];
            }
            u[j] *= self.transform.gain_of(j);
        }
        u
    }

    fn deriv(&self, z: &[f64; NZ], v: &[f64; 4]) -> [f64; NZ] {
        let mut x = [0.0; 12];
        x.copy_from_slice(&z[..12]);
        let b = self.transform.model_f(self.base, &x, &self.effective(z, v));
        let mut out = [0.0; NZ];
        out[..12].copy_from_slice(&b);
        for c in 0..6 {
            if let Some(tau) = self.transform.accel_lag[c] {
                out[6 + c] = z[L0 + c];
                out[L0 + c] = (b[6 + c] - z[L0 + c]) / tau;
            }
        }
        let sample = Sample {
            x: &x,
            base_acc: [out[6], out[7], out[8]],
            flight_time: z[16],
        };
        for (kind, theta) in &self.linear {
            let d = delta(*kind, theta, &sample, &self.ctx);
            for i in 0..3 {
                out[6 + i] += d[i];
            }
        }
        for j in 0..4 {
            if let Some(tau) = self.transform.lag[j] {
                out[12 + j] = (v[j] - z[12 + j]) / tau;
            }
        }
        out[16] = 1.0;
        out
    }

    /// ẋ of the 12 states at (x, s, t) under the delayed input v.
    pub fn f(&self, x: &[f64; 12], s: &Lags, t: f64, v: &[f64; 4]) -> [f64; 12] {
        let d = self.deriv(&pack(x, s, t), v);
        std::array::from_fn(|i| d[i])
    }

    /// RK4 substeps: the base model's, more if a lag is stiffer (h/τ ≤ 2 on the lag states).
    pub fn substeps(&self, dt: f64, base_substeps: usize) -> usize {
        let tau_min = self.transform.fastest_lag();
        let lag = if tau_min.is_finite() {
            (dt / (2.0 * tau_min)).ceil() as usize
        } else {
            1
        };
        base_substeps.max(lag).max(1)
    }

    /// Delayed inputs and lag states of a segment.
    pub fn seen_inputs(&self, seg: &SegData) -> SeenInputs {
        let n = seg.len();
        let mut v = seg.u.to_vec();
        let mut s = vec![[0.0; 10]; n];
        for j in 0..4 {
            let col: Vec<f64> = seg.u.iter().map(|r| r[j]).collect();
            let d = delayed(&col, seg.dt, self.transform.total_delay(j));
            let st = match self.transform.lag[j] {
                Some(tau) => lag_states(&d, seg.dt, tau),
                None => d.clone(),
            };
            for m in 0..n {
                v[m][j] = d[m];
                s[m][j] = st[m];
            }
        }
        if self.transform.accel_lag.iter().any(Option::is_some) {
            // The base rows at the start and the end of every sample under its input, then their
            // lag (first-order hold between the two, as a flight computer would estimate it).
            let b = |m: usize, at: usize| {
                let z = pack(&seg.x[at], &s[at], seg.flight_time(at));
                self.transform
                    .model_f(self.base, &seg.x[at], &self.effective(&z, &v[m]))
            };
            let ends: Vec<([f64; 12], [f64; 12])> = (0..n).map(|m| (b(m, m), b(m, (m + 1).min(n - 1)))).collect();
            for c in 0..6 {
                if let Some(tau) = self.transform.accel_lag[c] {
                    let b0: Vec<f64> = ends.iter().map(|e| e.0[6 + c]).collect();
                    let b1: Vec<f64> = ends.iter().map(|e| e.1[6 + c]).collect();
                    let (states, _) = row_lag(&b0, &b1, seg.dt, tau);
                    for (sm, l) in s.iter_mut().zip(states) {
                        sm[4 + c] = l;
                    }
                }
            }
        }
        SeenInputs { v, s }
    }

    /// One sample from (x, s, t) under the delayed input v.
    pub fn step(&self, x: &[f64; 12], s: &Lags, t: f64, v: &[f64; 4], dt: f64, m: usize) -> ([f64; 12], Lags) {
        let z = rk4(|z| self.deriv(z, v), &pack(x, s, t), dt, m);
        let mut xo = [0.0; 12];
        xo.copy_from_slice(&z[..12]);
        let mut so = [0.0; 10];
        so[..4].copy_from_slice(&z[12..16]);
        so[4..].copy_from_slice(&z[L0..]);
        (xo, so)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{attach_corrections, parse, Corrections, Drag, GroundEffect, ThrustDecay};
    use crate::ModelIr;

    /// The augmentation stepped for the shrink figures is the model the corrected file describes:
    /// f of the corrected model's IR equals [`Augmented::deriv`] at random points.
    #[test]
    fn augmentation_matches_the_corrected_model() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/sindy_m100.json");
        let text = std::fs::read_to_string(&path).unwrap();
        let base_model = parse(&text, "sindy_m100.json").unwrap();
        let base = Base::new(&base_model, None, None);
        let ctx = Context {
            gravity: base.gravity,
            rotor_radius: 0.2,
        };
        let linear = vec![
            (EffectKind::LinearDrag, vec![0.3, 0.5]),
            (EffectKind::QuadraticDrag, vec![0.05, 0.08]),
            (EffectKind::ForceBias, vec![0.1, -0.2, 0.3]),
            (EffectKind::ThrustGain, vec![-0.1]),
            (EffectKind::ThrustDecay, vec![-0.001]),
            (EffectKind::GroundEffect, vec![1.2]),
        ];
        let mut transform = InputTransform::default();
        transform.lag[1] = Some(0.1);
        transform.lag[3] = Some(0.2);
        transform.accel_lag[2] = Some(0.05);
        transform.accel_lag[3] = Some(0.03);
        let aug = Augmented {
            base: &base,
            ctx,
            linear,
            transform,
        };
        let mut c = Corrections {
            linear_drag: Some(Drag { xy: 0.3, z: 0.5 }),
            quadratic_drag: Some(Drag { xy: 0.05, z: 0.08 }),
            force_bias: Some([0.1, -0.2, 0.3]),
            thrust_gain: Some(-0.1),
            thrust_decay: Some(ThrustDecay { per_second: -0.001 }),
            ground_effect: Some(GroundEffect {
                gain: 1.2,
                rotor_radius: 0.2,
            }),
            ..Corrections::default()
        };
        c.actuator_lag.insert("u_roll".into(), 0.1);
        c.actuator_lag.insert("u_yaw_rate".into(), 0.2);
        c.acceleration_lag.insert("vz".into(), 0.05);
        c.acceleration_lag.insert("roll_rate".into(), 0.03);
        let corrected = parse(&attach_corrections(&text, "c.json", &c).unwrap(), "c.json").unwrap();
        // States: 12, u_roll_lagged, u_yaw_rate_lagged, vz_dot_lagged, roll_rate_dot_lagged,
        // flight_time.
        assert_eq!(corrected.nx(), 17);
        let ir = ModelIr::new(&corrected);
        let mut seed = 7u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..50 {
            let x: [f64; 12] = std::array::from_fn(|i| if i == 2 { 0.3 + rnd() } else { rnd() });
            let (l_vz, l_roll) = (5.0 * rnd(), 20.0 * rnd());
            let s = [0.0, rnd(), 0.0, rnd(), 0.0, 0.0, l_vz, l_roll, 0.0, 0.0];
            let t = 100.0 * (rnd() + 0.5);
            let v: [f64; 4] = std::array::from_fn(|_| rnd());
            let z = pack(&x, &s, t);
            let mine = aug.deriv(&z, &v);
            let xs: Vec<f64> = x.iter().copied().chain([s[1], s[3], l_vz, l_roll, t]).collect();
            let theirs = ir.eval_f(&xs, &v);
            for i in 0..12 {
                assert!(
                    (mine[i] - theirs[i]).abs() < 1e-12,
                    "row {i}: {} vs {}",
                    mine[i],
                    theirs[i]
                );
            }
            assert!((mine[13] - theirs[12]).abs() < 1e-12 && (mine[15] - theirs[13]).abs() < 1e-12);
            assert!((mine[L0 + 2] - theirs[14]).abs() < 1e-9 * theirs[14].abs().max(1.0));
            assert!((mine[L0 + 3] - theirs[15]).abs() < 1e-9 * theirs[15].abs().max(1.0));
            assert_eq!(theirs[16], 1.0);
        }
    }
}
