//! Self-check results: per case, the confusion matrix, the shrink per effect, Markdown.

use super::cases::{Case, Magnitude, EFFECTS};
use crate::diagnose::Diagnosis;
use serde::Serialize;
use std::collections::BTreeMap;

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
    /// Per true effect named: the held-out one-step RMSE reduction of its affected channels,
    /// 1 − √(mean MSE_after / MSE_before), from the round that named it.
    pub shrink: Vec<(String, f64)>,
    /// The same reduction of the gap over the noise floor: 1 − √(Σ (MSE_after − F) / Σ (MSE_before − F))
    /// with F the base model's held-out MSE on fresh nominal logs per channel (None without them).
    pub gap_shrink: Vec<(String, Option<f64>)>,
}

impl CaseResult {
    pub fn new(case: &Case, d: &Diagnosis, floor: Option<&BTreeMap<String, f64>>) -> Self {
        let truth = case.truth();
        let verdict = d.verdict.clone();
        let top1_correct = verdict.first().is_some_and(|v| truth.contains(v));
        let all_named = truth.iter().all(|t| verdict.contains(t));
        let shrink = d
            .effects
            .iter()
            .filter(|e| truth.contains(&e.name) && verdict.contains(&e.name))
            .map(|e| (e.name.clone(), e.heldout_reduction))
            .collect();
        let gap_shrink = d
            .effects
            .iter()
            .filter(|e| truth.contains(&e.name) && verdict.contains(&e.name))
            .map(|e| {
                let g = floor.and_then(|f| {
                    let (mut before, mut after) = (0.0, 0.0);
                    for (ch, b) in &e.heldout_rmse_before {
                        let a = e.heldout_rmse_after.get(ch)?;
                        let fl = f.get(ch)?;
                        before += (b * b - fl * fl).max(0.0);
                        after += (a * a - fl * fl).max(0.0);
                    }
                    (before > 0.0).then(|| 1.0 - (after / before).sqrt())
                });
                (e.name.clone(), g)
            })
            .collect();
        Self {
            case: case.name(),
            realistic: case.magnitude == Magnitude::Realistic,
            truth,
            verdict,
            top1_correct,
            all_named,
            shrink,
            gap_shrink,
        }
    }

    /// The named true effect shrinks the held-out one-step gap by at least half: the RMSE itself,
    /// or — where sensor noise sets a floor the model cannot go below — the gap over that floor.
    pub fn shrink_ok(&self) -> bool {
        !self.shrink.is_empty()
            && self
                .shrink
                .iter()
                .zip(&self.gap_shrink)
                .all(|((_, s), (_, g))| *s >= 0.5 || g.is_some_and(|g| g >= 0.5))
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
            "| case | must name | verdict | top-1 | all named | held-out one-step RMSE shrink | shrink of the gap over the noise floor | passes |\n|---|---|---|---|---|---|---|---|\n",
        );
        for r in &self.results {
            let shrink = if r.shrink.is_empty() {
                "—".to_string()
            } else {
                r.shrink
                    .iter()
                    .map(|(n, v)| format!("{n} {:.0} %", 100.0 * v))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let gap = if r.gap_shrink.is_empty() {
                "—".to_string()
            } else {
                r.gap_shrink
                    .iter()
                    .map(|(n, v)| match v {
                        Some(v) => format!("{n} {:.0} %", 100.0 * v),
                        None => format!("{n} —"),
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.case,
                r.truth.join(", "),
                r.verdict.join(", "),
                yes(r.top1_correct),
                yes(r.all_named),
                shrink,
                gap,
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
