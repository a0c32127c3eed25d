//! f′ (the base model with the inputs it sees, [`super::design::seen_f`]) for the many input
//! transforms of one scan, which differ from a reference transform in one channel only: a delay or
//! lag of input j, or the lag of an acceleration row. Where the inputs a sample sees are the
//! reference's, its f′ row is the reference's; where only input j differs, only the instructions of
//! the model's tape that depend on u_j are evaluated again ([`crate::symbolic::Partial`]), from the
//! values the reference evaluation left. Both are bit for bit what a full evaluation gives, so a
//! scan's figures do not change; it costs one full evaluation per sample instead of one per grid
//! point.
//!
//! The cache lives in the [`super::problem::Problem`] for the duration of one scan
//! ([`Scope`]); [`super::problem::Problem::seen_f`] consults it.

use super::catalogue::inputs::InputTransform;
use super::data::{dynamic, SegData};
use super::design::seen_f;
use super::residuals::Base;
use crate::symbolic::Partial;

/// The reference evaluation at one set of points (x_m, ū_m) of a segment.
struct Points {
    /// The dynamic rows vx..yaw_rate of f (the kinematic ones do not depend on the inputs and are
    /// not used).
    f: Vec<[f64; 6]>,
    /// Frontier values of the partial tape, `width` per point.
    front: Vec<f64>,
}

/// One segment under the reference transform (the inputs the model sees under it are computed
/// again when needed: [`InputTransform::apply`] is cheap next to the model).
struct SegCache {
    /// The segment's states (identity of the segment: the data are not moved while cached).
    x: *const [f64; 12],
    n: usize,
    /// At (x_m, ū_m).
    at: Points,
    /// At (x_{m+1}, ū_m) (the ends of the samples, for acceleration lags), m + 1 < n.
    ends: Option<Points>,
}

/// f′ under transforms near a reference (module docs).
pub(crate) struct SeenCache {
    reference: InputTransform,
    /// The input that may differ from the reference (None: none may, only row lags).
    input: Option<usize>,
    partial: Option<Partial>,
    segs: Vec<SegCache>,
}

impl SeenCache {
    /// The cache of `segs` under `reference`, for transforms that differ in input `input` (if any)
    /// or in the acceleration lags; `ends`: also the samples' ends (a row lag may be scanned or is
    /// present). None when the reference has loop mismatches (they evaluate the model at other
    /// points): those scans evaluate fully.
    pub fn new(
        base: &Base,
        segs: &[&SegData],
        reference: &InputTransform,
        input: Option<usize>,
        ends: bool,
    ) -> Option<Self> {
        if reference.loops.iter().any(Option::is_some) {
            return None;
        }
        let tape = base.ir.f_tape();
        let partial = input.map(|j| tape.partial(&[12 + j]));
        let width = partial.as_ref().map_or(0, Partial::frontier_len);
        let mut values = Vec::new();
        let mut eval = |x: &[f64; 12], u: &[f64; 4], front: &mut Vec<f64>| -> [f64; 6] {
            let mut vars = [0.0; 16];
            vars[..12].copy_from_slice(x);
            vars[12..].copy_from_slice(u);
            let mut out = [0.0; 12];
            tape.eval_values(&vars, &mut values, &mut out);
            if let Some(p) = &partial {
                p.gather(&values, front);
            }
            dynamic(&out)
        };
        let segs = segs
            .iter()
            .map(|seg| {
                let n = seg.x.len();
                let u = reference.apply(&seg.u, seg.dt);
                let mut at = Points {
                    f: Vec::with_capacity(n),
                    front: Vec::with_capacity(n * width),
                };
                for (x, u) in seg.x.iter().zip(&u) {
                    let f = eval(x, u, &mut at.front);
                    at.f.push(f);
                }
                let ends = ends.then(|| {
                    let mut e = Points {
                        f: Vec::with_capacity(n),
                        front: Vec::with_capacity(n * width),
                    };
                    for m in 0..n.saturating_sub(1) {
                        let f = eval(&seg.x[m + 1], &u[m], &mut e.front);
                        e.f.push(f);
                    }
                    e
                });
                SegCache {
                    x: seg.x.as_ptr(),
                    n,
                    at,
                    ends,
                }
            })
            .collect();
        Some(Self {
            reference: *reference,
            input,
            partial,
            segs,
        })
    }

    fn find(&self, seg: &SegData) -> Option<&SegCache> {
        self.segs
            .iter()
            .find(|c| std::ptr::eq(c.x, seg.x.as_ptr()) && c.n == seg.x.len())
    }

    /// f′ of `seg` under `tr` (= [`seen_f`]), from the cache where it holds the segment and `tr`
    /// has no loop mismatches.
    pub fn seen_f(&self, seg: &SegData, base: &Base, tr: &InputTransform) -> Vec<[f64; 6]> {
        let Some(c) = self.find(seg) else {
            return seen_f(seg, base, tr);
        };
        let lagged = tr.accel_lag.iter().any(Option::is_some);
        if tr.is_identity() || tr.loops.iter().any(Option::is_some) || (lagged && c.ends.is_none()) {
            return seen_f(seg, base, tr);
        }
        let u = tr.apply(&seg.u, seg.dt);
        let reference_u = self.reference.apply(&seg.u, seg.dt);
        let mut scratch = Vec::new();
        let mut f: Vec<[f64; 6]> = (0..c.n)
            .map(|m| self.point(base, &c.at, m, &seg.x[m], &reference_u[m], &u[m], &mut scratch))
            .collect();
        if lagged {
            let ends_at = c.ends.as_ref().expect("checked above");
            let ends: Vec<[f64; 6]> = (0..c.n)
                .map(|m| {
                    if m + 1 < c.n {
                        self.point(base, ends_at, m, &seg.x[m + 1], &reference_u[m], &u[m], &mut scratch)
                    } else {
                        f[m]
                    }
                })
                .collect();
            tr.lag_rows(&mut f, &ends, seg.dt);
        }
        f
    }

    /// f at (x, u) where the reference evaluated (x, `reference_u`) as point m of `points`.
    #[allow(clippy::too_many_arguments)]
    fn point(
        &self,
        base: &Base,
        points: &Points,
        m: usize,
        x: &[f64; 12],
        reference_u: &[f64; 4],
        u: &[f64; 4],
        scratch: &mut Vec<f64>,
    ) -> [f64; 6] {
        let same = |k: usize| reference_u[k].to_bits() == u[k].to_bits();
        if (0..4).all(same) {
            return points.f[m];
        }
        if let (Some(j), Some(p)) = (self.input, &self.partial) {
            if (0..4).all(|k| k == j || same(k)) {
                let w = p.frontier_len();
                let mut vars = [0.0; 16];
                vars[..12].copy_from_slice(x);
                vars[12..].copy_from_slice(u);
                // The partial tape writes the outputs that depend on u_j; the others are the
                // reference's (the kinematic rows, which no input drives, are not kept).
                let mut f = [0.0; 12];
                f[6..].copy_from_slice(&points.f[m]);
                p.eval(&points.front[m * w..(m + 1) * w], &vars, scratch, &mut f);
                return dynamic(&f);
            }
        }
        dynamic(&base.f(x, u))
    }
}
