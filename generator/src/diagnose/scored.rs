//! A candidate's fitted parameters and score ([`Candidate`]), the scoring every candidate family
//! shares ([`finish`], [`under`]), and the fitted channel responses and loops the parameters hold.
//! The families ([`super::candidate`], [`super::loop_fit`], [`super::response_fit`]) depend on
//! this module; it depends on none of them.

use super::catalogue::inputs::InputTransform;
use super::catalogue::EffectKind;
use super::design::{SegBase, CHUNK};
use super::horizon_rule::horizon_errors;
pub(crate) use super::problem::{roles, AfterSums, Role};
use super::problem::{Current, HorizonErrors, Problem, State};
use super::score::{delta_bic, lr_z, reduction, Rules, Sums};

/// A scanned input parameter of one channel.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct InputParam {
    /// Input index (u_vz, u_roll, u_pitch, u_yaw_rate).
    pub input: usize,
    /// Delay or time constant, s (fit on all training data).
    pub value: f64,
    /// A delay refined over the horizon ([`super::horizon_fit`]): the one-step scan's optimum, to
    /// which `sigma` and `z` belong, and the residual cross-correlation's delay, the other end of
    /// the bracket it was refined in.
    pub one_step: Option<f64>,
    pub seed: Option<f64>,
    pub sigma: Option<f64>,
    /// Likelihood-ratio z of this channel alone.
    pub z: f64,
    /// Part of the effect: z above the threshold, no stronger kept channel on the same rows,
    /// and the held-out free runs not worse with it.
    pub kept: bool,
    /// Why a channel that moved is not part of the effect.
    pub not_kept: Option<String>,
}

/// The fitted parameters of a candidate (fit on all training data).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Params {
    /// In the order of [`columns`](super::catalogue::linear::parameter_names).
    Linear {
        values: Vec<f64>,
        sigma: Vec<f64>,
    },
    Input(Vec<InputParam>),
    /// Per input channel: delay, lag and gain fitted together.
    Response(Vec<ChannelFit>),
    /// Per loop (roll, pitch, yaw).
    Loop(Vec<LoopFit>),
    Stale {
        train_rows: usize,
        train_total: usize,
        holdout_rows: usize,
        holdout_total: usize,
    },
    NotApplicable,
}

/// What naming the candidate changes in the state.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Install {
    /// θ of the named linear effects and this one, per fit.
    Linear(Vec<Vec<f64>>),
    /// (input, value) of the channels that make up the effect.
    Input(Vec<(usize, f64)>),
    /// The channels that make up a channel response.
    Response(Vec<ChannelFit>),
    /// The loops' parameters (fit on all training data).
    Loop([Option<super::catalogue::loops::LoopParams>; super::catalogue::loops::NLOOPS]),
    Stale,
    Nothing,
}

/// A candidate's fit and score in one round.
#[derive(Clone, Debug)]
pub(crate) struct Candidate {
    pub kind: EffectKind,
    /// Dynamic channels (0 = vx … 5 = yaw_rate) the effect acts on; RMSEs and the reduction are
    /// reported over these.
    pub channels: Vec<usize>,
    pub params: Params,
    pub install: Install,
    pub train_before: Sums,
    pub train_after: Sums,
    pub test_before: Sums,
    pub test_after: Sums,
    /// Mean effective sample size N/τ over the scored channels (training, held out), τ of the
    /// residual before the candidate.
    pub train_n_eff: f64,
    pub test_n_eff: f64,
    /// Parameters added.
    pub k: usize,
    pub z: f64,
    pub delta_bic_train: f64,
    /// The score: held-out ΔBIC (lower is better).
    pub delta_bic_test: f64,
    pub reduction: f64,
    /// The reduction as a share of the base model's held-out RMSE (= `reduction` in round 1).
    pub reduction_of_base: f64,
    /// Held-out horizon rule ([`super::horizon_rule`]): mean over the 12 states of the MSE ratio
    /// after/before of free runs over the horizon (None when not evaluated: another rule failed).
    pub horizon_ratio: Option<f64>,
    pub significant: bool,
    /// Why it is not significant (empty when it is).
    pub reasons: Vec<String>,
}

pub(crate) struct Scored {
    pub kind: EffectKind,
    pub channels: Vec<usize>,
    pub scored: Vec<usize>,
    pub params: Params,
    pub install: Install,
    pub k: usize,
    /// z from standard errors (linear effects); the likelihood-ratio z otherwise.
    pub z: Option<f64>,
    /// Why the fitted parameters are not acceptable (outside the model format's range).
    pub invalid: Vec<String>,
    /// The model with the candidate added, for the horizon rule, and its horizon errors if
    /// already known.
    pub after_state: State,
    pub after_horizon: Option<HorizonErrors>,
}

/// Sums with every channel's SSE at least N × floor.
fn floored(mut s: Sums, floor: &[f64; 6]) -> Sums {
    for c in 0..6 {
        s.sse[c] = s.sse[c].max(s.n as f64 * floor[c]);
    }
    s
}

