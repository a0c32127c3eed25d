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
use super::data::{dynamic, SegData};
use super::residuals::{filter, Base};
use super::score::Sums;
use std::borrow::Cow;
use std::ops::Range;

/// Interior samples whose linear columns are computed at a time ([`SegBase::chunks`]): the
/// columns of a segment are never held whole (24 bytes per sample and column), and the results do
/// not depend on the chunk (every sample's columns and sums are computed as in one piece).
pub(crate) const CHUNK: usize = 4096;

/// The residual and the filtered columns of the linear effects of a stretch of interior samples.
#[derive(Clone, Debug)]
pub(crate) struct Design<'d> {
    /// r⁰ at the interior samples.
    pub r0: Cow<'d, [[f64; 6]]>,
    /// For each requested linear effect, its filtered columns (interior samples × vx vy vz).
    pub cols: Vec<(EffectKind, Vec<Vec<[f64; 3]>>)>,
}

impl Design<'_> {
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
        let mut r = self.r0.to_vec();
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

/// What a segment's fitting problem under one input transform is made of: r⁰ at the interior
/// samples and the base model's v̇ (the vx vy vz rows of f′) at every row — 72 bytes per row, none
/// under the base model's own transform (the prepared data hold both). The linear effects'
/// filtered columns are computed from it when needed, [`CHUNK`] samples at a time ([`SegBase::chunks`]).
pub(crate) struct SegBase<'d> {
    seg: &'d SegData<'d>,
    r0: Cow<'d, [[f64; 6]]>,
    /// v̇ of f′ at every row; None: the prepared data's f (the base model's own transform).
    acc: Option<Vec<[f64; 3]>>,
}

impl<'d> SegBase<'d> {
    /// Under the base model's own input transform: the prepared residual and f.
    pub fn identity(seg: &'d SegData<'d>) -> Self {
        Self {
            seg,
            r0: Cow::Borrowed(&seg.r),
            acc: None,
        }
    }

    /// A segment that is not used (no samples).
    pub fn unused(seg: &'d SegData<'d>) -> Self {
        Self {
            seg,
            r0: Cow::Borrowed(&[]),
            acc: Some(Vec::new()),
        }
    }

    /// From f′ at every row (its dynamic rows under the transform, [`seen_f`]).
    pub fn new(seg: &'d SegData<'d>, fs: &[[f64; 6]]) -> Self {
        let n = seg.len();
        let df: Vec<[f64; 6]> = fs
            .iter()
            .zip(&seg.f)
            .map(|(a, b)| std::array::from_fn(|c| a[c] - b[c]))
            .collect();
        let l = filter(&seg.kernel, &df, n);
        let r0 = seg
            .r
            .iter()
            .zip(&l)
            .map(|(r, l)| std::array::from_fn(|c| r[c] - l[c]))
            .collect();
        Self {
            seg,
            r0: Cow::Owned(r0),
            acc: Some(fs.iter().map(|f| [f[0], f[1], f[2]]).collect()),
        }
    }

    /// Under `transform`, f′ from `seen` (called only when the transform is not the base
    /// model's own).
    pub fn under(seg: &'d SegData<'d>, transform: &InputTransform, seen: impl FnOnce() -> Vec<[f64; 6]>) -> Self {
        if transform.is_identity() {
            Self::identity(seg)
        } else {
            Self::new(seg, &seen())
        }
    }

    /// r⁰ at the interior samples.
    #[cfg(test)]
    pub fn r0(&self) -> &[[f64; 6]] {
        &self.r0
    }

    fn acc(&self, m: usize) -> [f64; 3] {
        match &self.acc {
            Some(a) => a[m],
            None => {
                let f = &self.seg.f[m];
                [f[0], f[1], f[2]]
            }
        }
    }

