//! `--c-api` (docs/c-api.md): the header declares exactly the functions the ABI template defines,
//! generation is deterministic, a crate without `--c-api` gets none of it, and an f32 crate of
//! another model builds its staticlib and is called from C (gcc) with `float`s.

use std::fs;
use std::path::PathBuf;
use std::process::Command;
use uavgen::codegen::c_api::{storage_bound, storage_slack, FFI_RS, STATUS_CODES};
use uavgen::codegen::write::write_all;
use uavgen::codegen::{Float, QpMethod};
use uavgen::{generate, GenerateOptions, Model};

fn shipped(name: &str) -> Model {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(format!("{name}.json"));
    uavgen::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn file<'a>(files: &'a [(PathBuf, String)], path: &str) -> &'a str {
    files
        .iter()
        .find(|(p, _)| p == &PathBuf::from(path))
        .map(|(_, s)| s.as_str())
        .unwrap_or_else(|| panic!("no {path} among {:?}", files.iter().map(|f| &f.0).collect::<Vec<_>>()))
}

/// Names of the `extern "C"` functions of the template (without the `uavgen_model_` prefix).
fn template_functions() -> Vec<String> {
    FFI_RS
        .lines()
        .filter_map(|l| l.split("extern \"C\" fn uavgen_model_").nth(1))
        .map(|rest| rest.split('(').next().unwrap().to_string())
        .collect()
}

#[test]
fn header_declares_every_abi_function_and_status() {
    let options = GenerateOptions {
        c_api: true,
        ..GenerateOptions::default()
    };
    let generated = generate(&shipped("sindy_m100"), &options).unwrap();
    let header = file(&generated.files, "include/sindy_m100.h");
    let ffi = file(&generated.files, "capi/src/ffi.rs");
    let functions = template_functions();
    assert!(functions.len() >= 15, "{functions:?}");
    for f in &functions {
        assert!(
            header.contains(&format!(" sindy_m100_{f}(")),
            "the header does not declare sindy_m100_{f}"
        );
        assert!(ffi.contains(&format!("extern \"C\" fn sindy_m100_{f}(")));
    }
    // Every prototype in the header is a function of the ABI, and the other way round.
    let mut declared: Vec<String> = header
        .lines()
        .filter(|l| l.ends_with(");") && !l.starts_with(' ') && !l.starts_with('#'))
        .filter_map(|l| l.split(" sindy_m100_").nth(1))
        .map(|rest| rest.split('(').next().unwrap().to_string())
        .collect();
    let mut defined = functions.clone();
    declared.sort();
    defined.sort();
    assert_eq!(declared, defined);
    for (name, value, _) in STATUS_CODES {
        assert!(header.contains(&format!("SINDY_M100_{name} = {value},")), "{name}");
        assert!(ffi.contains(&format!("pub const {name}: i32 = {value};")), "{name}");
    }
    // No placeholder left (the `@generated` header lines aside).
    let body: String = ffi.lines().filter(|l| !l.starts_with("// ")).collect();
    assert!(
        !body.contains("uavgen_model") && !body.contains('@'),
        "a placeholder is left in ffi.rs"
    );
    assert!(header.contains(&format!(
        "#define SINDY_M100_STORAGE_SIZE {}",
        storage_bound(12, 4, 30, Float::F64, QpMethod::Condensed)
    )));
    assert!(header.contains("typedef double sindy_m100_real;"));
    // The solver crate itself keeps `forbid(unsafe_code)`; only capi/src/ffi.rs has `unsafe`.
    assert!(file(&generated.files, "src/lib.rs").contains("#![forbid(unsafe_code)]"));
    for (path, text) in &generated.files {
        if path != &PathBuf::from("capi/src/ffi.rs") {
            assert!(!text.contains("unsafe {"), "{} has an unsafe block", path.display());
        }
    }
    // Deterministic, and nothing of it without --c-api.
    let again = generate(&shipped("sindy_m100"), &options).unwrap();
    assert_eq!(generated.files, again.files);
    let plain = generate(&shipped("sindy_m100"), &GenerateOptions::default()).unwrap();
    assert!(plain
        .files
        .iter()
        .all(|(p, _)| !p.starts_with("capi") && !p.starts_with("include")));
    assert_eq!(plain.files.len() + 4, generated.files.len());
}

