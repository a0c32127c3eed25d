//! The report in words: plain-English sentences with figures, largest gap first.

use super::regimes::RegimeStats;
use super::summary::ChannelStats;
use super::xcorr::DRIVEN_STATE;
use super::{state_index, WhereReport, INPUT_COLUMNS};

/// A number with about 3 significant digits.
pub fn num(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".to_string();
    }
    let a = x.abs();
    if !(1e-4..1e6).contains(&a) {
        return format!("{x:.2e}");
    }
    let mag = a.log10().floor() as i32;
    let decimals = (2 - mag).clamp(0, 6) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A fraction as a percentage ("41 %", "3.2 %").
pub fn pct(x: f64) -> String {
    let p = 100.0 * x;
    if p.abs() < 10.0 {
        format!("{p:.1} %")
    } else {
        format!("{p:.0} %")
    }
}

fn p_value(p: f64) -> String {
    if p < 1e-16 {
        "p < 1e-16".to_string()
    } else {
        format!("p = {}", num(p))
    }
}

fn with_unit(x: f64, unit: &str) -> String {
    if unit.is_empty() {
        num(x)
    } else {
        format!("{} {unit}", num(x))
    }
}

/// Short names of the regime variables, for sentences.
fn regime_name(key: &str) -> &str {
    match key {
        "speed" => "horizontal speed",
        "tilt" => "tilt",
        "height" => "height",
        "vertical_speed" => "vertical speed",
        "yaw_rate" => "|yaw rate|",
        "time_in_flight" => "time in flight",
        "battery_voltage" => "battery voltage",
        other => other,
    }
}

fn is_velocity(channel: &str) -> bool {
    matches!(channel, "vx" | "vy" | "vz")
}

fn is_rate(channel: &str) -> bool {
    matches!(channel, "roll_rate" | "pitch_rate" | "yaw_rate")
}

/// "name share (RMSE …, ratio …)" items ranked by share, or by listing order without scales.
fn ranking(stats: &[ChannelStats]) -> Vec<String> {
    let mut order: Vec<&ChannelStats> = stats.iter().filter(|s| s.n > 0).collect();
    order.sort_by(|a, b| b.share.unwrap_or(-1.0).total_cmp(&a.share.unwrap_or(-1.0)));
    order
        .iter()
        .map(|s| match (s.share, s.normalised_rmse) {
            (Some(sh), Some(nr)) => format!(
                "{} {} (RMSE {}, {} of the no-change error)",
                s.channel,
                pct(sh),
                with_unit(s.rmse, &s.unit),
                num(nr)
            ),
            _ => format!("{} (RMSE {})", s.channel, with_unit(s.rmse, &s.unit)),
        })
        .collect()
}

fn channel_ranking(r: &WhereReport, out: &mut Vec<String>) {
    let items = ranking(&r.one_step);
    if items.is_empty() {
        return;
    }
    let scaled = r.one_step.iter().any(|s| s.share.is_some());
    out.push(if scaled {
        format!(
            "Largest one-step gap first (share of the total normalised derivative error; no-change error = RMS of \
             the measured derivative): {}.",
            items.join(", ")
        )
    } else {
        format!("One-step derivative residuals: {}.", items.join(", "))
    });
    if let Some(h) = &r.horizon {
        let items = ranking(h);
        if items.is_empty() {
            return;
        }
        let steps = r
            .horizon_steps
            .map(|n| format!("{n} samples ({} s)", num(n as f64 * r.dt)))
            .unwrap_or_else(|| "N samples".to_string());
        out.push(format!(
            "Over the horizon (free run of {steps}, residual at its end; no-change error = RMS change of the state \
             over the horizon): {}.",
            items.join(", ")
        ));
        let worse: Vec<&str> = h
            .iter()
            .filter(|s| s.normalised_rmse.is_some_and(|v| v > 1.0))
            .map(|s| s.channel.as_str())
            .collect();
        if !worse.is_empty() {
            out.push(format!(
                "Over the horizon the model predicts {} worse than assuming no change.",
                worse.join(", ")
            ));
        }
    }
}