pub(crate) fn finish(p: &Problem, cur: &Current, after: &AfterSums, s: Scored, rules: &Rules) -> Candidate {
    let before = &cur.before;
    let train_before = before.train();
    let train_after = after.train;
    // τ of the residual before the candidate: one sample size for every candidate of a round
    // (the residual after would reward a candidate for leaving a rougher residual).
    let train_tau = before.train_tau;
    let test_before = before.test;
    let mut test_after = Sums::default();
    for i in p.test_fits() {
        test_after.add(&after.test[i]);
    }
    let test_tau = before.test_tau;
    let (train_before, train_after) = (floored(train_before, &p.floor), floored(train_after, &p.floor));
    let (test_before, test_after) = (floored(test_before, &p.floor), floored(test_after, &p.floor));
    let mean_n_eff = |n: usize, tau: &[f64; 6]| {
        s.scored.iter().map(|&c| n as f64 / tau[c]).sum::<f64>() / s.scored.len().max(1) as f64
    };
    let (train_n_eff, test_n_eff) = (
        mean_n_eff(train_after.n, &train_tau),
        mean_n_eff(test_after.n, &test_tau),
    );
    let delta_bic_train = delta_bic(&train_before, &train_after, &train_tau, &s.scored, s.k);
    let delta_bic_test = delta_bic(&test_before, &test_after, &test_tau, &s.scored, s.k);
    let red = reduction(&test_before, &test_after, &s.channels);
    // The same as a share of the base model's gap: what this candidate adds to the reduction.
    let base = floored(cur.base_test, &p.floor);
    let gained = reduction(&base, &test_after, &s.channels) - reduction(&base, &test_before, &s.channels);
    let z =
        s.z.unwrap_or_else(|| lr_z(&train_before, &train_after, &train_tau, &s.scored));
    let mut reasons = Vec::new();
    if s.params == Params::NotApplicable {
        reasons.push("not applicable: the data have no stale rows".to_string());
    } else {
        if delta_bic_test >= rules.max_delta_bic {
            reasons.push(format!(
                "held-out ΔBIC {delta_bic_test:.1} is not below {}",
                rules.max_delta_bic
            ));
        }
        if red < rules.min_reduction {
            reasons.push(format!(
                "held-out RMSE reduction {:.1} % is below {:.1} %",
                100.0 * red,
                100.0 * rules.min_reduction
            ));
        } else if gained < rules.min_reduction {
            reasons.push(format!(
                "held-out RMSE reduction {:.1} % of the base model's RMSE is below {:.1} %",
                100.0 * gained,
                100.0 * rules.min_reduction
            ));
        }
        reasons.extend(s.invalid.iter().cloned());
        if z.is_nan() || z <= rules.min_z {
            reasons.push(format!("z = {z:.2} is not above {}", rules.min_z));
        }
    }
    // The horizon rule, only for a candidate that passes the others (free runs cost time).
    let mut horizon_ratio = None;
    if reasons.is_empty() {
        let after = s.after_horizon.unwrap_or_else(|| horizon_errors(p, &s.after_state));
        horizon_ratio = cur.horizon.ratio(&after);
        reasons.extend(cur.horizon.objection(&after));
    }
    Candidate {
        kind: s.kind,
        channels: s.channels,
        params: s.params,
        install: s.install,
        train_before,
        train_after,
        test_before,
        test_after,
        train_n_eff,
        test_n_eff,
        k: s.k,
        z,
        delta_bic_train,
        delta_bic_test,
        reduction: red,
        reduction_of_base: gained,
        horizon_ratio,
        significant: reasons.is_empty(),
        reasons,
    }
}

/// The model `state` describes with the input transform `tr`: per fit, the (training, held-out)
/// sums of its residuals (each segment's sums added in turn), and, given `after`, the residuals
/// summed into it as [`finish`] scores them.
pub(crate) fn under(
    p: &Problem,
    state: &State,
    tr: &InputTransform,
    mut after: Option<&mut AfterSums>,
) -> Vec<(Sums, Sums)> {
    let segs = p.data.variant(state.destale);
    let role = roles(p, segs.len());
    let mut sums = vec![(Sums::default(), Sums::default()); p.fits.len()];
    for (s, seg) in segs.iter().enumerate() {
        if role.iter().all(|r| r[s] == Role::None) {
            continue;
        }
        let b = SegBase::under(seg, tr, || p.seen_f(seg, tr));
        let mut one = vec![Sums::default(); p.fits.len()];
        b.chunks(&p.ctx, &state.linear, CHUNK, |k0, d| {
            for (i, th) in state.theta.iter().enumerate() {
                if role[i][s] == Role::None {
                    continue;
                }
                let res = d.residual(&state.linear, th);
                one[i].push_masked(&res, &p.mask[s][k0..k0 + res.len()]);
                if let Some(a) = after.as_deref_mut() {
                    a.add(p, i, s, k0, &res);
                }
            }
        });
        for (i, one) in one.iter().enumerate() {
            match role[i][s] {
                Role::None => {}
                Role::Train => sums[i].0.add(one),
                Role::Test => sums[i].1.add(one),
            }
        }
    }
    sums
}

/// A fitted channel, for the report.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ChannelFit {
    pub input: usize,
    pub delay: f64,
    pub delay_sigma: Option<f64>,
    pub lag: f64,
    pub lag_sigma: Option<f64>,
    pub gain: f64,
    pub gain_sigma: f64,
    /// The delay the residual cross-correlation suggested (the scan's seed), s.
    pub seed: Option<f64>,
    pub z: f64,
    pub kept: bool,
    pub not_kept: Option<String>,
}

impl ChannelFit {
    /// d + τ: the response time the channel adds, s.
    pub fn added_time(&self) -> f64 {
        self.delay + self.lag
    }
}

/// A fitted loop, for the report.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LoopFit {
    pub l: usize,
    pub gain: f64,
    pub gain_sigma: f64,
    pub coupling: f64,
    pub coupling_sigma: f64,
    pub z: f64,
    pub kept: bool,
    pub not_kept: Option<String>,
}
