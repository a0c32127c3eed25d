//! Fitting and scoring `loop_mismatch` ([`super::catalogue::loops`]).
//!
//! Per loop ℓ, with the filtered columns L[own_ℓ] and L[coupling_ℓ] (the derivative kernel L of
//! [`super::residuals`], under the current input transform), least squares of the row's residual
//!
//! ```text
//! r_ℓ,k ≈ (gain − 1) L[own_ℓ]_k + (coupling − 1) L[coupling_ℓ]_k
//! ```
//!
//! on the training samples of each fit (a column whose norm is below 1e-9 of the other's is left
//! out: a row without couplings keeps coupling = 1). Standard errors from (ΦᵀΦ)⁻¹ s² τ (τ the
//! integrated autocorrelation time of the row's residual); a loop is part of the effect when its
//! z = max |θ|/σ is above the rule's threshold and its gain is positive.
//!
//! [`refit`] then refines each named loop's gain over the training free runs of one MPC horizon
//! ([`super::horizon_fit::refine_loop_gains`]): the one-step fit attenuates a loop, and reads a
//! delayed loop as a slower one.

use super::catalogue::loops::{channel, LoopParams, NLOOPS};
use super::catalogue::EffectKind;
use super::data::SegData;
use super::problem::{AfterSums, Current, Problem, State};
use super::residuals::{filter, Base};
use super::score::Rules;
use super::scored::{finish, Candidate, Install, LoopFit, Params, Scored};

/// A loop is a mismatch only when it differs materially from the base model's: its bandwidth
/// ratio √gain outside [1/[`MATERIAL_BANDWIDTH`], [`MATERIAL_BANDWIDTH`]] or its coupling changed by
/// more than [`MATERIAL_COUPLING`]. Below that the fit measures the base model's own identification
/// error, not the aircraft: a SINDy model diagnosed against fresh flights of the very plant it was
/// identified on fits gains of 1.13–1.25 (bandwidth ratio 1.06–1.12) and couplings of 1.20–1.23,
/// significantly (z 6–15) — the attenuation of a least-squares fit on noisy regressors — while the
/// real M100 against a simulator's model gives bandwidth ratios 0.66–0.74 and couplings 0.13–0.26.
pub const MATERIAL_BANDWIDTH: f64 = 1.25;
/// See [`MATERIAL_BANDWIDTH`].
pub const MATERIAL_COUPLING: f64 = 0.5;

/// Whether a loop with these parameters differs materially from the base model's.
pub fn material(gain: f64, coupling: f64) -> bool {
    let b = super::catalogue::loops::bandwidth_ratio(gain);
    !(1.0 / MATERIAL_BANDWIDTH..=MATERIAL_BANDWIDTH).contains(&b) || (coupling - 1.0).abs() > MATERIAL_COUPLING
}

/// The filtered (own, coupling) columns of every loop at a segment's interior samples, under
/// `state`'s input transform with the loops being fitted left out.
fn columns(seg: &SegData, base: &Base, state: &State) -> Vec<[f64; 2 * NLOOPS]> {
    let mut tr = state.transform;
    tr.loops = [None; NLOOPS];
    let u = tr.apply(&seg.u, seg.dt);
    let vals: Vec<[f64; 2 * NLOOPS]> = seg
        .x
        .iter()
        .zip(&u)
        .map(|(x, u)| {
            let b = tr.model_f(base, x, u);
            let mut out = [0.0; 2 * NLOOPS];
            for l in 0..NLOOPS {
                let (own, coupling) = super::catalogue::loops::parts(base, l, x, u, &b);
                out[2 * l] = own;
                out[2 * l + 1] = coupling;
            }
            out
        })
        .collect();
    filter(&seg.kernel, &vals, seg.len())
}