fn bin_range(r: &super::Regime, b: usize) -> String {
    format!("{}–{} {}", num(r.bins[b].lo), num(r.bins[b].hi), r.unit)
}

fn regime_sentence(regime: &super::Regime, ch: &ChannelStats, s: &RegimeStats, what: &str) -> Option<String> {
    let name = regime_name(&regime.variable);
    let first = s.rmse.iter().position(Option::is_some)?;
    let last = s.rmse.iter().rposition(Option::is_some)?;
    let (r0, r1) = (s.rmse[first]?, s.rmse[last]?);
    let (m0, m1) = (s.mean[first]?, s.mean[last]?);
    let ratio = s.rmse_ratio.unwrap_or(1.0);
    let verb = if ratio >= 1.5 {
        "grows with"
    } else if ratio <= 1.0 / 1.5 {
        "shrinks with"
    } else {
        "depends on"
    };
    let mut text = format!(
        "The {} {what}residual {verb} {name}: RMSE {} at {} → {} at {}; mean residual {} → {} ({} of its variance \
         explained by the {name} bins, {} of the variation of its squared error",
        ch.channel,
        with_unit(r0, &ch.unit),
        bin_range(regime, first),
        with_unit(r1, &ch.unit),
        bin_range(regime, last),
        num(m0),
        with_unit(m1, &ch.unit),
        pct(s.eta_squared),
        pct(s.eta_squared_ms),
    );
    if let Some(rv) = s.r {
        text.push_str(&format!("; r = {} with {name}", num(rv)));
    }
    if let Some(ra) = s.r_abs {
        text.push_str(&format!(", r = {} for |residual|", num(ra)));
    }
    text.push_str(").");
    Some(text)
}

