//! Delays refined over the horizon: the second stage of `identify --input-delay auto`
//! (docs/identification.md, "Delays refined over the horizon").
//!
//! The one-step scan of [`super::response`] scores each delay by how well the driven row's
//! derivative is predicted one sample ahead. On attitude channels that answer is short: with the
//! attitude and its rate in the library, a regression can mimic part of a pure delay by its
//! damping terms (uₖ₋ₙ ≈ uₖ − n Δt u̇ₖ), and noise on the rates weighs the one-step error towards
//! no delay. On m100_like flights it put u_roll at 0–0.05 s and u_pitch at 0.058 s against the
//! plant's 0.076 / 0.090 s. What the MPC needs is the model that predicts best over its horizon,
//! so here each channel's delay is chosen by the *whole identified model's* free runs:
//!
//! - the logs are split twice ([`split_logs`]): every segment's first [`RefineOptions::train_share`]
//!   fitted and the rest held out, and its last share fitted and the first part held out;
//! - per channel (in LOG_FORMAT.md order, once; not a channel in [`RefineOptions::fixed`], e.g.
//!   one that carries no signal), the candidates are the one-step delay d₁ and d₁ + k `step`
//!   for k = −`below` … `above` (within 0 … `max_delay`, less the top sample period: a delay at
//!   the scan's edge is refused, as in the one-step scan), its lag kept; each candidate
//!   is scored by the caller: per split, the model refitted on the training part with that
//!   response and its held-out free runs over one MPC horizon (overall RMSE, [`crate::evaluate`]'s
//!   figure) relative to the one-step response's; the score is the worse split's ratio, so a
//!   delay must predict better on both held-out ends. On the real M100 logs a single split was
//!   not enough: there every change of delay also changes the sparsity the fit selects, and a
//!   u_vz delay of 0.105 s that scored 13 % better on the logs' last fifth made run 7 twice as
//!   bad (docs/identification.md);
//! - the best candidate replaces the current delay only when it improves the score by at least
//!   `min_gain` (relative): without clear evidence the one-step answer stays. A best candidate at
//!   an edge of the grid is followed on in `step`s while the score keeps improving. With
//!   [`RefineOptions::confirm`] the candidates' scores are a cheaper screen (SINDy refits only
//!   the rows the channel drives) and the best one, when it screens at least half of `min_gain`
//!   better, is scored again by the full refit, whose score decides.
//!
//! The search is generic over the score so that it is tested on its own (a hand-made score
//! surface) and the CLI supplies the fit (SINDy or PD) it is identifying.

use super::response::{at_edge, InputResponse, INPUTS};
use crate::logs::{FlightLog, Segment};

/// The search's grid and rule (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct RefineOptions {
    /// The grid's step, s.
    pub step: f64,
    /// Steps below the one-step delay.
    pub below: usize,
    /// Steps above it.
    pub above: usize,
    /// Largest delay scanned, s (the one-step scan's range); candidates within one sample period
    /// of it are at the edge and not tried.
    pub max_delay: f64,
    /// Relative improvement of the held-out score a new delay must bring.
    pub min_gain: f64,
    /// Share of every segment fitted; the rest is held out.
    pub train_share: f64,
    /// Duration each part of a split segment needs, s (else the segment is fitted whole).
    pub min_part: f64,
    /// Channels left at their one-step delay (no evidence to refine them: silent channels).
    pub fixed: [bool; 4],
    /// The candidates' scores are a cheaper screen (SINDy: only the driven rows refitted): a
    /// channel's [`CONFIRMED`] best candidates that screen at least half of `min_gain` better are
    /// scored again by the full refit, and those scores decide.
    pub confirm: bool,
}

impl Default for RefineOptions {
    /// Steps of 1/60 s (half a sample at 30 Hz), 1/30 s below to 1/15 s above, 0 … 0.5 s, a 5 %
    /// gain, 80 % fitted, parts of at least 3 s (three horizons), every channel refined.
    fn default() -> Self {
        Self {
            step: 1.0 / 60.0,
            below: 2,
            above: 4,
            max_delay: 0.5,
            min_gain: 0.05,
            train_share: 0.8,
            min_part: 3.0,
            fixed: [false; 4],
            confirm: false,
        }
    }
}

