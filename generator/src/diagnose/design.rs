//! The fitting problem of one segment under the current input transform: the residual the
//! transformed inputs leave, and the filtered regressors of the linear effects.
//!
//! With f′_m = f(x_m, ū_m) the base model with the inputs it sees (delays and lags applied,
//! [`super::catalogue::inputs`]) and L the derivative kernel ([`super::residuals`]):
//!
//! ```text
//! r⁰_k   = r_k − L[f′ − f]_k                    (vx..yaw_rate)
//! Φ̃_k   = L[Φ(x, f′_v, t)]_k                   (one 3-vector per linear column, rows vx vy vz;
//!                                               vz only for thrust_gain and thrust_decay)
//! r_k(θ) = r⁰_k − Σ_i θ_i Φ̃_{i,k}               (the residual with the linear corrections θ)
//! ```

use super::catalogue::inputs::InputTransform;
use super::catalogue::linear::{columns, regressors, Context, Sample};
use super::catalogue::EffectKind;
use super::data::SegData;
use super::residuals::{filter, Base};

/// A segment's residual and regressors under one input transform.
#[derive(Clone, Debug)]
pub(crate) struct Design {
    /// r⁰ at the interior samples.
    pub r0: Vec<[f64; 6]>,
    /// For each requested linear effect, its filtered columns (interior samples × vx vy vz).
    pub cols: Vec<(EffectKind, Vec<Vec<[f64; 3]>>)>,
}

impl Design {
    /// The filtered columns of `kind` (panics if it was not requested).
    pub fn columns_of(&self, kind: EffectKind) -> &[Vec<[f64; 3]>] {
        &self
            .cols
            .iter()
            .find(|(k, _)| *k == kind)
            .unwrap_or_else(|| panic!("design without the columns of {kind}"))
            .1
    }

    /// The residual with linear corrections: `kinds` in order, θ their concatenated parameters.
    pub fn residual(&self, kinds: &[EffectKind], theta: &[f64]) -> Vec<[f64; 6]> {
        let mut r = self.r0.clone();
        let mut at = 0;
        for &kind in kinds {
            for col in self.columns_of(kind) {
                let th = theta[at];
                at += 1;
                if th == 0.0 {
                    continue;
                }
                for (rk, ck) in r.iter_mut().zip(col) {
                    for c in 0..3 {
                        rk[c] -= th * ck[c];
                    }
                }
            }
        }
        r
    }
}

/// Effects that act on the vertical row only (their horizontal columns are 0): the thrust
/// magnitude effects, as in the `corrections` block (docs/model-format.md): behind an autopilot
/// that holds the commanded vertical speed the horizontal acceleration at a given tilt returns to
/// g·tan(tilt) once the vertical loop has compensated a thrust or mass mismatch.
pub(crate) fn vertical_only(kind: EffectKind) -> bool {
    matches!(kind, EffectKind::ThrustGain | EffectKind::ThrustDecay)
}

/// f(x_m, ū_m) at every row: the base model with the inputs it sees, its lagged acceleration rows
/// replaced by their lags' interval averages.
pub(crate) fn seen_f(seg: &SegData, base: &Base, transform: &InputTransform) -> Vec<[f64; 12]> {
    if transform.is_identity() {
        return seg.f.clone();
    }
    let u = transform.apply(&seg.u, seg.dt);
    let mut f: Vec<[f64; 12]> = seg
        .x
        .iter()
        .zip(&u)
        .map(|(x, u)| transform.model_f(base, x, u))
        .collect();
    if transform.accel_lag.iter().any(Option::is_some) {
        // The rows at the end of each sample under its input.
        let n = f.len();
        let ends: Vec<[f64; 12]> = (0..n)
            .map(|m| {
                if m + 1 < n {
                    transform.model_f(base, &seg.x[m + 1], &u[m])
                } else {
                    f[m]
                }
            })
            .collect();
        transform.lag_rows(&mut f, &ends, seg.dt);
    }
    f
}

/// The design of `seg` under `transform` with the columns of `kinds`.
pub(crate) fn design(
    seg: &SegData,
    base: &Base,
    transform: &InputTransform,
    ctx: &Context,
    kinds: &[EffectKind],
) -> Design {
    let fs = seen_f(seg, base, transform);
    design_from(seg, &fs, ctx, kinds)
}

/// [`design`] from precomputed f′.
pub(crate) fn design_from(seg: &SegData, fs: &[[f64; 12]], ctx: &Context, kinds: &[EffectKind]) -> Design {
    let n = seg.len();
    let r0 = if std::ptr::eq(fs.as_ptr(), seg.f.as_ptr()) {
        seg.r.clone()
    } else {
        let df: Vec<[f64; 6]> = fs
            .iter()
            .zip(&seg.f)
            .map(|(a, b)| std::array::from_fn(|c| a[6 + c] - b[6 + c]))
            .collect();
        let l = filter(&seg.kernel, &df, n);
        seg.r
            .iter()
            .zip(&l)
            .map(|(r, l)| std::array::from_fn(|c| r[c] - l[c]))
            .collect()
    };
    let cols = kinds
        .iter()
        .map(|&kind| {
            let p = columns(kind);
            let mut point = vec![vec![[0.0; 3]; n]; p];
            let mut buf = [[0.0; 3]; 3];
            for m in 0..n {
                let s = Sample {
                    x: &seg.x[m],
                    base_acc: [fs[m][6], fs[m][7], fs[m][8]],
                    flight_time: seg.flight_time[m],
                };
                regressors(kind, &s, ctx, &mut buf[..p]);
                if vertical_only(kind) {
                    for b in &mut buf[..p] {
                        b[0] = 0.0;
                        b[1] = 0.0;
                    }
                }
                for i in 0..p {
                    point[i][m] = buf[i];
                }
            }
            let filtered = point.iter().map(|col| filter(&seg.kernel, col, n)).collect();
            (kind, filtered)
        })
        .collect();
    Design { r0, cols }
}
