//! `uavgen --model … --horizon …` (and `uavgen.generate` in Python): a model and generation
//! options to a crate written into a directory.

use crate::codegen::write::{check_target, write_all_with};
use crate::codegen::{default_crate_name, GenerateError, GenerateOptions, GeneratedCrate};
use crate::model::Model;
use std::path::{Path, PathBuf};

/// A crate generated and written.
pub struct Written {
    /// The directory written.
    pub out: PathBuf,
    pub generated: GeneratedCrate,
}

/// Generate the crate of `model` (read from `label`, which errors name) with `options` and write it
/// into `out` (default: `./<crate name>`); `force` as `--force`. `run` runs the generation (the CLI
/// wraps it in a spinner; `|work| work()` otherwise). The output is checked before any work.
pub fn generate_into(
    model: &Model,
    label: &str,
    options: &GenerateOptions,
    out: Option<&Path>,
    force: bool,
    run: impl FnOnce(&dyn Fn() -> Result<GeneratedCrate, GenerateError>) -> Result<GeneratedCrate, GenerateError>,
) -> Result<Written, String> {
    options.validate().map_err(|e| e.to_string())?;
    let name = options
        .crate_name
        .clone()
        .unwrap_or_else(|| default_crate_name(&model.name));
    let out = out.map_or_else(|| PathBuf::from(&name), Path::to_path_buf);
    // Refuse early, before the (possibly slow) substep scan.
    check_target(&out).map_err(|e| e.to_string())?;
    let generated = run(&|| crate::generate(model, options)).map_err(|e| format!("{label}: {e}"))?;
    write_all_with(&out, &generated.files, force).map_err(|e| e.to_string())?;
    Ok(Written { out, generated })
}

impl Written {
    /// What the CLI prints after generating: one line, and one more for the C ABI.
    pub fn summary(&self, model: &Model, options: &GenerateOptions) -> Vec<String> {
        let generated = &self.generated;
        let how = match &generated.substep_choice {
            Some(c) => format!(
                "auto: stiffest eigenvalue {:.1}{:+.1}i 1/s over {} envelope points",
                c.stiffest.re, c.stiffest.im, c.points
            ),
            None => "given".into(),
        };
        let mut lines = vec![format!(
            "generated crate `{}` in {} ({} states, {} inputs, N = {}, {} RK4 substeps per sample ({how}))",
            generated.crate_name,
            self.out.display(),
            model.nx(),
            model.nu(),
            options.horizon,
            generated.substeps
        )];
        if options.c_api {
            let p = crate::codegen::c_api::prefix(&generated.crate_name);
            lines.push(format!(
                "C ABI: {}/include/{p}.h; build lib{p}_capi.a with `cargo build --release --manifest-path {}/capi/Cargo.toml` (docs/c-api.md)",
                self.out.display(),
                self.out.display()
            ));
        }
        lines
    }
}
