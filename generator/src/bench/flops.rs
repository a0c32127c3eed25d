//! Floating-point work of one RTI step of a generated crate, counted from the code the generator
//! emits for it (the figures `uavgen check` prints), so that `uavgen bench` can relate its
//! instruction counts and times to the arithmetic they perform.
//!
//! The crate is regenerated in memory from its model file with the options its header and
//! `src/dims.rs` record; the model file must be the crate's own (its SHA-256 is in the header).

use super::CrateDims;
use crate::codegen::{GenerateOptions, QpChoice};
use crate::{Float, Model};
use std::path::Path;

/// Multiply-adds of one RTI step without the QP's iterations (condensed crates; see
/// `codegen::kernels::StepFlops`). A multiply-add is 2 flops.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct StepWork {
    /// RK4 sensitivities of the N stages (`prepare`).
    pub linearisation: usize,
    /// Condensing: P, E·A chains, H blocks, G = ∂g/∂x₀ and the gradient at the guess (`prepare`).
    pub condensing: usize,
    /// Cholesky of H with every input free (`prepare`; an upper bound, fixed inputs make it smaller).
    pub cholesky: usize,
    /// g = g⁰ + G z₀ and the guess update (`feedback`, without the QP's iterations).
    pub feedback: usize,
}

impl StepWork {
    /// The work of a generated condensed crate at horizon `n` (what `uavgen check` prints).
    pub fn of(generated: &crate::GeneratedCrate, n: usize) -> Self {
        let flops = generated.structure.flops(n);
        Self {
            linearisation: generated.sensitivity_flops.per_step(n, generated.substeps).0,
            condensing: flops.condensing,
            cholesky: flops.cholesky,
            feedback: flops.feedback,
        }
    }

    /// Multiply-adds of the whole step without QP iterations.
    pub fn total(&self) -> usize {
        self.prepare() + self.feedback
    }

    /// Multiply-adds of `prepare`.
    pub fn prepare(&self) -> usize {
        self.linearisation + self.condensing + self.cholesky
    }

    /// Flops (2 per multiply-add) of `prepare`.
    pub fn prepare_flops(&self) -> usize {
        2 * self.prepare()
    }

    /// Flops of the whole step without QP iterations.
    pub fn total_flops(&self) -> usize {
        2 * self.total()
    }
}

/// The value of `key=` in the header's `// options:` line (line 3 of `src/lib.rs`).
fn header_option<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    header
        .split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
}

/// The step's work for the crate in `crate_dir` (with `dims` read from it) generated from `model`;
/// `Ok(None)` for a crate whose QP is not the condensed one (its kernels are not counted).
pub fn step_work(model: &Model, crate_dir: &Path, dims: &CrateDims) -> Result<Option<StepWork>, String> {
    let lib = crate_dir.join("src/lib.rs");
    let text = std::fs::read_to_string(&lib).map_err(|e| format!("{}: cannot read: {e}", lib.display()))?;
    let header: Vec<&str> = text.lines().take(4).collect();
    let model_line = header.iter().find(|l| l.starts_with("// model:"));
    let options_line = header
        .iter()
        .find(|l| l.starts_with("// options:"))
        .ok_or_else(|| format!("{}: no `// options:` header line", lib.display()))?;
    if let Some(line) = model_line {
        if !line.contains(&model.source.sha256) {
            return Err(format!(
                "{}: the crate was not generated from this model file (its header: {})",
                model.source.file,
                line.trim_start_matches("// ")
            ));
        }
    }
    if header_option(options_line, "qp") != Some("condensed") {
        return Ok(None);
    }
    let float = match header_option(options_line, "float") {
        Some("f32") => Float::F32,
        _ => Float::F64,
    };
    let options = GenerateOptions {
        horizon: dims.horizon,
        rate_hz: 1.0 / dims.dt,
        substeps: Some(dims.substeps),
        float,
        mpc: Some(dims.options.clone()),
        qp: QpChoice::Condensed,
        ..GenerateOptions::default()
    };
    let generated = crate::generate(model, &options).map_err(|e| format!("{}: {e}", model.source.file))?;
    Ok(Some(StepWork::of(&generated, dims.horizon)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_options_are_read_by_key() {
        let line = "// options: horizon=30 rate=30 Hz substeps=1 (auto) float=f32 qp=condensed (auto) c-api";
        assert_eq!(header_option(line, "qp"), Some("condensed"));
        assert_eq!(header_option(line, "float"), Some("f32"));
        assert_eq!(header_option(line, "horizon"), Some("30"));
        assert_eq!(header_option(line, "missing"), None);
    }

    /// 2 flops per multiply-add; prepare is everything but the feedback.
    #[test]
    fn flops_count_two_per_multiply_add() {
        let w = StepWork {
            linearisation: 1,
            condensing: 10,
            cholesky: 100,
            feedback: 1000,
        };
        assert_eq!(w.prepare(), 111);
        assert_eq!(w.prepare_flops(), 222);
        assert_eq!(w.total_flops(), 2222);
    }
}