#[test]
fn storage_bound_covers_the_solver() {
    // size_of of the ABI's Slot (magic, last solution, Mpc) for N = 30, NX = 12, NU = 4, measured
    // with `<name>_storage_size()` on thumbv7em-none-eabihf (4-byte usize) and x86-64 (8-byte):
    // condensed f64 310 328 / 310 816 B (the qp's NV + 1 index words), riccati f64 94 760 B
    // (no usize); the generated crates' compile-time assertions check the same on every build.
    // The bound covers the solver on both, and exceeds it by at most storage_slack.
    for (qp, sizes) in [
        (QpMethod::Condensed, [310_328, 310_816]),
        (QpMethod::Riccati, [94_760, 94_760]),
    ] {
        let bound = storage_bound(12, 4, 30, Float::F64, qp);
        assert_eq!(bound % 64, 0);
        for size in sizes {
            assert!(
                size <= bound && bound <= size + storage_slack(size),
                "{qp:?}: {bound} for {size}"
            );
        }
    }
    // Hand count of the riccati solver's reals: 5·31·12 + 16·30·4 + 4 + 30·144 + 2·30·48 + 30·12 +
    // 30·16 + 12 = 11 836 reals = 94 688 B (f64), + 48 B of the ABI's header: the bound is that
    // plus 64, 1/64 and 512, rounded up to 64.
    assert_eq!(
        storage_bound(12, 4, 30, Float::F64, QpMethod::Riccati),
        (94_688 + 48 + 64 + (94_688 + 48 + 64) / 64 + 512usize).div_ceil(64) * 64
    );
    let f32_bound = storage_bound(12, 4, 30, Float::F32, QpMethod::Condensed);
    assert!((154_360 + 64..162_000).contains(&f32_bound), "{f32_bound}");
}

