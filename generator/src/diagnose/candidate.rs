//! Fitting and scoring one candidate against the current state ([`super::select`]): the
//! dispatch over the catalogue's families ([`evaluate`]), the linear effects and stale samples
//! here, the others in their own modules ([`super::input_fit`], [`super::loop_fit`],
//! [`super::response_fit`]).
//!
//! - **Linear effects**: weighted least squares of the vx vy vz residual on the filtered columns of
//!   the named linear effects and the candidate jointly ([`super::problem::fit_linear`]). Standard
//!   errors σ_θ = √(diag((ΦᵀWΦ)⁻¹) s² τ̄), s² the weighted residual variance and τ̄ the mean
//!   integrated autocorrelation time of the vx vy vz residuals; z = max_i |θ_i|/σ_i.
//! - **Latency, actuator lag** ([`super::input_fit`]): per input channel j, the delay (0 … max samples: whole samples,
//!   then quarter samples around the best) or the time constant (a logarithmic grid) is scanned;
//!   nothing else is refitted (0, no delay or lag, is a grid point). Each fit takes the value minimising Σ_c ln SSE_c over its training
//!   samples (c the channels that depend on u_j). σ from the curvature of the profile
//!   ℓ = −½ Σ_c (N/τ_c) ln SSE_c; z the likelihood-ratio z against the current model. Channels
//!   with z above the rule's threshold make up the effect (else the best channel alone, reported).
//! - **Stale samples**: the residual of the data with stale rows interpolated; z the
//!   likelihood-ratio z on the training data.

use super::catalogue::linear::columns;
use super::catalogue::{EffectKind, Family};
use super::design::{seen_f, SegBase, CHUNK};
use super::fit::MAX_LAG;
use super::problem::{fit_linear, AfterSums, Current, Problem, State};
use super::score::{taus, Rules};
use super::scored::{finish, Candidate, Install, Params, Scored};

/// The current residual summed as [`finish`] scores a candidate's (a candidate that changes nothing).
fn current_sums(p: &Problem, cur: &Current) -> AfterSums {
    let mut after = AfterSums::new(p, cur.segs.len());
    for (s, base) in cur.segs.iter().enumerate() {
        for i in 0..p.fits.len() {
            if after.wants(i, s) {
                base.chunks(&p.ctx, &cur.linear, CHUNK, |k0, d| {
                    after.add(p, i, s, k0, &d.residual(&cur.linear, &cur.theta[i]));
                });
            }
        }
    }
    after
}

/// Evaluate `kind` against `state`.
pub(crate) fn evaluate(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    match kind.family() {
        Family::Linear => linear(p, state, cur, kind, rules),
        Family::Input => super::input_fit::evaluate(p, state, cur, kind, rules),
        Family::Loop => super::loop_fit::evaluate(p, state, cur, rules),
        Family::Response => super::response_fit::evaluate(p, state, cur, rules),
        Family::Data => stale(p, state, cur, rules),
    }
}