impl RefineOptions {
    /// [`Self::min_part`] in rows of period `dt`.
    pub fn min_rows(&self, dt: f64) -> usize {
        super::response::samples(self.min_part, dt)
    }
}

/// The spacing of the held-out free runs' starts the candidates are scored on, s: one run from
/// every sample up to 20 Hz, every ⌊0.05 s / Δt⌋-th sample above (runs that start a few
/// milliseconds apart are nearly the same run; at 100 Hz this scores a fifth of them, at 30 Hz
/// every one).
pub const SCORE_SPACING_S: f64 = 0.05;

/// The stride between scored free runs at sample period `dt` (at least 1; see [`SCORE_SPACING_S`]).
pub fn score_stride(dt: f64) -> usize {
    if dt.is_finite() && dt > 0.0 {
        ((SCORE_SPACING_S / dt + 1e-9).floor() as usize).max(1)
    } else {
        1
    }
}

/// What the search did on one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelRefinement {
    pub input: &'static str,
    /// The delay it started from (the one-step scan's).
    pub one_step: f64,
    /// The delay chosen.
    pub delay: f64,
    /// Every candidate's held-out score (s, score); ∞ where the fit or every free run failed.
    pub scores: Vec<(f64, f64)>,
    /// The candidates scored again by the full refit (s, score), when screened scores are
    /// confirmed ([`RefineOptions::confirm`]).
    pub confirmed: Vec<(f64, f64)>,
}

/// Screened candidates confirmed per channel at most (the best screens first): two, because
/// the screen can rank neighbours the other way round (the bed's M100-class `hold` flight:
/// u_pitch 0.067 s screened 0.8904, 0.100 s 0.8992; the full refit 0.8959 and 0.8719).
pub const CONFIRMED: usize = 2;

/// The refined response and the held-out score before and after.
#[derive(Clone, Debug, PartialEq)]
pub struct Refinement {
    pub response: InputResponse,
    /// Held-out score of the one-step response and of the refined one.
    pub before: f64,
    pub after: f64,
    pub channels: Vec<ChannelRefinement>,
}

/// The candidate delays of one channel around `d1` (sorted, distinct, within 0 … max_delay, none
/// at the edge: within the sample period `dt` of max_delay).
pub fn candidates(d1: f64, dt: f64, options: &RefineOptions) -> Vec<f64> {
    // Below 0 the grid is clipped to 0 (kept once by the dedup).
    let mut out: Vec<f64> = (-(options.below as i64)..=options.above as i64)
        .map(|k| (d1 + k as f64 * options.step).max(0.0))
        .filter(|d| *d <= options.max_delay + 1e-12 && !at_edge(*d, options.max_delay, dt))
        .collect();
    out.sort_by(f64::total_cmp);
    out.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    out
}

