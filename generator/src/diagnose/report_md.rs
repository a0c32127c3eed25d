//! report.md: the diagnosis for a reader — verdict, where, which effect, how far it shrinks, the
//! corrected model, notes and the plots.

use super::{Diagnosis, EffectReport, LogSummary};
use serde_json::Value;
use std::fmt::Write;

/// `v` with 4 significant digits (scientific outside 1e-3 … 1e5).
fn num(v: f64) -> String {
    if !v.is_finite() {
        return "—".to_string();
    }
    if v == 0.0 {
        return "0".to_string();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.3e}");
    }
    let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

fn opt(v: Option<f64>) -> String {
    v.map_or("—".to_string(), num)
}

/// A parameter value (number, array or object of numbers) in words.
fn value(v: &Value) -> String {
    match v {
        Value::Number(n) if n.is_u64() || n.is_i64() => n.to_string(),
        Value::Number(n) => n.as_f64().map_or(n.to_string(), num),
        Value::Null => "—".to_string(),
        Value::Object(o) if o.is_empty() => "—".to_string(),
        Value::Array(a) => format!("[{}]", a.iter().map(value).collect::<Vec<_>>().join(", ")),
        Value::Object(o) => o
            .iter()
            .map(|(k, v)| format!("{k} {}", value(v)))
            .collect::<Vec<_>>()
            .join(", "),
        other => other.to_string(),
    }
}

