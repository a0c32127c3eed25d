//! The numeric ranges of every input kind, in one place, and the helpers that check them.
//!
//! Every reader (model files, MPC options, plant files, flight logs, CLI values) checks its
//! numbers against these ranges before any work is done, and names the file, the field (JSON
//! path or CSV line and column) and the value in its error. The ranges are documented per field
//! in docs/model-format.md, docs/mpc.md, docs/plant-format.md and docs/logs.md; a value outside
//! them is not physical for a quadrotor of this project's class, or would overflow the arithmetic
//! of the generated code.

use serde_json::Value;

/// Largest magnitude of any number in a model file (every field, including `corrections` and
/// `provenance`-free numbers the kind reads).
pub const MODEL_MAX_ABS: f64 = 1e9;
/// Vehicle mass, kg.
pub const MASS_KG: (f64, f64) = (1e-3, 1e4);
/// Gravitational acceleration, m/s².
pub const GRAVITY: (f64, f64) = (0.0, 100.0);
/// Largest |ξk| of a PD model.
pub const XI_MAX_ABS: f64 = 1e6;
/// Largest |coefficient| of a SINDy model.
pub const COEFFICIENT_MAX_ABS: f64 = 1e6;
/// Most states a model may have (with the extra states of its corrections). The automatic
/// substep rule and the generated solver scale with NX³; a quadrotor model has 12 to 20.
pub const MAX_STATES: usize = 64;
/// Most inputs a model may have.
pub const MAX_INPUTS: usize = 16;
/// Most library terms of a SINDy model.
pub const MAX_LIBRARY_TERMS: usize = 2000;

/// Most non-zero coefficients of a SINDy model (the generated code and its Jacobians grow with
/// them; the paper's model has 155 candidate terms per row).
pub const MAX_COEFFICIENTS: usize = 5000;

/// Largest growth of an unstable mode per sample, Re λ · DT, that generation with the automatic
/// substep rule accepts: e^7 ≈ 1100 times in one sample (Re λ ≈ 210 1/s at 30 Hz). The paper's
/// falling PD model grows far slower; a coefficient of 1e6 on vx does not.
pub const MAX_GROWTH_PER_SAMPLE: f64 = 7.0;

/// MPC weights (q, q_terminal, r).
pub const MPC_WEIGHT: (f64, f64) = (0.0, 1e6);
/// Largest |bound| of an MPC input bound.
pub const MPC_BOUND_MAX_ABS: f64 = 1e3;
/// MPC regularisation.
pub const MPC_REGULARISATION: (f64, f64) = (0.0, 1.0);
/// Most QP iterations.
pub const MPC_MAX_QP_ITERATIONS: usize = 100_000;
/// Largest accepted QP work budget (multiply-adds per solve): 2³² − 1, the largest a 32-bit
/// target's usize holds (the constant is emitted as a usize).
pub const MPC_MAX_QP_WORK: usize = 4_294_967_295;

/// Largest magnitude of any number in a plant file.
pub const PLANT_MAX_ABS: f64 = 1e6;

/// Largest magnitude of a value in a flight log (positions in m, velocities in m/s, angles in
/// rad, rates, inputs, voltage) other than the time stamp.
pub const LOG_MAX_ABS: f64 = 1e6;
/// Largest magnitude of a log's time stamp `t`, s (Unix times fit).
pub const LOG_TIME_MAX_ABS: f64 = 1e12;

/// `v` for a message: plain for ordinary magnitudes, short scientific form (`1e308`, `-4.2e30`)
/// for huge or tiny ones, so that no message prints a 300-digit number.
pub fn short(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) {
        // Up to 6 significant digits, trailing zeros dropped.
        let s = format!("{v:.5e}");
        let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
        let mantissa = if mantissa.contains('.') {
            mantissa.trim_end_matches('0').trim_end_matches('.')
        } else {
            mantissa
        };
        format!("{mantissa}e{exp}")
    } else {
        format!("{v}")
    }
}

/// `Ok(v)` if `v` is finite and within `[lo, hi]`, else the message "must be within [lo, hi]
/// (unit), found v".
pub fn within(v: f64, (lo, hi): (f64, f64), unit: &str) -> Result<f64, String> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(v)
    } else {
        let unit = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        Err(format!(
            "must be within [{}, {}]{unit}, found {}",
            short(lo),
            short(hi),
            short(v)
        ))
    }
}

/// `Ok(v)` if `|v| ≤ max_abs` (and finite), else the message.
pub fn bounded(v: f64, max_abs: f64) -> Result<f64, String> {
    if v.is_finite() && v.abs() <= max_abs {
        Ok(v)
    } else {
        Err(format!(
            "must be finite with magnitude at most {}, found {}",
            short(max_abs),
            short(v)
        ))
    }
}

/// The first number in `value` (recursively) with magnitude above `max_abs`, as (JSON path, value).
/// Keys listed in `skip` at the top level (free-form notes) are not searched.
pub fn first_out_of_range(value: &Value, max_abs: f64, skip: &[&str]) -> Option<(String, f64)> {
    fn walk(value: &Value, path: &mut String, max_abs: f64) -> Option<(String, f64)> {
        match value {
            Value::Number(n) => {
                let x = n.as_f64().unwrap_or(f64::INFINITY);
                (!(x.is_finite() && x.abs() <= max_abs)).then(|| (path.clone(), x))
            }
            Value::Array(items) => items.iter().enumerate().find_map(|(i, item)| {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                let hit = walk(item, path, max_abs);
                path.truncate(len);
                hit
            }),
            Value::Object(map) => map.iter().find_map(|(k, item)| {
                let len = path.len();
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(k);
                let hit = walk(item, path, max_abs);
                path.truncate(len);
                hit
            }),
            _ => None,
        }
    }
    match value {
        Value::Object(map) => map
            .iter()
            .filter(|(k, _)| !skip.contains(&k.as_str()))
            .find_map(|(k, item)| walk(item, &mut k.clone(), max_abs)),
        other => walk(other, &mut String::new(), max_abs),
    }
}

/// Text with a leading UTF-8 byte-order mark removed (editors on Windows write one; JSON and CSV
/// readers would report it as a syntax error at column 1).
pub fn strip_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_keeps_ordinary_numbers_and_shortens_huge_ones() {
        assert_eq!(short(9.81), "9.81");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(1e308), "1e308");
        assert_eq!(short(-4.25e30), "-4.25e30");
        assert_eq!(short(1.5e-7), "1.5e-7");
        assert!(short(f64::MAX).len() < 16);
    }

    #[test]
    fn ranges_name_the_bounds_and_the_value() {
        assert_eq!(within(9.81, GRAVITY, "m/s²"), Ok(9.81));
        let e = within(1e308, GRAVITY, "m/s²").unwrap_err();
        assert_eq!(e, "must be within [0, 100] m/s², found 1e308");
        assert!(bounded(f64::NAN, 1.0).is_err());
    }

    #[test]
    fn the_first_out_of_range_number_is_found_with_its_path() {
        let v: Value = serde_json::json!({"provenance": {"x": 1e300}, "a": [1, {"b": 2e10}]});
        assert_eq!(
            first_out_of_range(&v, 1e9, &["provenance"]),
            Some(("a[1].b".into(), 2e10))
        );
        assert_eq!(first_out_of_range(&v, 1e11, &["provenance"]), None);
    }
}