/// (score, regime index, channel index) of the regime dependences worth reporting, strongest first.
fn regime_candidates(r: &WhereReport, horizon: bool) -> Vec<(f64, usize, usize)> {
    let min = r.options.min_explained;
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (ri, regime) in r.regimes.iter().enumerate() {
        if regime.bins.len() < 2 {
            continue;
        }
        let channels = if horizon {
            regime.horizon.as_deref().unwrap_or(&[])
        } else {
            &regime.one_step
        };
        for (c, rc) in channels.iter().enumerate() {
            let e = rc.stats.explained();
            if e >= min && e > 3.0 * rc.stats.eta_squared_null {
                candidates.push((e, ri, c));
            }
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
    candidates
}

fn regime_findings(r: &WhereReport, out: &mut Vec<String>) {
    // The strongest dependence of each channel, at most three channels.
    let mut seen = Vec::new();
    for (_, ri, c) in regime_candidates(r, false) {
        if seen.contains(&c) {
            continue;
        }
        seen.push(c);
        let regime = &r.regimes[ri];
        if let Some(s) = regime_sentence(regime, &r.one_step[c], &regime.one_step[c].stats, "") {
            out.push(s);
        }
        if seen.len() == 3 {
            break;
        }
    }
    // The strongest one over the horizon.
    if let (Some(h), Some(&(_, ri, c))) = (&r.horizon, regime_candidates(r, true).first()) {
        let regime = &r.regimes[ri];
        if let Some(stats) = regime.horizon.as_ref().map(|v| &v[c].stats) {
            if let Some(s) = regime_sentence(regime, &h[c], stats, "horizon ") {
                out.push(s);
            }
        }
    }
}

fn own_state_findings(r: &WhereReport, out: &mut Vec<String>) {
    let mut items: Vec<_> = r
        .own_state
        .iter()
        .filter(|o| o.r.abs() > o.bound && o.r.abs() >= 0.2)
        .collect();
    items.sort_by(|a, b| b.r.abs().total_cmp(&a.r.abs()));
    for o in items {
        let unit = r
            .one_step
            .iter()
            .find(|s| s.channel == o.channel)
            .map_or("", |s| s.unit.as_str());
        let meaning = match (is_velocity(&o.channel), is_rate(&o.channel), o.slope < 0.0) {
            (true, _, true) => "a drag-like force the model lacks".to_string(),
            (true, _, false) => format!(
                "the model has too much drag on {} (or lacks a force growing with it)",
                o.state
            ),
            (_, true, true) => "damping the model lacks".to_string(),
            (_, true, false) => format!("the model over-damps {}", o.state),
            _ => format!("a term in {} the model lacks", o.state),
        };
        out.push(format!(
            "The {} residual correlates with {} (r = {}, significance bound ±{}; residual ≈ {} {} {} · {}, {}): {meaning}.",
            o.channel,
            o.state,
            num(o.r),
            num(o.bound),
            num(o.intercept),
            if o.slope < 0.0 { "−" } else { "+" },
            num(o.slope.abs()),
            o.state,
            if unit.is_empty() { "slope per unit of the state".to_string() } else { format!("in {unit}") },
        ));
    }
}

fn bias_findings(r: &WhereReport, out: &mut Vec<String>) {
    let mut items: Vec<&ChannelStats> = r
        .one_step
        .iter()
        .filter(|s| s.t.is_some_and(|t| t.abs() >= 3.0))
        .collect();
    items.sort_by(|a, b| b.bias_fraction.total_cmp(&a.bias_fraction));
    for s in items {
        let what = if is_velocity(&s.channel) {
            "a constant force (or trim offset) the model lacks"
        } else if is_rate(&s.channel) {
            "a constant moment (or trim offset) the model lacks"
        } else {
            "a constant offset the model lacks"
        };
        out.push(format!(
            "The {} residual has a bias of {} (standard error {} from {} effective of {} samples, t = {}; {} of its \
             mean-square error): {what}.",
            s.channel,
            with_unit(s.mean, &s.unit),
            num(s.std_error),
            num(s.n_eff),
            s.n,
            num(s.t.unwrap_or(0.0)),
            pct(s.bias_fraction),
        ));
    }
}

fn samples(n: usize) -> String {
    format!("{n} sample{}", if n == 1 { "" } else { "s" })
}

/// ", and the data show … responding k samples after it" when the response-lag test found a delay.
fn delay_hint(r: &WhereReport, j: usize) -> String {
    match r.response_lags.get(j).map(|l| (l, &l.xcorr)) {
        Some((l, x)) if x.significant && x.localised && x.peak_lag > 0 => format!(
            "; the data show {} responding {} ({} s) after {}: a delay the model lacks",
            l.response,
            samples(x.peak_lag as usize),
            num(x.peak_seconds),
            l.input
        ),
        _ => String::new(),
    }
}

fn lag_findings(r: &WhereReport, out: &mut Vec<String>) {
    let mut items: Vec<_> = r
        .cross_correlation
        .iter()
        .filter(|x| x.prewhitened.significant && x.prewhitened.localised)
        .collect();
    items.sort_by(|a, b| {
        let z = |x: &super::CrossCorrelation| x.prewhitened.peak_rho.abs() / x.prewhitened.bound;
        z(b).total_cmp(&z(a))
    });
    for x in items.into_iter().take(3) {
        let pw = &x.prewhitened;
        let j = INPUT_COLUMNS.iter().position(|i| *i == x.input).unwrap_or(0);
        let driven = state_index(&x.channel) == Some(DRIVEN_STATE[j]);
        let raw_at = x.rho[(pw.peak_lag + x.max_lag as isize) as usize];
        let figures = format!(
            "prewhitened ρ = {}, significance bound ±{}; raw ρ = {} there, raw peak {} at lag {}",
            num(pw.peak_rho),
            num(pw.bound),
            num(raw_at),
            num(x.peak_rho),
            x.peak_lag
        );
        let n = samples(pw.peak_lag.unsigned_abs());
        out.push(match pw.peak_lag {
            l if l > 0 => format!(
                "{} leads the {} residual by {n} ({} s, {figures}): {}.",
                x.input,
                x.channel,
                num(pw.peak_seconds),
                if driven {
                    "an unmodelled input delay or lag"
                } else {
                    "a delayed input effect the model misses"
                }
            ),
            0 => format!(
                "The {} residual correlates with {} at lag 0 ({figures}): {}.",
                x.channel,
                x.input,
                match (driven, pw.peak_rho < 0.0) {
                    (true, true) => format!(
                        "the model responds to {} more strongly or sooner than the aircraft{}",
                        x.input,
                        delay_hint(r, j)
                    ),
                    (true, false) => format!(
                        "the aircraft responds to {} more strongly than the model (gain too low)",
                        x.input
                    ),
                    (false, _) => "an input effect (coupling) the model misses".to_string(),
                }
            ),
            _ => format!(
                "The {} residual leads {} by {n} ({} s, {figures}): the commands react to the model error \
                 (closed-loop feedback) or are logged late, which is not an input delay.",
                x.channel,
                x.input,
                num(-pw.peak_seconds)
            ),
        });
    }
}

fn response_findings(r: &WhereReport, out: &mut Vec<String>) {
    let items: Vec<String> = r
        .response_lags
        .iter()
        .filter(|l| l.xcorr.significant && l.xcorr.localised)
        .map(|l| {
            let x = &l.xcorr;
            let n = samples(x.peak_lag.unsigned_abs());
            let figures = format!("ρ = {}, background {}", num(x.peak_rho), num(x.median_abs));
            if x.peak_lag >= 0 {
                format!(
                    "{} responds {n} ({} s) after {} ({figures})",
                    l.response,
                    num(x.peak_seconds),
                    l.input
                )
            } else {
                format!(
                    "{} moves {n} ({} s) before the logged {} ({figures}: the command is logged late or reacts to \
                     the state)",
                    l.response,
                    num(-x.peak_seconds),
                    l.input
                )
            }
        })
        .collect();
    if !items.is_empty() {
        out.push(format!(
            "Input → response lags in the data (prewhitened cross-correlation of each input with the state it \
             drives): {}.",
            items.join("; ")
        ));
    }
}

fn coherence_findings(r: &WhereReport, out: &mut Vec<String>) {
    let Some(sp) = &r.spectrum else { return };
    let mut items: Vec<(f64, usize, usize)> = Vec::new();
    for (i, c) in sp.coherence.iter().enumerate() {
        if let Some((b, v)) = c
            .band_mean
            .iter()
            .enumerate()
            .filter_map(|(b, v)| v.map(|v| (b, v)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        {
            if v > c.threshold {
                items.push((v, i, b));
            }
        }
    }
    items.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (v, i, b) in items.into_iter().take(2) {
        let c = &sp.coherence[i];
        out.push(format!(
            "The {} residual is coherent with {} at {} (mean coherence {}, 95 % chance level {}): the model's \
             response to {} in that band is wrong (missing, excess or mistimed input dynamics).",
            c.channel,
            c.input,
            sp.band_labels[b],
            num(v),
            num(c.threshold),
            c.input
        ));
    }
}

fn band_findings(r: &WhereReport, out: &mut Vec<String>) {
    let Some(sp) = &r.spectrum else { return };
    let mut order: Vec<usize> = (0..sp.channels.len()).filter(|&c| sp.channels[c].windows > 0).collect();
    order.sort_by(|a, b| {
        let share = |c: usize| r.one_step.get(c).and_then(|s| s.share).unwrap_or(0.0);
        share(*b).total_cmp(&share(*a))
    });
    let items: Vec<String> = order
        .iter()
        .map(|&c| {
            let ch = &sp.channels[c];
            format!(
                "{} {} ({})",
                ch.channel,
                sp.band_labels[ch.dominant_band],
                pct(ch.band_fraction[ch.dominant_band])
            )
        })
        .collect();
    if !items.is_empty() {
        out.push(format!(
            "Band with the most residual power (Welch, {}-sample Hann windows): {} — low bands point to slow, \
             state- or regime-dependent forces, high bands to fast unmodelled dynamics or noise.",
            sp.nperseg,
            items.join(", ")
        ));
    }
}

fn whiteness_findings(r: &WhereReport, out: &mut Vec<String>) {
    let (bad, good): (Vec<_>, Vec<_>) = r.whiteness.iter().partition(|w| w.p_value < 0.01);
    let m = r.whiteness.first().map_or(0, |w| w.lags);
    if !bad.is_empty() {
        let items: Vec<String> = bad
            .iter()
            .map(|w| {
                format!(
                    "{} Q = {} ({}, ρ1 = {})",
                    w.channel,
                    num(w.q),
                    p_value(w.p_value),
                    num(w.acf1)
                )
            })
            .collect();
        out.push(format!(
            "Not white (Ljung-Box over {m} lags): {} — the errors are systematic, not noise (smoothed derivatives \
             also correlate neighbouring samples).",
            items.join(", ")
        ));
    }
    if !good.is_empty() {
        let names: Vec<&str> = good.iter().map(|w| w.channel.as_str()).collect();
        out.push(format!(
            "White at the 1 % level (Ljung-Box over {m} lags): {}.",
            names.join(", ")
        ));
    }
}

fn quality_findings(r: &WhereReport, out: &mut Vec<String>) {
    let q = &r.quality;
    if q.stale_fraction > r.options.stale_warning {
        let mut text = format!(
            "{} of rows ({} of {}) repeat the previous state (sample-and-hold): derivatives across them are biased",
            pct(q.stale_fraction),
            q.stale_rows,
            q.rows
        );
        if let Some((s, ratio)) = q
            .stale_split
            .iter()
            .filter_map(|s| match (s.rmse_stale, s.rmse_fresh) {
                (Some(a), Some(b)) if b > 0.0 => Some((s, a / b)),
                _ => None,
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
        {
            text.push_str(&if ratio >= 1.2 {
                format!(
                    "; the {} one-step RMSE is {}× larger on stale rows than on fresh ones (the largest ratio)",
                    s.channel,
                    num(ratio)
                )
            } else {
                format!(
                    "; the one-step residuals are not much larger on stale rows (largest RMSE ratio {}, {})",
                    num(ratio),
                    s.channel
                )
            });
        }
        if q.segments.len() > 1 {
            if let Some(worst) = q
                .segments
                .iter()
                .max_by(|a, b| a.stale_fraction.total_cmp(&b.stale_fraction))
            {
                text.push_str(&format!(
                    "; most in segment {} ({})",
                    worst.segment,
                    pct(worst.stale_fraction)
                ));
            }
        }
        text.push('.');
        out.push(text);
    }
    out.extend(q.notes.iter().cloned());
}

/// The findings of a report (see `docs/diagnose-where.md`): channel ranking (one step, horizon),
/// regime dependences, own-state correlations (drag), input → residual lags, coherence, bias,
/// response lags, dominant bands, whiteness, data quality and the reader's notes.
pub fn findings(r: &WhereReport) -> Vec<String> {
    let mut out = Vec::new();
    channel_ranking(r, &mut out);
    regime_findings(r, &mut out);
    own_state_findings(r, &mut out);
    lag_findings(r, &mut out);
    coherence_findings(r, &mut out);
    bias_findings(r, &mut out);
    response_findings(r, &mut out);
    band_findings(r, &mut out);
    whiteness_findings(r, &mut out);
    quality_findings(r, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(0.05234), "0.0523");
        assert_eq!(num(-0.21), "-0.21");
        assert_eq!(num(1234.4), "1234");
        assert_eq!(num(3.0), "3");
        assert_eq!(num(1.5e-7), "1.50e-7");
        assert_eq!(pct(0.4123), "41 %");
        assert_eq!(pct(0.032), "3.2 %");
    }
}
