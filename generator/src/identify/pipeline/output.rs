//! The model text as `identify` writes it: the input response as `corrections`, the operating
//! envelope, the horizon check, the warnings in the provenance.

use super::{parse_delay_spec, round_s, stage, DelaySpec, IdentifyOptions, Method, Report, INPUTS};
use crate::identify::excitation::{self, Excitation};
use crate::identify::horizon_check::{self, HorizonCheck};
use crate::identify::response::InputResponse;
use crate::model::envelope;

/// The horizon check of `identify`: the start yaw within the logged arc when the heading did not
/// move, the inputs within the logged range (widened, capped at the MPC bounds)
/// (docs/identification.md, "Unexcited directions").
pub(super) fn horizon_check_options(ex: &Excitation) -> HorizonCheck {
    HorizonCheck::for_excitation(ex)
}

/// The model text with the input response as `corrections` (latency, actuator_lag).
pub(super) fn attach(json: &str, options: &IdentifyOptions, response: Option<InputResponse>) -> Result<String, String> {
    let Some(r) = response.filter(|r| !r.is_identity()) else {
        return Ok(json.to_string());
    };
    let latency = INPUTS
        .iter()
        .zip(r.delay)
        .filter(|(_, d)| round_s(*d) > 0.0)
        .map(|(n, d)| (n.to_string(), round_s(d)))
        .collect();
    let actuator_lag = INPUTS
        .iter()
        .zip(r.lag)
        .filter_map(|(n, l)| l.map(|t| (n.to_string(), round_s(t))))
        .collect();
    let source = match parse_delay_spec(&options.input_delay) {
        Ok(DelaySpec::Auto) => {
            "uavgen identify --input-delay auto: delays and lags estimated from the logs; the model was fitted to the inputs they give"
        }
        _ => "uavgen identify --input-delay: the model was fitted to u(t - delay)",
    };
    let corrections = crate::model::Corrections {
        source: Some(source.into()),
        latency,
        actuator_lag,
        ..Default::default()
    };
    crate::model::attach_corrections(json, &options.out_label, &corrections).map_err(|e| e.to_string())
}

/// Warnings for the commanded channels the model does not act on: a static gain below
/// [`excitation::ZERO_GAIN`] (docs/identification.md, "Zero gains"). A silent channel whose terms
/// were left out is said so.
pub(super) fn gain_warnings(model: &crate::model::Model, ex: &Excitation, report: &dyn Report) -> Vec<String> {
    let Some(gains) = excitation::channel_gains(model) else {
        return Vec::new();
    };
    let silent = ex.silent();
    let mut out = Vec::new();
    for (input, g) in excitation::zero_gains(&gains, [true; 4]) {
        let j = INPUTS.iter().position(|n| *n == input).unwrap_or(0);
        let w = if silent[j] {
            format!("{input}: the model does not act on it (static gain {g:.3}): the logs carry no signal on this channel, so the model cannot predict its effect")
        } else {
            format!("{input}: the identified static gain is ~0 ({g:.3}, below {}): the model ignores a command the logs carry", excitation::ZERO_GAIN)
        };
        report.line(&format!("warning: {w}"));
        out.push(w);
    }
    out
}

/// How the fitted text becomes the text written.
pub(super) struct Output<'a> {
    pub options: &'a IdentifyOptions,
    pub response: Option<InputResponse>,
    pub envelope: Option<&'a envelope::DeclaredEnvelope>,
}

impl Output<'_> {
    /// The model text as it will be written (corrections and envelope attached) and what `--model`
    /// will read from it, validated.
    pub fn finish(&self, json: &str) -> Result<(String, crate::model::Model), String> {
        let json = attach(json, self.options, self.response)?;
        let json = match self.envelope {
            Some(e) => envelope::attach(&json, &self.options.out_label, e).map_err(|e| e.to_string())?,
            None => json,
        };
        let model = crate::model::parse(&json, &self.options.out_label)
            .map_err(|e| format!("the identified model is invalid: {e}"))?;
        Ok((json, model))
    }

    /// The text to write: `json` as [`Output::finish`] makes it, its corrections said, and the
    /// horizon check (one MPC horizon of free run from random envelope states must stay bounded).
    /// When the model fails it and `unrefined` (the sparse fit before the loop refinement) is
    /// given, that one is checked instead; a model that still fails is an error unless the check
    /// is off. Also gives the fitted text chosen (before corrections) and the model.
    pub fn checked(
        &self,
        json: &str,
        unrefined: Option<&str>,
        ex: &Excitation,
        report: &dyn Report,
    ) -> Result<(String, String, crate::model::Model), String> {
        let mut chosen = json.to_string();
        let (mut json, mut model) = self.finish(json)?;
        if let Some(c) = model.corrections.as_ref() {
            for line in c.summary(&model.inputs) {
                report.line(&format!("  corrections: {}", line.trim()));
            }
        }
        let check_options = horizon_check_options(ex);
        let mut checked = stage(report, "horizon check", || horizon_check::check(&model, &check_options));
        if let (Some(r), Some(text)) = (&checked, unrefined) {
            if !r.passed() {
                report.line(&format!(
                    "loop refinement: the refined model leaves the bounds within one MPC horizon ({} of {} trials); keeping the coefficients fitted before the refinement",
                    r.unbounded, r.trials
                ));
                (json, model) = self.finish(text)?;
                chosen = text.to_string();
                checked = horizon_check::check(&model, &check_options);
            }
        }
        if let Some(r) = checked {
            report.line(&r.summary());
            if !r.passed() && self.options.horizon_check {
                return Err(format!(
                    "{}: not written: the identified model leaves the bounds within one MPC horizon ({} of {} trials); \
                     give sparser --sweep-values (or a larger --threshold), or pass --no-horizon-check to write it anyway",
                    self.options.out_label, r.unbounded, r.trials
                ));
            }
        }
        Ok((json, chosen, model))
    }

    /// The fit's text (before corrections and envelope) with `provenance.warnings`.
    pub fn add_warnings(&self, text: &str, warnings: &[String]) -> Result<String, String> {
        fn put(p: &mut serde_json::Value, warnings: &[String]) {
            if let serde_json::Value::Object(m) = p {
                m.insert("warnings".into(), serde_json::json!(warnings));
            }
        }
        match self.options.method {
            Method::Sindy => {
                let mut f: crate::model::SindyFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
                put(&mut f.provenance, warnings);
                serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
            }
            Method::Pd => {
                let mut f: crate::model::PdFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
                put(&mut f.provenance, warnings);
                serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
            }
        }
        .map(|t| t + "\n")
    }
}