/// Refine every channel's delay of `start` (see the module documentation); `score(r, full)`
/// returns the held-out score of a response (lower is better), `None` when it cannot be scored;
/// `full` asks for the full refit (the start, and with [`RefineOptions::confirm`] the
/// confirmations), else the candidate may be screened. `None` when `start` itself cannot be
/// scored: there is nothing to compare with.
pub fn refine(
    start: &InputResponse,
    dt: f64,
    options: &RefineOptions,
    score: &mut dyn FnMut(&InputResponse, bool) -> Option<f64>,
) -> Option<Refinement> {
    let before = score(start, true).filter(|s| s.is_finite())?;
    let (mut current, mut best) = (*start, before);
    let mut channels = Vec::with_capacity(4);
    for (j, input) in INPUTS.iter().enumerate() {
        let d1 = current.delay[j];
        if options.fixed[j] {
            channels.push(ChannelRefinement {
                input,
                one_step: d1,
                delay: d1,
                scores: Vec::new(),
                confirmed: Vec::new(),
            });
            continue;
        }
        let mut scores = Vec::new();
        let mut choice = (d1, best);
        let mut try_delay = |d: f64| {
            let s = if (d - d1).abs() < 1e-12 {
                best
            } else {
                let mut r = current;
                r.delay[j] = d;
                score(&r, false).filter(|s| s.is_finite()).unwrap_or(f64::INFINITY)
            };
            scores.push((d, s));
            s
        };
        let grid = candidates(d1, dt, options);
        for &d in &grid {
            let s = try_delay(d);
            if s < choice.1 {
                choice = (d, s);
            }
        }
        // The best at an edge of the grid: walk on in half samples while the score improves.
        for (edge, step) in [(grid.first(), -options.step), (grid.last(), options.step)] {
            if edge.map_or(true, |e| (e - choice.0).abs() > 1e-12) {
                continue;
            }
            loop {
                let d = choice.0 + step;
                if d < -1e-12 || d > options.max_delay + 1e-12 || at_edge(d, options.max_delay, dt) {
                    break;
                }
                let s = try_delay(d.max(0.0));
                if s >= choice.1 {
                    break;
                }
                choice = (d.max(0.0), s);
            }
        }
        let mut confirmed = Vec::new();
        if options.confirm {
            let mut screened: Vec<(f64, f64)> = scores
                .iter()
                .copied()
                .filter(|(d, s)| (d - d1).abs() > 1e-12 && *s < best * (1.0 - 0.5 * options.min_gain))
                .collect();
            screened.sort_by(|a, b| a.1.total_cmp(&b.1));
            choice = (d1, best);
            for &(d, _) in screened.iter().take(CONFIRMED) {
                let mut r = current;
                r.delay[j] = d;
                let s = score(&r, true).filter(|s| s.is_finite()).unwrap_or(f64::INFINITY);
                confirmed.push((d, s));
                if s < choice.1 {
                    choice = (d, s);
                }
            }
        }
        if choice.1 < best * (1.0 - options.min_gain) {
            current.delay[j] = choice.0;
            best = choice.1;
        }
        channels.push(ChannelRefinement {
            input,
            one_step: d1,
            delay: current.delay[j],
            scores,
            confirmed,
        });
    }
    Some(Refinement {
        response: current,
        before,
        after: best,
        channels,
    })
}

/// Which end of every segment is held out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeldOut {
    /// The last 1 − `train_share` of every segment.
    Tail,
    /// The first 1 − `train_share`.
    Head,
}

/// The logs split in time: every segment's `train_share` fitted and the rest (at its `end`) held
/// out, each part at least `min_rows` rows (else the whole segment is fitted). The held-out list
/// is empty when no segment is long enough.
pub fn split_logs(
    logs: &[FlightLog],
    train_share: f64,
    min_rows: usize,
    end: HeldOut,
) -> (Vec<FlightLog>, Vec<FlightLog>) {
    let mut train = Vec::with_capacity(logs.len());
    let mut test = Vec::new();
    for log in logs {
        let (mut fit, mut held) = (Vec::new(), Vec::new());
        for seg in &log.segments {
            let n = seg.len();
            let fitted = ((n as f64) * train_share).round() as usize;
            if fitted < min_rows || n.saturating_sub(fitted) < min_rows {
                fit.push(seg.clone());
                continue;
            }
            match end {
                HeldOut::Tail => {
                    fit.push(slice(seg, 0, fitted));
                    held.push(slice(seg, fitted, n));
                }
                HeldOut::Head => {
                    held.push(slice(seg, 0, n - fitted));
                    fit.push(slice(seg, n - fitted, n));
                }
            }
        }
        train.push(FlightLog {
            segments: fit,
            ..log.clone()
        });
        if !held.is_empty() {
            test.push(FlightLog {
                segments: held,
                ..log.clone()
            });
        }
    }
    (train, test)
}

