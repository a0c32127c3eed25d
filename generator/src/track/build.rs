//! Generate the model's crate and build the tracking harness (runtime/track-harness) against it.

use crate::codegen::write::write_all;
use crate::codegen::GenerateOptions;
use crate::Model;
use std::path::{Path, PathBuf};
use std::process::Command;

const HARNESS_MAIN: &str = include_str!("../../../runtime/track-harness/src/main.rs");

/// This source tree's runtime crate, which the harness depends on.
fn runtime_dir() -> Result<PathBuf, String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime");
    dir.canonicalize().map_err(|e| {
        format!(
            "{}: {e} (uavgen track builds its harness against the runtime crate of the uavgen source tree it was built from)",
            dir.display()
        )
    })
}

/// Generate `model` into `work/crate-<name>` and build the harness in `work/harness-<name>`;
/// returns the crate name and the harness binary.
pub fn build_harness(model: &Model, options: &GenerateOptions, work: &Path) -> Result<(String, PathBuf), String> {
    let generated = crate::generate(model, options).map_err(|e| e.to_string())?;
    let name = generated.crate_name.clone();
    std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
    let crate_dir = work.join(format!("crate-{name}"));
    write_all(&crate_dir, &generated.files).map_err(|e| e.to_string())?;
    let crate_dir = crate_dir
        .canonicalize()
        .map_err(|e| format!("{}: {e}", crate_dir.display()))?;
    let dir = work.join(format!("harness-{name}"));
    std::fs::create_dir_all(dir.join("src")).map_err(|e| format!("{}: {e}", dir.display()))?;
    let manifest = format!(
        "[package]\nname = \"uavgen-track-{name}\"\nversion = \"0.1.0\"\nedition = \"2021\"\npublish = false\n\n\
         [dependencies]\nsolver = {{ package = \"{name}\", path = {:?} }}\nuavgen-runtime = {{ path = {:?} }}\n\n[workspace]\n",
        crate_dir.display().to_string(),
        runtime_dir()?.display().to_string()
    );
    let write = |path: PathBuf, text: &str| std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()));
    write(dir.join("Cargo.toml"), &manifest)?;
    write(dir.join("src/main.rs"), HARNESS_MAIN)?;
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(work.join("target"))
        .status()
        .map_err(|e| format!("cannot run cargo (uavgen track builds the generated crate with it): {e}"))?;
    if !status.success() {
        return Err(format!("building the tracking harness for {name} failed"));
    }
    Ok((
        name.clone(),
        work.join("target/release").join(format!("uavgen-track-{name}")),
    ))
}