#[test]
fn f32_crate_builds_its_staticlib_and_runs_from_c() {
    for tool in ["gcc"] {
        if Command::new(tool).arg("--version").output().is_err() {
            println!("SKIPPED f32_crate_builds_its_staticlib_and_runs_from_c: `{tool}` is not installed");
            return;
        }
    }
    let options = GenerateOptions {
        horizon: 12,
        float: Float::F32,
        crate_name: Some("hover_f32_capi_test".into()),
        c_api: true,
        ..GenerateOptions::default()
    };
    let generated = generate(&shipped("pd_hover"), &options).unwrap();
    // Outside the uavgen workspace (a package below it would have to be a member); the build
    // products in the workspace's target/tmp, kept between runs.
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let out = root.join("hover_f32_capi_test");
    write_all(&out, &generated.files).unwrap();
    let header = fs::read_to_string(out.join("include/hover_f32_capi_test.h")).unwrap();
    assert!(header.contains("typedef float hover_f32_capi_test_real;"));
    assert!(header.contains("#define HOVER_F32_CAPI_TEST_N 12"));
    let target = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("c-api-f32-target");
    let build = Command::new(env!("CARGO"))
        .args(["build", "--release", "--quiet", "--offline", "--target-dir"])
        .arg(&target)
        .current_dir(out.join("capi"))
        .output()
        .unwrap();
    assert!(
        build.status.success(),
        "the capi package did not build:\n{}",
        String::from_utf8_lossy(&build.stderr)
    );
    let c = r#"
#include <stdio.h>
#include "hover_f32_capi_test.h"
static hover_f32_capi_test_storage storage;
int main(void) {
    hover_f32_capi_test_real x[HOVER_F32_CAPI_TEST_NX] = {0}, u[HOVER_F32_CAPI_TEST_NU] = {0};
    hover_f32_capi_test_real lo[HOVER_F32_CAPI_TEST_NU] = HOVER_F32_CAPI_TEST_U_MIN;
    hover_f32_capi_test_real hi[HOVER_F32_CAPI_TEST_NU] = HOVER_F32_CAPI_TEST_U_MAX;
    hover_f32_capi_test_real r[(HOVER_F32_CAPI_TEST_N + 1) * HOVER_F32_CAPI_TEST_NX] = {0};
    for (int k = 0; k <= HOVER_F32_CAPI_TEST_N; k++) r[k * HOVER_F32_CAPI_TEST_NX + 2] = 1.0f;
    if (hover_f32_capi_test_storage_size() > sizeof storage) return 2;
    if (hover_f32_capi_test_init(&storage, sizeof storage, x, u) != HOVER_F32_CAPI_TEST_OK) return 3;
    for (int k = 0; k < 60; k++) {
        hover_f32_capi_test_status s = hover_f32_capi_test_solve(&storage, x, r, u);
        if (s < 0) return 4;
        for (int i = 0; i < HOVER_F32_CAPI_TEST_NU; i++) if (!(u[i] >= lo[i] && u[i] <= hi[i])) return 5;
        hover_f32_capi_test_real next[HOVER_F32_CAPI_TEST_NX];
        if (hover_f32_capi_test_discrete_dynamics(x, u, next) != HOVER_F32_CAPI_TEST_OK) return 6;
        for (int i = 0; i < HOVER_F32_CAPI_TEST_NX; i++) x[i] = next[i];
        hover_f32_capi_test_shift(&storage);
    }
    printf("%.6f\n", (double)x[2]);
    return 0;
}
"#;
    fs::write(root.join("main.c"), c).unwrap();
    let binary = root.join("main");
    let gcc = Command::new("gcc")
        .args(["-std=c11", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-I"])
        .arg(out.join("include"))
        .arg(root.join("main.c"))
        .arg(target.join("release/libhover_f32_capi_test_capi.a"))
        .args(["-lgcc_s", "-lutil", "-lrt", "-lpthread", "-lm", "-ldl", "-lc", "-o"])
        .arg(&binary)
        .output()
        .unwrap();
    assert!(gcc.status.success(), "gcc:\n{}", String::from_utf8_lossy(&gcc.stderr));
    let run = Command::new(&binary).output().unwrap();
    assert!(run.status.success(), "the C program exited with {:?}", run.status);
    let z: f64 = String::from_utf8_lossy(&run.stdout).trim().parse().unwrap();
    assert!((z - 1.0).abs() < 0.1, "climbed to z = {z}, not to the 1 m setpoint");
}

#[test]
fn the_cli_flag_writes_the_header_and_the_package() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m");
    let model = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/pd_hover.json");
    let run = Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .arg("--model")
        .arg(&model)
        .args([
            "--horizon",
            "5",
            "--substeps",
            "1",
            "--crate-name",
            "my-hover",
            "--c-api",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{stdout}{}", String::from_utf8_lossy(&run.stderr));
    // `-` in the crate name becomes `_` in C identifiers and in the library's name.
    assert!(
        stdout.contains("include/my_hover.h") && stdout.contains("libmy_hover_capi.a"),
        "{stdout}"
    );
    let header = fs::read_to_string(out.join("include/my_hover.h")).unwrap();
    assert!(header.contains("#define MY_HOVER_N 5") && header.contains("my_hover_status my_hover_solve("));
    let manifest = fs::read_to_string(out.join("capi/Cargo.toml")).unwrap();
    assert!(manifest.contains("name = \"my-hover_capi\"") && manifest.contains("my-hover = { path = \"..\" }"));
    assert!(fs::read_to_string(out.join("capi/src/ffi.rs"))
        .unwrap()
        .contains("use my_hover::{"));
    // Without the flag: no header, no package.
    let plain = dir.path().join("plain");
    let run = Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .arg("--model")
        .arg(&model)
        .args(["--horizon", "5", "--substeps", "1", "--out"])
        .arg(&plain)
        .output()
        .unwrap();
    assert!(run.status.success());
    assert!(!plain.join("include").exists() && !plain.join("capi").exists());
}

#[test]
fn the_header_quotes_the_measured_stack_bounds_only_for_the_measured_crate() {
    // generated/stack-bounds.json (scripts/stack_bounds.sh) covers sindy_m100 as regenerate.sh makes it
    // (default options + --c-api): every ABI function gets a <NAME>_STACK_ define, init's ≤ 2 KiB.
    let options = GenerateOptions {
        c_api: true,
        ..GenerateOptions::default()
    };
    let generated = generate(&shipped("sindy_m100"), &options).unwrap();
    let header = file(&generated.files, "include/sindy_m100.h");
    for f in template_functions() {
        assert!(
            header.contains(&format!("#define SINDY_M100_STACK_{} ", f.to_ascii_uppercase())),
            "no stack bound for {f}"
        );
    }
    let init: u64 = header
        .lines()
        .find_map(|l| l.strip_prefix("#define SINDY_M100_STACK_INIT "))
        .and_then(|v| v.trim().parse().ok())
        .expect("SINDY_M100_STACK_INIT");
    assert!((64..=2048).contains(&init), "{init}");
    let readme = file(&generated.files, "README.md");
    assert!(readme.contains("| `Mpc::feedback` |"), "{readme}");
    // Another horizon is another crate: not measured, and the header says so instead of guessing.
    let other = generate(&shipped("sindy_m100"), &GenerateOptions { horizon: 20, ..options }).unwrap();
    let header = file(&other.files, "include/sindy_m100.h");
    assert!(!header.contains("_STACK_"), "{header}");
    assert!(header.contains("Stack: not measured for this crate"));
    assert!(file(&other.files, "README.md").contains("Not measured for this crate."));
}