/// The log time the refinement works on at most, s: longer logs are refined on evenly spread
/// excerpts of this much ([`excerpt_logs`]). The refinement estimates four delays; its cost is a
/// refit and held-out free runs per candidate, proportional to the log. Five minutes of log
/// (the benchmark's n5, the M100 runs 1–5) are used whole.
pub const MAX_REFINE_S: f64 = 360.0;

/// The length of one excerpt, s (long enough to split 80/20 into parts of three horizons).
pub const EXCERPT_S: f64 = 60.0;

/// `logs` cut to at most `max_s` seconds in total (rows × each segment's median period): the logs
/// themselves when they are not longer; else every segment keeps its share (its length × the
/// ratio, at least one row) in pieces of at most `excerpt_s`, evenly spread over it, each piece
/// a segment of its own (the logs stay separate logs). Deterministic.
pub fn excerpt_logs(logs: &[FlightLog], max_s: f64, excerpt_s: f64) -> Vec<FlightLog> {
    let period = |seg: &Segment| -> f64 {
        let steps: Vec<f64> = seg.t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        crate::logs::median(&steps).unwrap_or(0.0)
    };
    let total: f64 = logs
        .iter()
        .flat_map(|l| &l.segments)
        .map(|seg| seg.len() as f64 * period(seg))
        .sum();
    let longer = total > max_s && max_s > 0.0;
    if !longer {
        return logs.to_vec();
    }
    let ratio = max_s / total;
    logs.iter()
        .map(|log| {
            let mut segments = Vec::new();
            for seg in &log.segments {
                let n = seg.len();
                let dt = period(seg);
                let keep = ((n as f64 * ratio).round() as usize).clamp(1, n);
                let piece = if dt > 0.0 {
                    ((excerpt_s / dt).round() as usize).max(1)
                } else {
                    keep
                };
                let pieces = keep.div_ceil(piece).max(1);
                let len = keep / pieces;
                // Piece i centred at (i + ½) n / pieces.
                for i in 0..pieces {
                    let centre = ((2 * i + 1) * n) / (2 * pieces);
                    let a = centre.saturating_sub(len / 2).min(n - len);
                    let mut part = slice(seg, a, a + len);
                    part.index = segments.len();
                    segments.push(part);
                }
            }
            FlightLog {
                segments,
                ..log.clone()
            }
        })
        .collect()
}