fn logs_line(logs: &[LogSummary]) -> String {
    logs.iter()
        .map(|l| {
            format!(
                "`{}` ({} rows, {} segment{}, {} stale rows, {} samples)",
                l.source,
                l.rows,
                l.segments,
                if l.segments == 1 { "" } else { "s" },
                l.stale_rows,
                l.samples
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn rmse_change(e: &EffectReport) -> String {
    e.heldout_rmse_before
        .iter()
        .map(|(c, b)| {
            let a = e.heldout_rmse_after.get(c).copied().unwrap_or(f64::NAN);
            format!("{c} {} → {}", num(*b), num(a))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

pub(crate) fn markdown(d: &Diagnosis, plots: &[String]) -> String {
    let mut s = String::new();
    header(&mut s, d);
    where_section(&mut s, d);
    which_section(&mut s, d);
    responses_section(&mut s, d);
    shrink_section(&mut s, d);
    corrected_section(&mut s, d, plots);
    s
}

/// Title, verdict (and the closed-loop warning), the model and the data.
fn header(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "# Diagnosis of `{}` ({})\n", d.model.name, d.model.kind);
    let verdict = if d.verdict == ["none"] {
        "**none** — no catalogued effect explains the gap between the model and the data significantly".to_string()
    } else {
        d.verdict
            .iter()
            .map(|v| format!("**{v}**"))
            .collect::<Vec<_>>()
            .join(" + ")
    };
    let _ = writeln!(s, "Verdict: {verdict}.\n");
    if !d.warnings.is_empty() {
        let _ = writeln!(
            s,
            "**Physical checks** ([docs/diagnose.md](docs/diagnose.md#physical-checks)):\n"
        );
        for w in &d.warnings {
            let _ = writeln!(s, "- {w}");
        }
        let _ = writeln!(s);
    }
    if d.shrink.closed_loop.verdict.as_deref() == Some("worse") {
        let _ = writeln!(
            s,
            "**The corrections are not recommended for closed loop:** on `{}` the corrected model flies worse than the base (the runs are listed after the per-state table); `corrected.json` is written as a finding, not as the fix.\n",
            d.shrink.closed_loop.plant.as_deref().unwrap_or("the plant")
        );
    }
    let _ = writeln!(
        s,
        "- model: `{}` (SHA-256 {}…), g = {} m/s²",
        d.model.file,
        &d.model.sha256[..d.model.sha256.len().min(12)],
        d.model.gravity
    );
    let _ = writeln!(s, "- training logs: {}", logs_line(&d.logs));
    let held = if d.holdout.mode == "logs" {
        format!("held-out logs {}", logs_line(&d.holdout.logs))
    } else {
        format!(
            "cross-validation, {} folds ({})",
            d.holdout.folds, d.holdout.description
        )
    };
    let _ = writeln!(s, "- scored on: {held}\n");
}

/// "Where the model parts from the data": the residual analysis's findings.
fn where_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "## Where the model parts from the data\n");
    match &d.where_report {
        Some(w) => {
            let findings = w.findings();
            if findings.is_empty() {
                let _ = writeln!(s, "No finding stands out.\n");
            }
            for f in findings {
                let _ = writeln!(s, "- {f}");
            }
            let _ = writeln!(
                s,
                "\n(the base model's residuals on the training logs; details under `where` in report.json)\n"
            );
        }
        None => {
            let _ = writeln!(s, "(not analysed)\n");
        }
    }
}

/// "Which effect": every candidate's fit and score, why the best others were not named, the scanned
/// channels left out.
fn which_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "## Which effect\n");
    let _ = writeln!(
        s,
        "Each catalogued effect fitted on the training data as an augmentation of the model, scored on \
         the held-out data; named greedily while significant (held-out ΔBIC < {}, held-out RMSE reduction \
         ≥ {} % of the affected channels, z > {}).\n",
        d.options.rules.max_delta_bic,
        100.0 * d.options.rules.min_reduction,
        d.options.rules.min_z
    );
    let _ = writeln!(
        s,
        "| effect | parameters | ± | held-out one-step RMSE before → after | reduction | held-out ΔBIC | z | named |"
    );
    let _ = writeln!(s, "|---|---|---|---|---:|---:|---:|---|");
    for e in &d.effects {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} % | {} | {} | {} |",
            e.name,
            value(&e.parameters),
            value(&e.uncertainty),
            rmse_change(e),
            100.0 * e.heldout_reduction,
            num(e.score),
            num(e.z),
            if e.selected {
                format!("yes (round {})", e.round)
            } else {
                "no".to_string()
            }
        );
    }
    let not_named: Vec<&EffectReport> = d.effects.iter().filter(|e| !e.selected).take(3).collect();
    if !not_named.is_empty() {
        let _ = writeln!(s, "\nWhy the best of the others were not named:\n");
        for e in not_named {
            let why = if e.reasons.is_empty() {
                format!(
                    "significant, but at most {} effects are named (--max-effects)",
                    d.options.rules.max_effects
                )
            } else {
                e.reasons.join("; ")
            };
            let _ = writeln!(s, "- {}: {why}", e.name);
        }
    }
    // Delay and lag channels that moved but are not part of their effect.
    let left_out: Vec<String> = d
        .effects
        .iter()
        .flat_map(|e| {
            e.scan.iter().flatten().filter_map(move |c| {
                c.not_kept
                    .as_ref()
                    .map(|why| format!("- {} {} {:.3} s: {why}", e.name, c.input, c.value))
            })
        })
        .collect();
    if !left_out.is_empty() {
        let _ = writeln!(s, "\nScanned channels that moved but were left out:\n");
        for line in left_out {
            let _ = writeln!(s, "{line}");
        }
    }
    refined_section(s, d);
    let _ = writeln!(s);
}

/// The named delays that the horizon moved away from their one-step optimum, with both estimates.
fn refined_section(s: &mut String, d: &Diagnosis) {
    let refined: Vec<String> = d
        .effects
        .iter()
        .filter(|e| e.selected)
        .flat_map(|e| {
            e.scan.iter().flatten().filter(|c| c.kept).filter_map(move |c| {
                let one = c.one_step?;
                let sigma = c.sigma.map(|v| format!(" ± {v:.3}")).unwrap_or_default();
                let xc = c
                    .cross_correlation
                    .map(|v| format!(", the residual cross-correlation {v:.3} s"))
                    .unwrap_or_default();
                Some(format!(
                    "- {} {}: {:.3} s, chosen over the horizon between the one-step optimum {one:.3}{sigma} s{xc}",
                    e.name, c.input, c.value
                ))
            })
        })
        .collect();
    if !refined.is_empty() {
        let _ = writeln!(
            s,
            "\nDelays refined over the horizon (the free runs of the training data decide between the one-step fit \
             and the residual analysis; docs/diagnose.md):\n"
        );
        for line in refined {
            let _ = writeln!(s, "{line}");
        }
    }
}

