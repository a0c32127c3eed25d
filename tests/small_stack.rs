//! Stack use on small host threads (issue 28, docs/c-api.md "Stack"): the solver lives in caller
//! storage (the C ABI's buffer, a `Box` in Rust), and
//!
//! - `<name>_init` / `Mpc::initialize` run on a 16 KiB thread (glibc's smallest, PTHREAD_STACK_MIN):
//!   `init` writes the solver in place, it does not build a solver-sized value in its frame first
//!   (310 KB before: a segfault here);
//! - prepare + feedback + shift run on a 32 KiB thread, for the condensed (sindy_m100) and the
//!   stage-wise (sindy_m100_riccati) solvers, through the C ABI and the Rust API, f64 and f32.
//!
//! A thread that overflows its stack hits the guard page and kills the test process (SIGSEGV):
//! these tests cannot pass by accident. The thumbv7em bounds of every function are measured by
//! scripts/stack_bounds.sh (docs/generated-api.md, "Stack").

use std::thread;

use sindy_m100_capi as capi;
use sindy_m100_riccati_capi as rcapi;

const INIT_STACK: usize = 16 * 1024;
const STEP_STACK: usize = 32 * 1024;

/// Run `f` on a thread with `bytes` of stack and return its result.
fn on_stack<T: Send + 'static>(bytes: usize, f: impl FnOnce() -> T + Send + 'static) -> T {
    thread::Builder::new()
        .stack_size(bytes)
        .spawn(f)
        .expect("spawn a small-stack thread")
        .join()
        .expect("the small-stack thread finished")
}

/// Hover at (1, 2, 3), and a reference window from there moving along x; the window on the heap,
/// so that the test's own frames stay small (the solver's are measured).
fn hover<const NX: usize, const N1: usize>() -> ([f64; NX], Box<[[f64; NX]; N1]>) {
    let mut x = [0.0; NX];
    x[0] = 1.0;
    x[1] = 2.0;
    x[2] = 3.0;
    let mut r = Box::new([x; N1]);
    for (k, row) in r.iter_mut().enumerate() {
        row[0] += 0.01 * k as f64;
    }
    (x, r)
}

/// A zeroed, 16-aligned heap buffer of `bytes` bytes.
fn storage(bytes: usize) -> Vec<u128> {
    vec![0u128; bytes.div_ceil(16)]
}

/// One C ABI: init on a 16 KiB thread, then 3 × (prepare, feedback, shift) on a 32 KiB one.
macro_rules! c_abi_on_small_stacks {
    ($test:ident, $capi:ident, $crate_:ident, $init:ident, $prepare:ident, $feedback:ident, $shift:ident) => {
        #[test]
        fn $test() {
            use $crate_::{N, NU, NX};
            let mut buffer = storage($capi::STORAGE_SIZE);
            // The address travels between threads as an integer; the buffer outlives both threads.
            let at = buffer.as_mut_ptr() as usize;
            let status = on_stack(INIT_STACK, move || {
                let (x0, _) = hover::<NX, { N + 1 }>();
                let u = [0.0; NU];
                // SAFETY: `at` is a 16-aligned, zeroed buffer of STORAGE_SIZE bytes used by this
                // thread alone; x0 and u have NX and NU elements.
                unsafe {
                    $capi::$init(
                        at as *mut core::ffi::c_void,
                        $capi::STORAGE_SIZE,
                        x0.as_ptr(),
                        u.as_ptr(),
                    )
                }
            });
            assert_eq!(status, $capi::status::OK);
            let statuses = on_stack(STEP_STACK, move || {
                let (x0, reference) = hover::<NX, { N + 1 }>();
                let mut u0 = [f64::NAN; NU];
                let mut out = Vec::new();
                for _ in 0..3 {
                    let storage = at as *mut core::ffi::c_void;
                    // SAFETY: the storage was initialised by init above and is used by this
                    // thread alone; the arrays have the documented lengths.
                    unsafe {
                        out.push($capi::$prepare(storage, reference.as_ptr().cast()));
                        out.push($capi::$feedback(storage, x0.as_ptr(), u0.as_mut_ptr()));
                        out.push($capi::$shift(storage));
                    }
                }
                (out, u0)
            });
            let (statuses, u0) = statuses;
            assert!(statuses.iter().all(|&s| s == $capi::status::OK), "{statuses:?}");
            assert!(u0.iter().all(|v| v.is_finite()), "{u0:?}");
            drop(buffer);
        }
    };
}

c_abi_on_small_stacks!(
    condensed_c_abi_runs_on_16_and_32_kib,
    capi,
    sindy_m100,
    sindy_m100_init,
    sindy_m100_prepare,
    sindy_m100_feedback,
    sindy_m100_shift
);
c_abi_on_small_stacks!(
    riccati_c_abi_runs_on_16_and_32_kib,
    rcapi,
    sindy_m100_riccati,
    sindy_m100_riccati_init,
    sindy_m100_riccati_prepare,
    sindy_m100_riccati_feedback,
    sindy_m100_riccati_shift
);

/// One Rust crate: the solver in a `Box` built on the main thread, initialize on a 16 KiB thread,
/// 3 × (prepare, feedback, shift) on a 32 KiB one.
macro_rules! rust_api_on_small_stacks {
    ($test:ident, $crate_:ident, $real:ty) => {
        #[test]
        fn $test() {
            use $crate_::{Mpc, Status, N, NU, NX};
            let mpc = Box::new(Mpc::new());
            let mpc = on_stack(INIT_STACK, move || {
                let mut mpc = mpc;
                let (x0, _) = hover::<NX, { N + 1 }>();
                mpc.initialize(&x0.map(|v| v as $real), &[0.0; NU]);
                mpc
            });
            let (mut mpc, statuses) = on_stack(STEP_STACK, move || {
                let mut mpc = mpc;
                let (x0, reference) = hover::<NX, { N + 1 }>();
                let x0 = x0.map(|v| v as $real);
                let reference = Box::new(reference.map(|row| row.map(|v| v as $real)));
                let mut statuses = Vec::new();
                for _ in 0..3 {
                    statuses.push(mpc.prepare(&reference));
                    let solution = mpc.feedback(&x0);
                    assert!(solution.u0.iter().all(|v| v.is_finite()));
                    statuses.push(solution.status);
                    mpc.shift();
                }
                (mpc, statuses)
            });
            assert!(statuses.iter().all(|s| *s == Status::Solved), "{statuses:?}");
            assert!(mpc.planned_inputs().iter().flatten().all(|v| v.is_finite()));
            mpc.shift();
        }
    };
}

rust_api_on_small_stacks!(condensed_f64_rust_api_runs_on_16_and_32_kib, sindy_m100, f64);
rust_api_on_small_stacks!(riccati_f64_rust_api_runs_on_16_and_32_kib, sindy_m100_riccati, f64);
rust_api_on_small_stacks!(condensed_f32_rust_api_runs_on_16_and_32_kib, pd_hover_f32, f32);

#[test]
fn the_storage_size_matches_the_solver() {
    for (exact, header) in [
        (capi::sindy_m100_storage_size(), capi::STORAGE_SIZE),
        (rcapi::sindy_m100_riccati_storage_size(), rcapi::STORAGE_SIZE),
    ] {
        println!("storage_size() {exact} B, STORAGE_SIZE {header} B");
        assert!(
            exact <= header && header <= exact + exact / 32 + 2048,
            "{exact} vs {header}"
        );
    }
}
