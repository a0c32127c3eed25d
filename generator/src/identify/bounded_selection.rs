//! Sweep selection that keeps the model bounded over one MPC horizon.
//!
//! An information criterion picks each row's sparsity on the training data alone; it cannot see
//! that a term it keeps (say vz² in the roll row) explodes at inputs the logs never held. When the
//! selected model fails the [`horizon_check`](super::horizon_check), rows are moved greedily to
//! sparser sweep values: each round tries every row at every sparser sweep value (that changes its
//! support and leaves it non-empty) and keeps the move that leaves the fewest unbounded trials (ties: the smallest rise in that row's training RSS), until
//! the model passes, or every possible move leaves more trials unbounded, or no row can be made
//! sparser without emptying it (then the caller reports the failure). Every move removes terms, so
//! the search ends.

use super::horizon_check::{check, HorizonCheck, HorizonReport};
use super::sindy::SindyFit;
use crate::model::parse;

/// What [`select_bounded`] did.
#[derive(Clone, Debug)]
pub struct BoundedSelection {
    /// The check of the finally chosen rows.
    pub report: HorizonReport,
    /// Moves made: (row state, from sweep value, to sweep value).
    pub moves: Vec<(String, f64, f64)>,
}

fn run_check(fit: &SindyFit, options: &HorizonCheck) -> Option<HorizonReport> {
    let model = parse(&fit.to_json(), "identified model").ok()?;
    check(&model, options)
}

/// Make `fit`'s selection pass the horizon check by moving rows to sparser sweep values (see the
/// module docs). Returns `None` for models the check does not apply to. On return `fit` holds the
/// final selection; `report.passed()` says whether it passes.
pub fn select_bounded(fit: &mut SindyFit, options: &HorizonCheck) -> Option<BoundedSelection> {
    select_bounded_with(fit, &|f| run_check(f, options))
}

/// [`select_bounded`] with the check given as a function of the fit (e.g. the model with the
/// `corrections` it will be written with: `uavgen identify` checks the model it writes).
pub fn select_bounded_with(
    fit: &mut SindyFit,
    run_check: &dyn Fn(&SindyFit) -> Option<HorizonReport>,
) -> Option<BoundedSelection> {
    search(fit, run_check, false)
}

fn search(
    fit: &mut SindyFit,
    run_check: &dyn Fn(&SindyFit) -> Option<HorizonReport>,
    relaxed: bool,
) -> Option<BoundedSelection> {
    let mut report = run_check(fit)?;
    let mut moves = Vec::new();
    // Sweep indices in increasing sparsity-parameter order.
    let mut order: Vec<usize> = (0..fit.sweep.len()).collect();
    order.sort_by(|&a, &b| fit.sweep[a].value.total_cmp(&fit.sweep[b].value));
    while !report.passed() {
        let start = fit.chosen.clone();
        let mut best: Option<(usize, usize, f64, Vec<usize>, HorizonReport)> = None;
        for t in 0..start.len() {
            let pos = order.iter().position(|&j| j == start[t]).unwrap_or(0);
            let terms = fit.sweep[start[t]].rows[t].terms;
            // Every sparser sweep value that changes this row's support, but never to an empty
            // row (a row without terms is no model of that state).
            let mut seen = terms;
            for &next in &order[pos + 1..] {
                let k = fit.sweep[next].rows[t].terms;
                if k == 0 || k >= seen {
                    continue;
                }
                seen = k;
                let mut trial = start.clone();
                trial[t] = next;
                fit.choose(&trial);
                let Some(r) = run_check(fit) else { continue };
                let rise = fit.sweep[next].rows[t].rss - fit.sweep[start[t]].rows[t].rss;
                let better = match &best {
                    None => true,
                    Some((_, _, best_rise, _, b)) => {
                        r.unbounded < b.unbounded || (r.unbounded == b.unbounded && rise < *best_rise)
                    }
                };
                if better {
                    best = Some((t, next, rise, trial, r));
                }
            }
        }
        // A move must not leave more trials unbounded; every move removes terms, so this ends.
        let Some((t, next, _, trial, r)) = best.filter(|b| relaxed || b.4.unbounded <= report.unbounded) else {
            fit.choose(&start);
            break;
        };
        moves.push((fit.targets[t].clone(), fit.sweep[start[t]].value, fit.sweep[next].value));
        fit.choose(&trial);
        report = r;
    }
    Some(BoundedSelection { report, moves })
}
