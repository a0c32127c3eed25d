//! The C ABI of `uavgen --c-api` (docs/c-api.md), on the shipped generated/sindy_m100:
//!
//! - examples/c is built with gcc against `include/sindy_m100.h` and `libsindy_m100_capi.a`, runs
//!   its 900-sample closed loop, and every input it prints must equal the Rust solver's on the same
//!   loop to 1e-12 (statuses and QP iterations exactly);
//! - the ABI refuses bad pointers with its status codes, called from Rust through the capi rlib;
//! - examples/cpp builds with g++: the flight-stack-agnostic wrapper runs its host check, the PX4
//!   module skeleton compiles against its stubs.

use std::path::Path;
use std::process::Command;

use sindy_m100::{discrete_dynamics, Mpc, Real, Status, N, NU, NX, U_MAX, U_MIN};
use sindy_m100_capi as capi;
use sindy_m100_capi::status;

const STEPS: usize = 900;
const SEGMENT: usize = 150;
const RAMP: usize = 60;
/// Waypoints (x, y, z, yaw) of examples/c/closed_loop.c.
const WAYPOINTS: [[Real; 4]; 8] = [
    [0.0, 0.0, 0.0, 0.0],
    [1.0, 0.0, 0.5, 0.0],
    [1.0, 1.0, 0.5, 0.5],
    [0.0, 1.0, 1.0, 1.0],
    [-1.0, 0.0, 0.5, 0.5],
    [-0.5, -0.5, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0],
];
const POSITION_STATES: [usize; 4] = [0, 1, 2, 5];

/// `reference_at` of closed_loop.c, operation for operation.
fn reference_at(k: usize) -> [Real; NX] {
    let mut segment = k / SEGMENT;
    let into = k % SEGMENT;
    let mut s = into.min(RAMP) as Real / RAMP as Real;
    if segment > 6 {
        segment = 6;
        s = 1.0;
    }
    let mut r = [0.0; NX];
    for i in 0..4 {
        let (a, b) = (WAYPOINTS[segment][i], WAYPOINTS[segment + 1][i]);
        r[POSITION_STATES[i]] = a + (b - a) * s;
    }
    r
}

fn window_at(k: usize) -> [[Real; NX]; N + 1] {
    core::array::from_fn(|j| reference_at(k + j))
}

fn status_code(s: Status) -> i32 {
    match s {
        Status::Solved => status::SOLVED,
        Status::IterationCap => status::ITERATION_CAP,
        Status::HessianRegularised => status::HESSIAN_REGULARISED,
        Status::InvalidInput => status::INVALID_INPUT,
        Status::NumericalFailure => status::NUMERICAL_FAILURE,
        Status::OutOfEnvelope => status::OUT_OF_ENVELOPE,
    }
}

/// One sample of the loop: (status, QP iterations, u).
type Step = (i32, u32, [Real; NU]);

/// The loop of closed_loop.c through the Rust API; the steps and the final state.
fn rust_loop() -> (Vec<Step>, [Real; NX]) {
    let mut mpc = Box::new(Mpc::new());
    let mut x = [0.0; NX];
    (x[0], x[1], x[2]) = (-0.5, 0.3, -0.2);
    mpc.initialize(&x, &[0.0; NU]);
    assert_eq!(mpc.prepare(&window_at(0)), Status::Solved);
    let mut steps = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        let s = mpc.feedback(&x);
        steps.push((status_code(s.status), s.qp_iterations as u32, s.u0));
        x = discrete_dynamics(&x, &s.u0);
        mpc.shift();
        mpc.prepare(&window_at(k + 1));
    }
    (steps, x)
}

fn parse_c_output(stdout: &str) -> Vec<Step> {
    stdout
        .lines()
        .filter(|l| l.starts_with("step "))
        .map(|line| {
            let f: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(f.len(), 4 + NU, "line {line:?}");
            let u: [Real; NU] = core::array::from_fn(|i| f[4 + i].parse().unwrap_or_else(|e| panic!("{line}: {e}")));
            (f[2].parse().unwrap(), f[3].parse().unwrap(), u)
        })
        .collect()
}

fn tool_missing(tool: &str) -> bool {
    Command::new(tool).arg("--version").output().is_err()
}

/// `make -C examples/<dir>` with the test's own target directory (the workspace's is locked by the
/// `cargo test` running this); the output directory.
fn make_example(dir: &str) -> std::path::PathBuf {
    let root = uavgen_tests::repo_root();
    let target = root.join("target").join("c-abi-test");
    let out = target.join(dir);
    let make = Command::new("make")
        .arg("-C")
        .arg(root.join("examples").join(dir))
        .arg(format!("CARGO_TARGET_DIR={}", target.display()))
        .arg(format!("OUT={}", out.display()))
        .output()
        .expect("run make");
    assert!(
        make.status.success(),
        "make -C examples/{dir} failed:\n{}\n{}",
        String::from_utf8_lossy(&make.stdout),
        String::from_utf8_lossy(&make.stderr)
    );
    out
}

