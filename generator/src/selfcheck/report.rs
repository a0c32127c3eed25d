//! Self-check results: per case, the confusion matrix, the shrink per effect, Markdown.

use super::cases::{Case, Magnitude, EFFECTS};
use crate::diagnose::{Diagnosis, Side};
use crate::metrics::Metrics;
use serde::Serialize;

/// One case's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct CaseResult {
    pub case: String,
    pub realistic: bool,
    /// What must be named (`["none"]` for nominal logs).
    pub truth: Vec<String>,
    pub verdict: Vec<String>,
    /// The verdict's first name is a true one (nominal: the verdict is `none`).
    pub top1_correct: bool,
    /// Every true effect is in the verdict.
    pub all_named: bool,
    /// Per true effect named: the held-out one-step RMSE reduction of its affected channels on
    /// the logs as flown (with sensor noise), 1 − √(mean MSE_after / MSE_before), from the round
    /// that named it.
    pub shrink: Vec<(String, f64)>,
    /// The same reduction on the held-out flight logged without sensor noise, base model vs the
    /// model with every named effect (None when not measured).
    pub clean_shrink: Vec<(String, Option<f64>)>,
    /// The reduction of the gap the effect opened: on the noise-free logs, the part of each
    /// channel's MSE above the base model's MSE on the same flight flown without the effect (its
    /// own identification error, M₀), 1 − √(Σ_c max(0, MSE_after − M₀)/MSE_before ÷
    /// Σ_c max(0, MSE_before − M₀)/MSE_before). The acceptance figure (docs/diagnosis.md).
    pub effect_gap_shrink: Vec<(String, Option<f64>)>,
    /// The same over all six dynamic channels, the model with every named effect: what the
    /// verdict does for the whole gap, also in channels the named effects leave alone.
    pub effect_gap_shrink_all: Option<f64>,
}

fn mse(m: &Metrics, c: &str) -> Option<f64> {
    m.names.iter().position(|n| n == c).map(|i| m.rmse[i].powi(2))
}

/// 1 − √(mean_c MSE_after/MSE_before) over the `channels` of the one-step metrics.
fn reduction(before: &Metrics, after: &Metrics, channels: &[String]) -> Option<f64> {
    let ratios: Vec<f64> = channels
        .iter()
        .filter_map(|c| Some(mse(after, c)? / mse(before, c)?))
        .filter(|r| r.is_finite())
        .collect();
    (!ratios.is_empty()).then(|| 1.0 - (ratios.iter().sum::<f64>() / ratios.len() as f64).sqrt())
}

/// The effect-gap reduction (see [`CaseResult::effect_gap_shrink`]); `without` holds M₀.
fn gap_reduction(before: &Metrics, after: &Metrics, without: &Metrics, channels: &[String]) -> Option<f64> {
    let (mut opened, mut left) = (0.0, 0.0);
    for c in channels {
        let (b, a, m0) = (mse(before, c)?, mse(after, c)?, mse(without, c)?);
        if b > 0.0 {
            opened += (b - m0).max(0.0) / b;
            left += (a - m0).max(0.0) / b;
        }
    }
    (opened > 0.0).then(|| 1.0 - (left / opened).sqrt())
}

impl CaseResult {
    /// `without`: the base model on the noise-free held-out flight flown without the effect.
    pub fn new(case: &Case, d: &Diagnosis, without: Option<&Side>) -> Self {
        let truth = case.truth();
        let verdict = d.verdict.clone();
        let top1_correct = verdict.first().is_some_and(|v| truth.contains(v));
        let all_named = truth.iter().all(|t| verdict.contains(t));
        let named = || {
            d.effects
                .iter()
                .filter(|e| truth.contains(&e.name) && verdict.contains(&e.name))
        };
        let shrink = named().map(|e| (e.name.clone(), e.heldout_reduction)).collect();
        let clean = d
            .reference
            .as_ref()
            .and_then(|r| Some((r.before.one_step.as_ref()?, r.after.one_step.as_ref()?)));
        let clean_shrink = named()
            .map(|e| (e.name.clone(), clean.and_then(|(b, a)| reduction(b, a, &e.channels))))
            .collect();
        let m0 = without.and_then(|w| w.one_step.as_ref());
        let effect_gap_shrink = named()
            .map(|e| {
                let g = clean
                    .zip(m0)
                    .and_then(|((b, a), m0)| gap_reduction(b, a, m0, &e.channels));
                (e.name.clone(), g)
            })
            .collect();
        let all: Vec<String> = crate::diagnose::catalogue::CHANNELS
            .iter()
            .map(|c| c.to_string())
            .collect();
        let effect_gap_shrink_all = (!case.effects.is_empty())
            .then(|| clean.zip(m0).and_then(|((b, a), m0)| gap_reduction(b, a, m0, &all)))
            .flatten();
        Self {
            case: case.name(),
            realistic: case.magnitude == Magnitude::Realistic,
            truth,
            verdict,
            top1_correct,
            all_named,
            shrink,
            clean_shrink,
            effect_gap_shrink,
            effect_gap_shrink_all,
        }
    }