/// "How the command channels answer": step responses, corrected against base.
fn responses_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "## How the command channels answer\n\nStep responses from rest, the corrected model (every named effect) against \
         the base model: time to 63 % of the settled value (d + τ for a delayed first-order response) and the settled \
         value over the step.\n"
    );
    for t in &d.response_times {
        let _ = writeln!(s, "- {}", t.sentence());
    }
    let _ = writeln!(s);
}

/// "How far the gap shrinks": per state and overall, before and after, one step and over the
/// horizon.
fn shrink_section(s: &mut String, d: &Diagnosis) {
    let sh = &d.shrink;
    let _ = writeln!(s, "## How far the gap shrinks ({})\n", sh.data);
    let with = if sh.effects.is_empty() {
        "nothing added: after = before".to_string()
    } else {
        sh.effects.join(" + ")
    };
    let _ = writeln!(
        s,
        "Base model vs with {with}: one-step derivative (vx … yaw_rate) and free runs of {} samples from \
         every held-out sample.\n",
        sh.horizon
    );
    let _ = writeln!(
        s,
        "| state | one-step RMSE before | after | d₁ before | after | horizon RMSE before | after | d₁ before | after |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for st in &sh.per_state {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            st.state,
            opt(st.one_step_rmse_before),
            opt(st.one_step_rmse_after),
            opt(st.one_step_d1_before),
            opt(st.one_step_d1_after),
            opt(st.horizon_rmse_before),
            opt(st.horizon_rmse_after),
            opt(st.horizon_d1_before),
            opt(st.horizon_d1_after)
        );
    }
    let overall = |side: &super::Side| {
        (
            side.one_step.as_ref().map(|m| (m.overall_rmse, m.overall_d1)),
            side.horizon.as_ref().map(|m| (m.overall_rmse, m.overall_d1)),
        )
    };
    let (ob, hb) = overall(&sh.before);
    let (oa, ha) = overall(&sh.after);
    let _ = writeln!(
        s,
        "| **overall** | {} | {} | {} | {} | {} | {} | {} | {} |\n",
        opt(ob.map(|v| v.0)),
        opt(oa.map(|v| v.0)),
        opt(ob.map(|v| v.1)),
        opt(oa.map(|v| v.1)),
        opt(hb.map(|v| v.0)),
        opt(ha.map(|v| v.0)),
        opt(hb.map(|v| v.1)),
        opt(ha.map(|v| v.1))
    );
    let _ = writeln!(
        s,
        "Horizon runs: {} ({} diverged) before, {} ({} diverged) after. Closed loop on a plant: {} ({}).\n",
        sh.before.horizon_runs,
        sh.before.horizon_diverged,
        sh.after.horizon_runs,
        sh.after.horizon_diverged,
        sh.closed_loop.status,
        sh.closed_loop.note
    );
}

/// The corrections block, the notes and the plots.
fn corrected_section(s: &mut String, d: &Diagnosis, plots: &[String]) {
    let _ = writeln!(s, "## The corrected model\n");
    let _ = writeln!(
        s,
        "`corrected.json` is the model file unchanged plus this `corrections` block (docs/model-format.md):\n"
    );
    let block = serde_json::to_string_pretty(&d.corrections).unwrap_or_default();
    let _ = writeln!(s, "```json\n{block}\n```\n");
    if !d.notes.is_empty() {
        let _ = writeln!(s, "## Notes\n");
        for n in &d.notes {
            let _ = writeln!(s, "- {n}");
        }
        let _ = writeln!(s);
    }
    if !plots.is_empty() {
        let _ = writeln!(s, "## Plots\n");
        for p in plots {
            let _ = writeln!(s, "- [{p}]({p})");
        }
    }
}