/// Name the first of `tools` that is not installed.
fn missing(tools: &[&str]) -> Option<String> {
    tools.iter().find(|t| tool_missing(t)).map(|t| t.to_string())
}

#[test]
fn c_example_matches_the_rust_solver_over_900_steps() {
    if let Some(tool) = missing(&["gcc", "make"]) {
        println!("SKIPPED c_example_matches_the_rust_solver_over_900_steps: `{tool}` is not installed");
        return;
    }
    let out = make_example("c");
    let binary = out.join("closed_loop");
    let run = Command::new(&binary).output().expect("run the C example");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{} failed:\n{stdout}\n{}",
        binary.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.starts_with("abi-checks ok"), "{stdout}");
    let c = parse_c_output(&stdout);
    let (rust, x) = rust_loop();
    assert_eq!(c.len(), STEPS, "the C example printed {} steps", c.len());
    let mut max_diff: Real = 0.0;
    for (k, (c, r)) in c.iter().zip(&rust).enumerate() {
        assert_eq!((c.0, c.1), (r.0, r.1), "step {k}: (status, QP iterations) C vs Rust");
        for i in 0..NU {
            let d = (c.2[i] - r.2[i]).abs();
            assert!(d <= 1e-12, "step {k}: u[{i}] C {} vs Rust {}", c.2[i], r.2[i]);
            max_diff = max_diff.max(d);
        }
    }
    // The loop must have done something: a tilt of 0.1 rad or more toward the first waypoint (0.6 m
    // away; 0.16 rad with the default input-rate weight, the bound 0.611 without), the last
    // waypoint reached.
    let roll = rust.iter().map(|s| s.2[1].abs()).fold(0.0, Real::max);
    assert!(roll >= 0.1, "largest |u_roll| {roll}");
    let r = reference_at(STEPS);
    let error = ((x[0] - r[0]).powi(2) + (x[1] - r[1]).powi(2) + (x[2] - r[2]).powi(2)).sqrt();
    assert!(error < 0.05, "final position error {error} m");
    println!("C vs Rust over {STEPS} steps: max |Δu| = {max_diff:e}");
}

/// 16-aligned storage on the heap, zero-filled like a C static.
fn zeroed_storage() -> Vec<u128> {
    vec![0u128; capi::STORAGE_SIZE.div_ceil(16) + 1]
}

/// `{ a, b, … }`, a C initialiser.
fn c_ints(v: &[usize]) -> String {
    format!(
        "{{ {} }}",
        v.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")
    )
}

#[test]
fn sizes_fit_the_header() {
    assert!(capi::sindy_m100_storage_size() <= capi::STORAGE_SIZE);
    assert!(capi::sindy_m100_storage_align() <= capi::STORAGE_ALIGN);
    let header = std::fs::read_to_string(uavgen_tests::repo_root().join("generated/sindy_m100/include/sindy_m100.h"))
        .expect("the header");
    for line in [
        format!("#define SINDY_M100_STORAGE_SIZE {}", capi::STORAGE_SIZE),
        format!("#define SINDY_M100_NX {NX}"),
        format!("#define SINDY_M100_NU {NU}"),
        format!("#define SINDY_M100_N {N}"),
        format!("SINDY_M100_NOT_INITIALISED = {},", status::NOT_INITIALISED),
        // The delays a C flight stack compensates, as the Rust crate's (u_vz: 4 samples).
        format!(
            "#define SINDY_M100_INPUT_DELAY_SAMPLES {}",
            c_ints(&sindy_m100::INPUT_DELAY_SAMPLES)
        ),
        format!("#define SINDY_M100_INPUT_LEAD {}", c_ints(&sindy_m100::INPUT_LEAD)),
        format!("#define SINDY_M100_DISTURBANCE_GAIN {:?}", sindy_m100::DISTURBANCE_GAIN),
    ] {
        assert!(header.contains(&line), "the header lacks {line:?}");
    }
}