/// Least squares of one loop on `segs` (indices into `cols`/`res`): θ = (gain − 1, coupling − 1),
/// the unscaled covariance (2×2) and the sums (n, SSE after).
fn solve(
    cols: &[Vec<[f64; 2 * NLOOPS]>],
    res: &[Vec<[f64; 6]>],
    segs: &[usize],
    mask: &[Vec<bool>],
    l: usize,
) -> ([f64; 2], [[f64; 2]; 2], usize, f64) {
    let c = channel(l);
    let (mut a, mut b) = ([[0.0; 2]; 2], [0.0; 2]);
    let mut n = 0;
    for &s in segs {
        for (k, r) in res[s].iter().enumerate() {
            if !mask[s][k] {
                continue;
            }
            let phi = [cols[s][k][2 * l], cols[s][k][2 * l + 1]];
            for i in 0..2 {
                b[i] += phi[i] * r[c];
                for j in 0..2 {
                    a[i][j] += phi[i] * phi[j];
                }
            }
            n += 1;
        }
    }
    // Columns that carry nothing are left out (θ = 0 there).
    let scale = a[0][0].max(a[1][1]);
    let active = [a[0][0] > 1e-9 * scale, a[1][1] > 1e-9 * scale];
    let mut theta = [0.0; 2];
    let mut cov = [[0.0; 2]; 2];
    match active {
        [true, true] => {
            let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
            if det > 1e-12 * a[0][0] * a[1][1] {
                cov = [[a[1][1] / det, -a[0][1] / det], [-a[1][0] / det, a[0][0] / det]];
            } else {
                cov[0][0] = 1.0 / a[0][0];
            }
        }
        [true, false] => cov[0][0] = 1.0 / a[0][0],
        [false, true] => cov[1][1] = 1.0 / a[1][1],
        _ => {}
    }
    for i in 0..2 {
        theta[i] = cov[i][0] * b[0] + cov[i][1] * b[1];
    }
    let mut sse = 0.0;
    for &s in segs {
        for (k, r) in res[s].iter().enumerate() {
            if mask[s][k] {
                let e = r[c] - theta[0] * cols[s][k][2 * l] - theta[1] * cols[s][k][2 * l + 1];
                sse += e * e;
            }
        }
    }
    (theta, cov, n, sse)
}

/// A segment's residual `res` with the loops' corrections θ (per loop, None: not part of the
/// effect) subtracted.
fn subtract(res: &[[f64; 6]], cols: &[[f64; 2 * NLOOPS]], theta: &[Option<[f64; 2]>; NLOOPS]) -> Vec<[f64; 6]> {
    res.iter()
        .zip(cols)
        .map(|(rk, ck)| {
            let mut out = *rk;
            for (l, th) in theta.iter().enumerate() {
                if let Some(th) = th {
                    out[channel(l)] -= th[0] * ck[2 * l] + th[1] * ck[2 * l + 1];
                }
            }
            out
        })
        .collect()
}

fn params(theta: &[f64; 2]) -> LoopParams {
    LoopParams {
        gain: 1.0 + theta[0],
        coupling: 1.0 + theta[1],
    }
}

