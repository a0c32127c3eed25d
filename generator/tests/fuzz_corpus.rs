//! Replays the fuzzing corpus and every crash the fuzzer found (`fuzz/corpus/<target>/`,
//! `fuzz/artifacts/<target>/`) through the fuzz targets' bodies (`uavgen::fuzzing`) on stable:
//! an input that once crashed stays fixed. Fuzzing itself: docs/testing.md.

use std::path::PathBuf;

fn replay(target: &str, body: fn(&[u8])) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fuzz");
    let mut count = 0;
    for dir in ["corpus", "artifacts"] {
        let dir = root.join(dir).join(target);
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        let mut files: Vec<PathBuf> = entries.flatten().map(|e| e.path()).filter(|p| p.is_file()).collect();
        files.sort();
        for path in files {
            if path.file_name().is_some_and(|n| n == ".keep") {
                continue;
            }
            let data = std::fs::read(&path).unwrap();
            eprintln!("{}", path.display());
            body(&data);
            count += 1;
        }
    }
    // The seeds are committed: an empty corpus means the replay checks nothing.
    assert!(count > 0, "no corpus for fuzz target {target}");
}

#[test]
fn model_corpus() {
    replay("model", uavgen::fuzzing::model);
}

#[test]
fn log_corpus() {
    replay("log", uavgen::fuzzing::log);
}

#[test]
fn plant_corpus() {
    replay("plant", uavgen::fuzzing::plant);
}

#[test]
fn mpc_options_corpus() {
    replay("mpc_options", uavgen::fuzzing::mpc_options);
}

#[test]
fn pysindy_corpus() {
    replay("pysindy", uavgen::fuzzing::pysindy);
}

#[test]
fn import_ulog_corpus() {
    replay("import_ulog", uavgen::fuzzing::import_ulog);
}

#[test]
fn import_bag_corpus() {
    replay("import_bag", uavgen::fuzzing::import_bag);
}

#[test]
fn import_mcap_corpus() {
    replay("import_mcap", uavgen::fuzzing::import_mcap);
}

#[test]
fn import_dataflash_corpus() {
    replay("import_dataflash", uavgen::fuzzing::import_dataflash);
}

#[test]
fn import_csv_corpus() {
    replay("import_csv", uavgen::fuzzing::import_csv);
}
