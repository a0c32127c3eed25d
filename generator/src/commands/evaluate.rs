//! `uavgen evaluate` (and `uavgen.evaluate` in Python): the checks before the work and the notes
//! around [`crate::evaluate::evaluate`].

use crate::evaluate::EvaluateOptions;
use crate::logs::FlightLog;
use crate::model::Model;

/// The options' checks, with the CLI's messages (flag names), before any work.
pub fn check_options(options: &EvaluateOptions) -> Result<(), String> {
    if options.horizon == 0 {
        return Err("--horizon: must be at least 1 sample, got 0".into());
    }
    if options.substeps == Some(0) {
        return Err("--substeps: must be at least 1, got 0".into());
    }
    Ok(())
}

/// Where a log leaves the envelope the model was identified on (cheap and worth knowing): one
/// note per such log, naming it by its source (the path as given).
pub fn envelope_notes(model: &Model, logs: &[FlightLog]) -> Vec<String> {
    let Some(e) = &model.envelope else {
        return Vec::new();
    };
    logs.iter()
        .filter_map(|log| {
            let (outside, rows, states) = crate::model::envelope::rows_outside(e, log);
            (outside > 0).then(|| {
                format!(
                    "{}: {outside} of {rows} rows outside the model's envelope ({}): the model extrapolates there",
                    log.source,
                    states.join(", ")
                )
            })
        })
        .collect()
}