    /// The design of the interior samples `range` (indices into the interior samples) with the
    /// columns of `kinds`.
    pub fn design(&self, ctx: &Context, kinds: &[EffectKind], range: Range<usize>) -> Design<'_> {
        let seg = self.seg;
        let h = seg.kernel.len() / 2;
        // Rows range.start .. range.end + 2h feed the filter at interior samples `range`.
        let rows = range.start..range.end + 2 * h;
        let len = rows.len();
        let cols = kinds
            .iter()
            .map(|&kind| {
                let p = columns(kind);
                let mut point = vec![vec![[0.0; 3]; len]; p];
                let mut buf = [[0.0; 3]; 3];
                for (i, m) in rows.clone().enumerate() {
                    let s = Sample {
                        x: &seg.x[m],
                        base_acc: self.acc(m),
                        flight_time: seg.flight_time(m),
                    };
                    regressors(kind, &s, ctx, &mut buf[..p]);
                    if vertical_only(kind) {
                        for b in &mut buf[..p] {
                            b[0] = 0.0;
                            b[1] = 0.0;
                        }
                    }
                    for q in 0..p {
                        point[q][i] = buf[q];
                    }
                }
                let filtered = point.iter().map(|col| filter(&seg.kernel, col, len)).collect();
                (kind, filtered)
            })
            .collect();
        Design {
            r0: Cow::Borrowed(&self.r0[range]),
            cols,
        }
    }

    /// The designs of all interior samples, `chunk` at a time: `f(first sample, design)`.
    pub fn chunks(&self, ctx: &Context, kinds: &[EffectKind], chunk: usize, mut f: impl FnMut(usize, &Design)) {
        let n = self.r0.len();
        let mut at = 0;
        while at < n {
            let end = (at + chunk.max(1)).min(n);
            f(at, &self.design(ctx, kinds, at..end));
            at = end;
        }
    }

    /// The residual with the linear corrections θ of `kinds` at every interior sample.
    pub fn residual(&self, ctx: &Context, kinds: &[EffectKind], theta: &[f64]) -> Vec<[f64; 6]> {
        if kinds.is_empty() {
            return self.r0.to_vec();
        }
        let mut out = Vec::with_capacity(self.r0.len());
        self.chunks(ctx, kinds, CHUNK, |_, d| out.extend(d.residual(kinds, theta)));
        out
    }

    /// Add the masked samples of the residual with the corrections θ of `kinds` to `sums`.
    pub fn add_sums(&self, ctx: &Context, kinds: &[EffectKind], theta: &[f64], mask: &[bool], sums: &mut Sums) {
        if kinds.is_empty() {
            sums.push_masked(&self.r0, mask);
            return;
        }
        self.chunks(ctx, kinds, CHUNK, |k0, d| {
            let r = d.residual(kinds, theta);
            sums.push_masked(&r, &mask[k0..k0 + r.len()]);
        });
    }
}

/// Effects that act on the vertical row only (their horizontal columns are 0): the thrust
/// magnitude effects, as in the `corrections` block (docs/model-format.md): behind an autopilot
/// that holds the commanded vertical speed the horizontal acceleration at a given tilt returns to
/// g·tan(tilt) once the vertical loop has compensated a thrust or mass mismatch.
pub(crate) fn vertical_only(kind: EffectKind) -> bool {
    matches!(kind, EffectKind::ThrustGain | EffectKind::ThrustDecay)
}

/// f(x_m, ū_m) at every row, its dynamic rows vx..yaw_rate: the base model with the inputs it
/// sees, its lagged acceleration rows replaced by their lags' interval averages.
pub(crate) fn seen_f(seg: &SegData, base: &Base, transform: &InputTransform) -> Vec<[f64; 6]> {
    if transform.is_identity() {
        return seg.f.clone();
    }
    let u = transform.apply(&seg.u, seg.dt);
    let mut f: Vec<[f64; 6]> = seg
        .x
        .iter()
        .zip(&u)
        .map(|(x, u)| dynamic(&transform.model_f(base, x, u)))
        .collect();
    if transform.accel_lag.iter().any(Option::is_some) {
        // The rows at the end of each sample under its input.
        let n = f.len();
        let ends: Vec<[f64; 6]> = (0..n)
            .map(|m| {
                if m + 1 < n {
                    dynamic(&transform.model_f(base, &seg.x[m + 1], &u[m]))
                } else {
                    f[m]
                }
            })
            .collect();
        transform.lag_rows(&mut f, &ends, seg.dt);
    }
    f
}