fn linear(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    let mut kinds = state.linear.clone();
    kinds.push(kind);
    let own = columns(kind);
    let fin = p.final_fit();
    let trains: Vec<&[usize]> = p.fits.iter().map(|f| f.train.as_slice()).collect();
    let fitted = fit_linear(p, &cur.segs, &trains, &kinds, &cur.before.fit_train);
    let per_fit: Vec<Vec<f64>> = fitted.iter().map(|f| f.0.clone()).collect();
    // The residual after, summed as `finish` scores it; the final fit's training residual kept
    // for its autocorrelation time.
    let mut after = AfterSums::new(p, cur.segs.len());
    let mut fin_train: Vec<Vec<[f64; 6]>> = vec![Vec::new(); cur.segs.len()];
    for (s, base) in cur.segs.iter().enumerate() {
        let users: Vec<usize> = (0..p.fits.len()).filter(|&i| after.wants(i, s)).collect();
        if users.is_empty() {
            continue;
        }
        let keep = p.fits[fin].train.contains(&s);
        base.chunks(&p.ctx, &kinds, CHUNK, |k0, d| {
            for &i in &users {
                let res = d.residual(&kinds, &per_fit[i]);
                after.add(p, i, s, k0, &res);
                if i == fin && keep {
                    fin_train[s].extend_from_slice(&res);
                }
            }
        });
    }
    let (values, sigma) = {
        let (theta, cov, w) = &fitted[fin];
        let s = after.train;
        let ptot = theta.len();
        let dof = (3 * s.n).saturating_sub(ptot).max(1) as f64;
        let s2 = (0..3).map(|c| w[c] * s.sse[c]).sum::<f64>() / dof;
        let parts: Vec<&[[f64; 6]]> = p.fits[fin].train.iter().map(|&t| fin_train[t].as_slice()).collect();
        let tau = taus(&parts, &[0, 1, 2], MAX_LAG);
        let tau_mean = (tau[0] + tau[1] + tau[2]) / 3.0;
        let first = ptot - own;
        let values = theta[first..].to_vec();
        let sigma: Vec<f64> = (first..ptot).map(|q| (cov[(q, q)] * s2 * tau_mean).sqrt()).collect();
        (values, sigma)
    };
    drop(fin_train);
    let z = values
        .iter()
        .zip(&sigma)
        .map(|(v, s)| if *s > 0.0 { v.abs() / s } else { 0.0 })
        .filter(|z| z.is_finite())
        .fold(0.0, f64::max);
    // A parameter significantly outside the model format's range is not a physical effect (a
    // negative drag); one that is not significant is written clamped.
    let (clamped, _) = super::catalogue::linear::clamp(kind, &values);
    let names = super::catalogue::linear::parameter_names(kind);
    let invalid = (0..values.len())
        .filter(|&q| clamped[q] != values[q] && (values[q] - clamped[q]).abs() > rules.min_z * sigma[q])
        .map(|q| {
            format!(
                "{}.{} = {:.4} ± {:.4} is outside the model format's range (written as {})",
                kind, names[q], values[q], sigma[q], clamped[q]
            )
        })
        .collect::<Vec<String>>();
    // Physical checks (super::physical): every named linear effect within its plausible range with
    // this one added, and no pair of them cancelling each other on the data.
    let mut invalid = invalid;
    invalid.extend(super::physical::implausible_added(
        (&state.linear, &state.theta[fin]),
        (&kinds, &per_fit[fin]),
        p.ctx.gravity,
    ));
    invalid.extend(
        super::physical::cancelling(
            &|s, f| cur.chunks(p, s, &kinds, f),
            &p.fits[fin].train,
            &p.mask,
            &kinds,
            &per_fit[fin],
            Some(kind),
        )
        .iter()
        .map(|c| c.sentence()),
    );
    let channels = if kind == EffectKind::GroundEffect || super::design::vertical_only(kind) {
        vec![2]
    } else {
        vec![0, 1, 2]
    };
    let after_state = State {
        linear: kinds,
        theta: per_fit.clone(),
        ..state.clone()
    };
    let scored = Scored {
        kind,
        channels,
        scored: vec![0, 1, 2],
        params: Params::Linear { values, sigma },
        install: Install::Linear(per_fit),
        k: own,
        z: Some(z),
        invalid,
        after_state,
        after_horizon: None,
    };
    finish(p, cur, &after, scored, rules)
}

fn stale(p: &Problem, state: &State, cur: &Current, rules: &Rules) -> Candidate {
    let all: Vec<usize> = (0..6).collect();
    let applicable = p.data.destaled.is_some() && !state.destale;
    let (after, params, install) = if applicable {
        let segs = p.data.variant(true);
        let mut after = AfterSums::new(p, segs.len());
        for (s, seg) in segs.iter().enumerate() {
            let users: Vec<usize> = (0..p.fits.len()).filter(|&i| after.wants(i, s)).collect();
            if users.is_empty() {
                continue;
            }
            let base = SegBase::under(seg, &state.transform, || seen_f(seg, p.base, &state.transform));
            base.chunks(&p.ctx, &state.linear, CHUNK, |k0, d| {
                for &i in &users {
                    after.add(p, i, s, k0, &d.residual(&state.linear, &state.theta[i]));
                }
            });
        }
        let (train_rows, train_total) = p.data.stale_rows(false);
        let (holdout_rows, holdout_total) = p.data.stale_rows(true);
        (
            after,
            Params::Stale {
                train_rows,
                train_total,
                holdout_rows,
                holdout_total,
            },
            Install::Stale,
        )
    } else {
        (current_sums(p, cur), Params::NotApplicable, Install::Nothing)
    };
    let after_state = State {
        destale: applicable,
        ..state.clone()
    };
    let scored = Scored {
        kind: EffectKind::StaleSamples,
        channels: all.clone(),
        scored: all,
        params,
        install,
        k: 0,
        z: None,
        invalid: Vec::new(),
        after_state,
        after_horizon: None,
    };
    finish(p, cur, &after, scored, rules)
}