fn slice(seg: &Segment, a: usize, b: usize) -> Segment {
    Segment {
        index: seg.index,
        t: seg.t[a..b].to_vec(),
        x: seg.x[a..b].to_vec(),
        u: seg.u[a..b].to_vec(),
        battery_voltage: seg.battery_voltage.as_ref().map(|v| v[a..b].to_vec()),
        first_line: seg.first_line + a,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_of(segments: &[(usize, f64)]) -> FlightLog {
        let segments: Vec<Segment> = segments
            .iter()
            .enumerate()
            .map(|(index, &(n, dt))| Segment {
                index,
                t: (0..n).map(|k| 100.0 * index as f64 + k as f64 * dt).collect(),
                x: (0..n).map(|k| [k as f64; 12]).collect(),
                u: vec![[0.0; 4]; n],
                battery_voltage: None,
                first_line: 2,
            })
            .collect();
        FlightLog {
            source: "a.csv".into(),
            metadata: Vec::new(),
            segments,
            report: crate::logs::QualityReport {
                source: "a.csv".into(),
                rows: 0,
                metadata_rate_hz: None,
                measured_period: None,
                nominal_period: None,
                segments: Vec::new(),
            },
        }
    }

    /// Logs within the cap are used whole; longer ones keep every segment's share in evenly
    /// spread pieces of at most the excerpt's length, each its own segment, taken from the
    /// original rows.
    #[test]
    fn long_logs_are_refined_on_evenly_spread_excerpts() {
        let short = vec![log_of(&[(15000, 0.01), (15000, 0.01)])];
        let same = excerpt_logs(&short, MAX_REFINE_S, EXCERPT_S);
        assert_eq!(same[0].segments.len(), 2);
        assert_eq!(same[0].segments[1].x, short[0].segments[1].x);
        // 1 h at 100 Hz and 20 min at 50 Hz: 4800 s cut to 360 s (7.5 %).
        let long = vec![log_of(&[(360_000, 0.01)]), log_of(&[(60_000, 0.02)])];
        let cut = excerpt_logs(&long, MAX_REFINE_S, EXCERPT_S);
        assert_eq!(cut.len(), 2);
        let rows = |l: &FlightLog| l.segments.iter().map(|s| s.len()).sum::<usize>();
        assert_eq!(rows(&cut[0]), 27_000); // 270 s: 5 pieces of 54 s
        assert_eq!(cut[0].segments.len(), 5);
        assert_eq!(rows(&cut[1]), 4_500); // 90 s: 2 pieces of 45 s
        let total: f64 = rows(&cut[0]) as f64 * 0.01 + rows(&cut[1]) as f64 * 0.02;
        assert!((total - MAX_REFINE_S).abs() < 1.0, "{total}");
        for (i, seg) in cut[0].segments.iter().enumerate() {
            assert_eq!(seg.index, i);
            // Evenly spread: piece i is centred at (i + ½) / 5 of the log, rows as logged.
            let first = seg.x[0][0] as usize;
            let centre = first + seg.len() / 2;
            assert!(
                (centre as f64 - (i as f64 + 0.5) * 72_000.0).abs() <= 1.0,
                "{i}: {centre}"
            );
            assert!(seg.x.iter().enumerate().all(|(k, x)| x[0] as usize == first + k));
            assert_eq!(seg.first_line, 2 + first);
        }
    }

    #[test]
    fn scored_runs_start_every_five_hundredths_of_a_second() {
        assert_eq!(score_stride(1.0 / 30.0), 1);
        assert_eq!(score_stride(1.0 / 20.0), 1);
        assert_eq!(score_stride(1.0 / 50.0), 2);
        assert_eq!(score_stride(0.01), 5);
        assert_eq!(score_stride(1.0 / 1000.0), 50);
        assert_eq!(score_stride(0.0), 1);
        assert_eq!(score_stride(f64::NAN), 1);
    }

    const DT: f64 = 1.0 / 30.0;

    #[test]
    fn candidates_are_half_samples_around_the_one_step_delay() {
        let o = RefineOptions::default();
        let c = candidates(0.05, DT, &o);
        let want = [
            0.05 - DT,
            0.05 - DT / 2.0,
            0.05,
            0.05 + DT / 2.0,
            0.05 + DT,
            0.05 + 1.5 * DT,
            0.05 + 2.0 * DT,
        ];
        assert_eq!(c.len(), want.len(), "{c:?}");
        for (a, b) in c.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{c:?}");
        }
        // From 0: nothing below; near the top: nothing above 0.5 s.
        let c = candidates(0.0, DT, &o);
        assert_eq!(c.len(), 5);
        assert_eq!(c[0], 0.0);
        let c = candidates(0.49, DT, &o);
        assert!(c.iter().all(|d| *d <= 0.5 + 1e-12), "{c:?}");
        // Below 0 is clipped to 0, once.
        let c = candidates(DT / 2.0, DT, &o);
        assert_eq!(c[0], 0.0);
        assert_eq!(c.iter().filter(|d| **d == 0.0).count(), 1, "{c:?}");
    }

    /// A score with its minimum at `truth` per channel (a bowl in the delays): the search moves
    /// each channel to the grid point nearest its truth within reach, and leaves alone a channel
    /// whose best candidate gains less than `min_gain`.
    #[test]
    fn the_search_finds_the_bowls_minimum_and_keeps_small_gains_out() {
        let truth = [0.127, 0.076, 0.09, 0.05];
        let start = InputResponse {
            delay: [0.117, 0.0, 0.058, 0.05],
            lag: [None; 4],
        };
        let mut calls = 0;
        let mut score = |r: &InputResponse, _: bool| {
            calls += 1;
            Some(
                1.0 + r
                    .delay
                    .iter()
                    .zip(truth)
                    .map(|(d, t)| 100.0 * (d - t).powi(2))
                    .sum::<f64>(),
            )
        };
        let o = RefineOptions::default();
        let r = refine(&start, DT, &o, &mut score).unwrap();
        // u_roll from 0: its grid ends 2 samples up (0.0667) still improving, so the search walks
        // on to 2.5 samples (0.0833, the half sample nearest 0.076) and stops at 3 (worse).
        assert!((r.response.delay[1] - 2.5 * DT).abs() < 1e-12, "{:?}", r.response);
        assert_eq!(r.channels[1].scores.len(), 5 + 2);
        // u_pitch: 0.058 + Δt = 0.0917, the grid point nearest 0.09.
        assert!((r.response.delay[2] - (0.058 + DT)).abs() < 1e-12, "{:?}", r.response);
        // u_vz: 0.117 + Δt/2 = 0.1337 is nearer 0.127, but the gain (0.0055 of a score of ≈ 1.69)
        // is below 1 %: kept. u_yaw_rate is at its truth: kept.
        assert_eq!(r.response.delay[0], 0.117);
        assert_eq!(r.response.delay[3], 0.05);
        assert!(r.after < r.before);
        assert_eq!(r.channels.len(), 4);
        assert_eq!(r.channels[1].one_step, 0.0);
        // One call for the start, then each channel's candidates but its current one.
        let expected: usize = 1
            + [0.117, 0.0, 0.058, 0.05]
                .iter()
                .map(|d| candidates(*d, DT, &o).len() - 1)
                .sum::<usize>()
            + 2;
        assert_eq!(calls, expected);
    }

    /// With `confirm`, a channel's best screened candidates (two at most, each at least half of
    /// `min_gain` better) are scored again by the full refit, and those scores decide: a screen
    /// that overstates a gain moves nothing, one that ranks two candidates the wrong way round
    /// moves to the better by the full refit, a screen gain below half of `min_gain` is not
    /// confirmed.
    #[test]
    fn screened_candidates_are_confirmed_by_the_full_score() {
        let start = InputResponse::default();
        let o = RefineOptions {
            confirm: true,
            ..RefineOptions::default()
        };
        let on = |r: &InputResponse, j: usize, k: f64| (r.delay[j] - k * o.step).abs() < 1e-9;
        // Full score: u_vz two steps up 8 % better, one step 2 %; the screen ranks them the other
        // way (4 % at one step, 3 % at two: both confirmed, two steps moved). It invents 10 % on
        // u_roll at one step (confirmed: not moved) and 2 % on u_pitch (below half of 5 %).
        let mut full_calls = Vec::new();
        let mut score = |r: &InputResponse, full: bool| {
            let f = |j: usize, k: f64| if on(r, j, k) { 1.0 } else { 0.0 };
            if full {
                full_calls.push(*r);
                return Some(1.0 - 0.08 * f(0, 2.0) - 0.02 * f(0, 1.0));
            }
            Some(1.0 - 0.04 * f(0, 1.0) - 0.03 * f(0, 2.0) - 0.1 * f(1, 1.0) - 0.02 * f(2, 1.0))
        };
        let r = refine(&start, DT, &o, &mut score).unwrap();
        assert!((r.response.delay[0] - 2.0 * o.step).abs() < 1e-12, "{:?}", r.response);
        assert_eq!(r.response.delay[1..], [0.0; 3]);
        assert_eq!(r.channels[0].confirmed.len(), 2);
        assert!((r.channels[0].confirmed[0].1 - 0.98).abs() < 1e-12);
        assert!((r.channels[0].confirmed[1].1 - 0.92).abs() < 1e-12);
        assert_eq!(r.channels[1].confirmed.len(), 1);
        assert!((r.channels[1].confirmed[0].1 - 0.92).abs() < 1e-12);
        assert!(r.channels[2].confirmed.is_empty());
        // The start and three confirmations.
        assert_eq!(full_calls.len(), 4);
        assert!((r.after - 0.92).abs() < 1e-12);
    }

    #[test]
    fn an_unscorable_start_is_none_and_unscorable_candidates_lose() {
        let start = InputResponse::default();
        assert!(refine(&start, DT, &RefineOptions::default(), &mut |_, _| None).is_none());
        // Every candidate but the start fails: nothing moves.
        let r = refine(&start, DT, &RefineOptions::default(), &mut |r, _| {
            (r.delay == [0.0; 4]).then_some(2.0)
        })
        .unwrap();
        assert_eq!(r.response, start);
        assert_eq!(r.before, r.after);
        assert!(r
            .channels
            .iter()
            .all(|c| c.scores.iter().skip(1).all(|s| s.1.is_infinite())));
    }

    /// The scan's edge (the top sample period of 0 … max_delay) is never tried, even when the
    /// score keeps improving towards it; a fixed (silent) channel keeps its delay untried.
    #[test]
    fn the_edge_of_the_scan_is_refused_and_fixed_channels_stay() {
        let o = RefineOptions::default();
        let c = candidates(0.45, DT, &o);
        assert!(!c.is_empty() && c.iter().all(|d| *d < 0.5 - DT + 1e-9), "{c:?}");
        let start = InputResponse {
            delay: [0.4, 0.0, 0.0, 0.0],
            lag: [None; 4],
        };
        let mut score = |r: &InputResponse, _: bool| {
            Some(1.0 + 100.0 * (r.delay[0] - 0.7).powi(2) + 100.0 * (r.delay[3] - 0.1).powi(2))
        };
        let fixed = RefineOptions {
            fixed: [false, false, false, true],
            ..o
        };
        let r = refine(&start, DT, &fixed, &mut score).unwrap();
        assert!(
            r.response.delay[0] > 0.4 && r.response.delay[0] < 0.5 - DT + 1e-9,
            "{:?}",
            r.response
        );
        assert!(r.channels[0].scores.iter().all(|(d, _)| *d < 0.5 - DT + 1e-9));
        assert_eq!(r.response.delay[3], 0.0);
        assert!(r.channels[3].scores.is_empty());
        assert_eq!(RefineOptions::default().min_rows(DT), 90);
        assert_eq!(RefineOptions::default().min_rows(0.01), 300);
    }

    #[test]
    fn split_logs_cuts_every_long_segment_at_the_share() {
        let seg = |n: usize| Segment {
            index: 0,
            t: (0..n).map(|i| i as f64 * DT).collect(),
            x: vec![[0.0; 12]; n],
            u: vec![[0.0; 4]; n],
            battery_voltage: None,
            first_line: 2,
        };
        let log = FlightLog {
            source: "a.csv".into(),
            metadata: Vec::new(),
            segments: vec![seg(1000), seg(50)],
            report: crate::logs::QualityReport {
                source: "a.csv".into(),
                rows: 1050,
                metadata_rate_hz: None,
                measured_period: None,
                nominal_period: None,
                segments: Vec::new(),
            },
        };
        let (head_train, head_test) = split_logs(std::slice::from_ref(&log), 0.8, 100, HeldOut::Head);
        assert_eq!(head_test[0].segments[0].len(), 200);
        assert_eq!(head_train[0].segments[0].first_line, 202);
        assert_eq!(head_train[0].segments[0].len(), 800);
        let (train, test) = split_logs(&[log], 0.8, 100, HeldOut::Tail);
        assert_eq!(train[0].segments.len(), 2);
        assert_eq!(train[0].segments[0].len(), 800);
        assert_eq!(train[0].segments[1].len(), 50);
        assert_eq!(test.len(), 1);
        assert_eq!(test[0].segments.len(), 1);
        assert_eq!(test[0].segments[0].len(), 200);
        assert_eq!(test[0].segments[0].first_line, 802);
        assert!((test[0].segments[0].t[0] - 800.0 * DT).abs() < 1e-12);
        // Too short everywhere: nothing held out.
        let (_, test) = split_logs(&train[0..1], 0.8, 1000, HeldOut::Tail);
        assert!(test.is_empty());
    }
}