#[test]
fn the_abi_refuses_bad_pointers_and_changes_nothing() {
    let mut buffer = zeroed_storage();
    let storage = buffer.as_mut_ptr().cast::<core::ffi::c_void>();
    let size = capi::STORAGE_SIZE;
    let x0 = [0.0; NX];
    let u = [0.0; NU];
    let window = window_at(0);
    let mut out = [7.0; NU];
    // SAFETY (all calls below): every pointer is NULL, or points into `buffer` (16-aligned, STORAGE_SIZE
    // + 16 bytes, zero or initialised by init) or to a Rust array of the documented length.
    unsafe {
        assert_eq!(
            capi::sindy_m100_prepare(storage, window.as_ptr().cast()),
            status::NOT_INITIALISED
        );
        assert_eq!(
            capi::sindy_m100_init(core::ptr::null_mut(), size, x0.as_ptr(), u.as_ptr()),
            status::NULL_POINTER
        );
        let misaligned = storage.cast::<u8>().add(4).cast();
        assert_eq!(
            capi::sindy_m100_init(misaligned, size, x0.as_ptr(), u.as_ptr()),
            status::MISALIGNED
        );
        assert_eq!(
            capi::sindy_m100_init(storage, 100, x0.as_ptr(), u.as_ptr()),
            status::STORAGE_TOO_SMALL
        );
        assert_eq!(
            capi::sindy_m100_last_status(storage),
            status::NOT_INITIALISED,
            "nothing was written"
        );
        assert_eq!(
            capi::sindy_m100_init(storage, size, x0.as_ptr(), u.as_ptr()),
            status::OK
        );
        assert_eq!(capi::sindy_m100_last_status(storage), status::NO_SOLUTION);
        assert_eq!(
            capi::sindy_m100_first_input(storage, out.as_mut_ptr()),
            status::NO_SOLUTION
        );
        assert_eq!(out, [7.0; NU], "nothing written before the first solve");
        // An input array inside the storage, an output inside the storage.
        let inside = storage.cast::<u8>().add(size / 2).cast::<Real>();
        assert_eq!(capi::sindy_m100_prepare(storage, inside), status::OVERLAP);
        assert_eq!(capi::sindy_m100_feedback(storage, x0.as_ptr(), inside), status::OVERLAP);
        assert_eq!(
            capi::sindy_m100_feedback(storage, core::ptr::null(), out.as_mut_ptr()),
            status::NULL_POINTER
        );
        assert_eq!(out, [7.0; NU]);
        // A working solve through the ABI equals the Rust API's.
        assert_eq!(
            capi::sindy_m100_solve(storage, x0.as_ptr(), window.as_ptr().cast(), out.as_mut_ptr()),
            status::SOLVED
        );
        let mut mpc = Box::new(Mpc::new());
        mpc.initialize(&x0, &u);
        let rust = mpc.solve(&x0, &window);
        assert_eq!(out, rust.u0);
        let mut plan = [[0.0; NU]; N];
        assert_eq!(
            capi::sindy_m100_planned_inputs(storage, plan.as_mut_ptr().cast()),
            status::OK
        );
        assert_eq!(&plan, mpc.planned_inputs());
        let mut iterations = 0u32;
        assert_eq!(capi::sindy_m100_qp_iterations(storage, &mut iterations), status::OK);
        assert_eq!(iterations as usize, rust.qp_iterations);
        // A NaN state: INVALID_INPUT, and the input is still within the bounds.
        let mut bad = x0;
        bad[4] = Real::NAN;
        assert_eq!(
            capi::sindy_m100_feedback(storage, bad.as_ptr(), out.as_mut_ptr()),
            status::INVALID_INPUT
        );
        assert!((0..NU).all(|i| out[i] >= U_MIN[i] && out[i] <= U_MAX[i]));
        // The disturbance: NULL and NaN refused, a finite one taken as the Rust API takes it.
        let mut e = [0.0; NX];
        e[6] = 0.02;
        assert_eq!(
            capi::sindy_m100_set_disturbance(storage, core::ptr::null()),
            status::NULL_POINTER
        );
        let mut nan = e;
        nan[7] = Real::NAN;
        assert_eq!(
            capi::sindy_m100_set_disturbance(storage, nan.as_ptr()),
            status::INVALID_INPUT
        );
        assert_eq!(capi::sindy_m100_set_disturbance(storage, e.as_ptr()), status::OK);
        assert!(mpc.set_disturbance(&e));
        assert_eq!(
            capi::sindy_m100_solve(storage, x0.as_ptr(), window.as_ptr().cast(), out.as_mut_ptr()),
            status::SOLVED
        );
        assert_eq!(out, mpc.solve(&x0, &window).u0);
        // Unaligned arrays are fine: they are copied with unaligned reads.
        let mut bytes = vec![0u8; NX * 8 + 1];
        let unaligned = bytes.as_mut_ptr().add(1).cast::<Real>();
        let mut next = [0.0; NX];
        assert_eq!(
            capi::sindy_m100_discrete_dynamics(unaligned, u.as_ptr(), next.as_mut_ptr()),
            status::OK
        );
        assert_eq!(next, discrete_dynamics(&[0.0; NX], &u));
    }
    assert!(Path::new(&uavgen_tests::repo_root())
        .join("examples/c/closed_loop.c")
        .exists());
}

#[test]
fn cpp_examples_build_and_the_wrapper_flies() {
    if let Some(tool) = missing(&["g++", "make"]) {
        println!("SKIPPED cpp_examples_build_and_the_wrapper_flies: `{tool}` is not installed");
        return;
    }
    let out = make_example("cpp");
    assert!(
        out.join("uavgen_mpc_module.o").exists(),
        "the PX4 module skeleton did not compile"
    );
    let run = Command::new(out.join("wrapper_check"))
        .output()
        .expect("run wrapper_check");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success() && stdout.starts_with("wrapper-check ok"),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    println!("{}", stdout.trim());
}
