//! The base model with named effects, stepped exactly (RK4 on an extended state) for the shrink
//! figures: what the corrected model file describes.
//!
//! Extended state z = [x (12), s (4 lag states, used for lagged inputs), t (flight time)]:
//!
//! ```text
//! ũ_j   = s_j if input j is lagged, else v_j          (v: the delayed input, interval average)
//! ẋ     = f(x, ũ) + [0 … 0, Σ Δv̇(x, f_v(x, ũ), t), 0 0 0]
//! ṡ_j   = (v_j − s_j)/τ_j
//! ṫ     = 1
//! ```
//!
//! A horizon run from the logged sample k starts at x_k, the lag states s_k that the log's inputs
//! give ([`super::catalogue::inputs::lag_states`]) and the flight time t_k.

use super::catalogue::inputs::{delayed, lag_states, InputTransform};
use super::catalogue::linear::{delta, Context, Sample};
use super::catalogue::EffectKind;
use super::data::SegData;
use super::residuals::{rk4, Base};

/// Dimension of the extended state.
const NZ: usize = 17;

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
    pub s: Vec<[f64; 4]>,
}

impl Augmented<'_> {
    /// The base model alone.
    pub fn plain<'a>(base: &'a Base, ctx: Context) -> Augmented<'a> {
        Augmented {
            base,
            ctx,
            linear: Vec::new(),
            transform: InputTransform::default(),
        }
    }

    fn deriv(&self, z: &[f64; NZ], v: &[f64; 4]) -> [f64; NZ] {
        let mut x = [0.0; 12];
        x.copy_from_slice(&z[..12]);
        let mut u = *v;
        for j in 0..4 {
            if self.transform.lag[j].is_some() {
                u[j] = z[12 + j];
            }
        }
        let f = self.base.f(&x, &u);
        let mut out = [0.0; NZ];
        out[..12].copy_from_slice(&f);
        let sample = Sample {
            x: &x,
            base_acc: [f[6], f[7], f[8]],
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
    pub fn f(&self, x: &[f64; 12], s: &[f64; 4], t: f64, v: &[f64; 4]) -> [f64; 12] {
        let mut z = [0.0; NZ];
        z[..12].copy_from_slice(x);
        z[12..16].copy_from_slice(s);
        z[16] = t;
        let d = self.deriv(&z, v);
        std::array::from_fn(|i| d[i])
    }

    /// RK4 substeps: the base model's, more if a lag is stiffer (h/τ ≤ 2 on the lag states).
    pub fn substeps(&self, dt: f64, base_substeps: usize) -> usize {
        let tau_min = self
            .transform
            .lag
            .iter()
            .flatten()
            .cloned()
            .fold(f64::INFINITY, f64::min);
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
        let mut v = seg.u.clone();
        let mut s = seg.u.clone();
        for j in 0..4 {
            let col: Vec<f64> = seg.u.iter().map(|r| r[j]).collect();
            let d = delayed(&col, seg.dt, self.transform.delay[j]);
            let st = match self.transform.lag[j] {
                Some(tau) => lag_states(&d, seg.dt, tau),
                None => d.clone(),
            };
            for m in 0..n {
                v[m][j] = d[m];
                s[m][j] = st[m];
            }
        }
        SeenInputs { v, s }
    }

    /// One sample from (x, s, t) under the delayed input v.
    pub fn step(&self, x: &[f64; 12], s: &[f64; 4], t: f64, v: &[f64; 4], dt: f64, m: usize) -> ([f64; 12], [f64; 4]) {
        let mut z = [0.0; NZ];
        z[..12].copy_from_slice(x);
        z[12..16].copy_from_slice(s);
        z[16] = t;
        let z = rk4(|z| self.deriv(z, v), &z, dt, m);
        let mut xo = [0.0; 12];
        xo.copy_from_slice(&z[..12]);
        let mut so = [0.0; 4];
        so.copy_from_slice(&z[12..16]);
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
        let corrected = parse(&attach_corrections(&text, "c.json", &c).unwrap(), "c.json").unwrap();
        // States: 12, u_roll_lagged, u_yaw_rate_lagged, flight_time.
        assert_eq!(corrected.nx(), 15);
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
            let s = [0.0, rnd(), 0.0, rnd()];
            let t = 100.0 * (rnd() + 0.5);
            let v: [f64; 4] = std::array::from_fn(|_| rnd());
            let mut z = [0.0; NZ];
            z[..12].copy_from_slice(&x);
            z[12..16].copy_from_slice(&s);
            z[16] = t;
            let mine = aug.deriv(&z, &v);
            let xs: Vec<f64> = x.iter().copied().chain([s[1], s[3], t]).collect();
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
            assert_eq!(theirs[14], 1.0);
        }
    }
}