    /// Every named true effect shrinks the held-out one-step gap it opened in its channels by at
    /// least half ([`CaseResult::effect_gap_shrink`]).
    pub fn shrink_ok(&self) -> bool {
        !self.effect_gap_shrink.is_empty() && self.effect_gap_shrink.iter().all(|(_, g)| g.is_some_and(|g| g >= 0.5))
    }

    /// The acceptance of a case: realistic single effects need top-1 and a shrink ≥ 50 %; pairs
    /// need both named; nominal needs `none`; small magnitudes are reported, not required.
    pub fn passes(&self) -> bool {
        if !self.realistic {
            return true;
        }
        match self.truth.len() {
            1 if self.truth[0] == "none" => self.verdict == ["none"],
            1 => self.top1_correct && self.shrink_ok(),
            _ => self.all_named,
        }
    }
}

/// The whole self-check.
#[derive(Clone, Debug, Serialize)]
pub struct SelfCheck {
    pub base_model_terms: usize,
    pub results: Vec<CaseResult>,
}

impl SelfCheck {
    pub fn passed(&self) -> bool {
        self.results.iter().all(CaseResult::passes)
    }

    /// Rows: the true effect of single-effect cases (and nominal); columns: the verdict's first name.
    pub fn confusion_matrix(&self, realistic: bool) -> String {
        let mut names: Vec<&str> = EFFECTS.iter().map(|(_, c)| *c).collect();
        names.push("none");
        let mut s = format!("| true \\ named first | {} | other |\n|---|", names.join(" | "));
        s += &"---:|".repeat(names.len() + 1);
        s.push('\n');
        for t in &names {
            let rows: Vec<&CaseResult> = self
                .results
                .iter()
                .filter(|r| r.realistic == realistic && r.truth.len() == 1 && r.truth[0] == *t)
                .collect();
            if rows.is_empty() {
                continue;
            }
            let count = |n: &str| {
                rows.iter()
                    .filter(|r| r.verdict.first().map(String::as_str) == Some(n))
                    .count()
            };
            let other = rows
                .iter()
                .filter(|r| !r.verdict.first().is_some_and(|v| names.contains(&v.as_str())))
                .count();
            let cells: Vec<String> = names
                .iter()
                .map(|n| match count(n) {
                    0 => "·".to_string(),
                    c => c.to_string(),
                })
                .collect();
            s += &format!(
                "| {t} | {} | {} |\n",
                cells.join(" | "),
                if other == 0 { "·".into() } else { other.to_string() }
            );
        }
        s
    }

    /// The report as Markdown: per case, then the confusion matrices.
    pub fn markdown(&self) -> String {
        let mut s = String::from(
            "| case | must name | verdict | top-1 | all named | one-step RMSE shrink, held-out logs | the same, noise-free | shrink of the gap the effect opened | the same, all six channels | passes |\n|---|---|---|---|---|---|---|---|---|---|\n",
        );
        let list = |v: &[(String, Option<f64>)]| {
            if v.is_empty() {
                return "—".to_string();
            }
            v.iter()
                .map(|(n, v)| match v {
                    Some(v) => format!("{n} {:.0} %", 100.0 * v),
                    None => format!("{n} —"),
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        for r in &self.results {
            let shrink: Vec<(String, Option<f64>)> = r.shrink.iter().map(|(n, v)| (n.clone(), Some(*v))).collect();
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.case,
                r.truth.join(", "),
                r.verdict.join(", "),
                yes(r.top1_correct),
                yes(r.all_named),
                list(&shrink),
                list(&r.clean_shrink),
                list(&r.effect_gap_shrink),
                match r.effect_gap_shrink_all {
                    Some(v) => format!("{:.0} %", 100.0 * v),
                    None => "—".to_string(),
                },
                if r.realistic { yes(r.passes()) } else { "(not required)" }
            );
        }
        s += "\nConfusion matrix, single effects at realistic magnitude (and nominal logs):\n\n";
        s += &self.confusion_matrix(true);
        s += "\nConfusion matrix, single effects at small magnitude:\n\n";
        s += &self.confusion_matrix(false);
        s
    }
}

fn yes(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}