/// Evaluate `loop_mismatch` against `state`.
pub(crate) fn evaluate(p: &Problem, state: &State, cur: &Current, rules: &Rules) -> Candidate {
    let segs = p.data.variant(state.destale);
    let cols: Vec<_> = segs.iter().map(|s| columns(s, p.base, state)).collect();
    let fin = p.final_fit();
    let train = &p.fits[fin].train;
    let tau = cur.before.train_tau;
    let res_fin = cur.residual(p, fin);
    let mut fits = Vec::new();
    for l in 0..NLOOPS {
        let (theta, cov, n, sse) = solve(&cols, &res_fin, train, &p.mask, l);
        let s2 = sse / (n.saturating_sub(2).max(1)) as f64 * tau[channel(l)];
        let sig = [(cov[0][0] * s2).sqrt(), (cov[1][1] * s2).sqrt()];
        let z = (0..2)
            .filter(|&i| sig[i] > 0.0)
            .map(|i| theta[i].abs() / sig[i])
            .fold(0.0, f64::max);
        let gain = 1.0 + theta[0];
        let not_kept = if z.is_nan() || z <= rules.min_z {
            Some(format!("z = {z:.2} is not above {}", rules.min_z))
        } else if gain <= 0.0 {
            Some(format!("gain {gain:.3} is not positive"))
        } else if !material(gain, 1.0 + theta[1]) {
            Some(format!(
                "within the base model's own identification error (bandwidth ratio {:.2}, coupling {:.2}; \
                 a mismatch needs a bandwidth ratio outside {:.2}–{MATERIAL_BANDWIDTH} or a coupling changed by more \
                 than {MATERIAL_COUPLING})",
                super::catalogue::loops::bandwidth_ratio(gain),
                1.0 + theta[1],
                1.0 / MATERIAL_BANDWIDTH
            ))
        } else {
            None
        };
        fits.push(LoopFit {
            l,
            gain,
            gain_sigma: sig[0],
            coupling: 1.0 + theta[1],
            coupling_sigma: sig[1],
            z,
            kept: not_kept.is_none(),
            not_kept,
        });
    }
    let kept: Vec<usize> = (0..NLOOPS).filter(|&l| fits[l].kept).collect();
    let none_kept = kept.is_empty();
    // Without a kept loop, the strongest is scored alone (and reported, not named).
    let used: Vec<usize> = if kept.is_empty() {
        (0..NLOOPS)
            .max_by(|&a, &b| fits[a].z.total_cmp(&fits[b].z))
            .into_iter()
            .collect()
    } else {
        kept
    };
    drop(res_fin);
    let mut after = AfterSums::new(p, segs.len());
    for (i, fold) in p.fits.iter().enumerate() {
        let res = cur.residual(p, i);
        let mut theta = [None; NLOOPS];
        for &l in &used {
            theta[l] = Some(solve(&cols, &res, &fold.train, &p.mask, l).0);
        }
        for (s, (r, col)) in res.iter().zip(&cols).enumerate() {
            if after.wants(i, s) {
                after.add(p, i, s, 0, &subtract(r, col, &theta));
            }
        }
    }
    let mut transform = state.transform;
    for &l in &used {
        transform.loops[l] = Some(LoopParams {
            gain: fits[l].gain,
            coupling: fits[l].coupling,
        });
    }
    let z = used.iter().map(|&l| fits[l].z).fold(0.0, f64::max);
    let mut invalid: Vec<String> = used
        .iter()
        .filter(|&&l| fits[l].gain <= 0.0)
        .map(|&l| {
            format!(
                "loop_mismatch.{}.gain = {:.3} is not positive",
                super::catalogue::loops::name(l),
                fits[l].gain
            )
        })
        .collect();
    if none_kept {
        for &l in &used {
            if let Some(why) = &fits[l].not_kept {
                invalid.push(format!(
                    "no loop is kept; the strongest, {}: {why}",
                    super::catalogue::loops::name(l)
                ));
            }
        }
    }
    let after_state = State {
        transform,
        ..state.clone()
    };
    let channels: Vec<usize> = used.iter().map(|&l| channel(l)).collect();
    let scored = Scored {
        kind: EffectKind::LoopMismatch,
        channels: channels.clone(),
        scored: channels,
        params: Params::Loop(fits),
        install: Install::Loop(transform.loops),
        k: 2 * used.len(),
        z: Some(z),
        invalid,
        after_state,
        after_horizon: None,
    };
    finish(p, cur, &after, scored, rules)
}

/// Backfitting: the named loops refitted (all training data) on the residual of the model with
/// every other named effect, under the current transform.
pub(crate) fn refit(p: &Problem, state: &mut State) {
    if state.transform.loops.iter().all(Option::is_none) {
        return;
    }
    let mut without = state.clone();
    without.transform.loops = [None; NLOOPS];
    let fin = p.final_fit();
    let res = super::problem::current(p, &without).residual(p, fin);
    let segs = p.data.variant(state.destale);
    let cols: Vec<_> = segs.iter().map(|s| columns(s, p.base, state)).collect();
    for l in 0..NLOOPS {
        if state.transform.loops[l].is_some() {
            let (theta, ..) = solve(&cols, &res, &p.fits[fin].train, &p.mask, l);
            let fitted = params(&theta);
            if fitted.gain > 0.0 {
                state.transform.loops[l] = Some(fitted);
            }
        }
    }
    super::horizon_fit::refine_loop_gains(p, state);
}
