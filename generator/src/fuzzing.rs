//! The bodies of the cargo-fuzz targets (`fuzz/`, nightly) and of their replay on stable
//! (`generator/tests/fuzz_corpus.rs` runs every file of `fuzz/corpus/` and `fuzz/artifacts/`
//! through them): each reads arbitrary bytes as one input kind and must return, never panic.
//! A returned `Err` is a clear rejection and fine; an accepted input must pass what comes next
//! (a parsed model generates a crate, an imported PySINDy model parses as a model).

use crate::codegen::{generate, GenerateOptions};
use crate::model::pysindy::{import, ImportOptions, KinematicRows};
use crate::mpc_options::MpcOptions;
use crate::sim::PlantFile;

/// Inputs longer than this are skipped (the readers are linear; long inputs only slow fuzzing).
pub const MAX_INPUT: usize = 64 * 1024;

fn text(data: &[u8]) -> Option<&str> {
    if data.len() > MAX_INPUT {
        return None;
    }
    std::str::from_utf8(data).ok()
}

/// A model file: parse, and generate the crate in memory (one substep: the automatic rule's
/// eigenvalue scan is exercised by the tests, and would dominate the fuzzing time).
pub fn model(data: &[u8]) {
    let Some(text) = text(data) else { return };
    let Ok(model) = crate::model::parse(text, "fuzz.json") else {
        return;
    };
    let options = GenerateOptions {
        substeps: Some(1),
        horizon: 5,
        ..GenerateOptions::default()
    };
    // Either a crate or an error value; a panic is a bug.
    let _ = generate(&model, &options);
}

/// A flight log (LOG_FORMAT.md CSV).
pub fn log(data: &[u8]) {
    let Some(text) = text(data) else { return };
    let _ = crate::logs::parse_log(text, "fuzz.csv");
}

/// A plant file.
pub fn plant(data: &[u8]) {
    let Some(text) = text(data) else { return };
    let _ = PlantFile::parse(text, "fuzz.json");
}

/// An MPC options file, for the standard 12-state model (models/pd_hover.json, embedded).
pub fn mpc_options(data: &[u8]) {
    let Some(text) = text(data) else { return };
    let model = crate::model::parse(include_str!("../../models/pd_hover.json"), "pd_hover.json")
        .expect("the shipped model parses");
    let _ = MpcOptions::parse(&model, text, "fuzz.json");
}

/// A PySINDy export: import, and the imported model must parse.
pub fn pysindy(data: &[u8]) {
    let Some(text) = text(data) else { return };
    let options = ImportOptions {
        name: "fuzz".into(),
        kinematic: KinematicRows::Auto,
        drop_below: 0.0,
    };
    let Ok(file) = import(text, "fuzz.json", &options) else {
        return;
    };
    let Ok(json) = serde_json::to_string_pretty(&file) else {
        return;
    };
    // The CLI validates the import exactly so; an error here is reported, not a panic.
    let _ = crate::model::parse(&json, "imported.json");
}
