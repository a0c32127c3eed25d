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

/// A recording of `format` imported with the preset `preset`, strictly and with `--partial`: an
/// error value is a clear rejection; what imports is converted to the CSV of the contract and read
/// back.
fn import_recording(data: &[u8], format: crate::import::Format, preset: &str) {
    use crate::import::{import_bytes, ImportOptions, Profile};
    if data.len() > MAX_INPUT {
        return;
    }
    let profile = Profile::resolve(preset).expect("the presets parse");
    for partial in [false, true] {
        let options = ImportOptions {
            partial,
            ..ImportOptions::default()
        };
        if let Ok(imported) = import_bytes("fuzz", Some(format), data, &profile, &options) {
            let _ = crate::logs::parse_log(&imported.to_csv(), "imported.csv");
        }
    }
}

/// A PX4 ULog with the `px4` preset.
pub fn import_ulog(data: &[u8]) {
    import_recording(data, crate::import::Format::Ulog, "px4");
}

/// A ROS 1 bag with the `dji-osdk-ros` preset.
pub fn import_bag(data: &[u8]) {
    import_recording(data, crate::import::Format::Bag, "dji-osdk-ros");
}

/// An MCAP file with the `mavros` preset.
pub fn import_mcap(data: &[u8]) {
    import_recording(data, crate::import::Format::Mcap, "mavros");
}

/// An ArduPilot DataFlash log with the `ardupilot` preset.
pub fn import_dataflash(data: &[u8]) {
    import_recording(data, crate::import::Format::DataFlash, "ardupilot");
}

/// A CSV of another schema with the `csv` template profile.
pub fn import_csv(data: &[u8]) {
    import_recording(data, crate::import::Format::Csv, "csv");
}
