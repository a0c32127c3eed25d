//! `--c-api`: the C ABI of a generated crate (docs/c-api.md).
//!
//! Three files are added to the crate:
//!
//! - `include/<name>.h`: the C header — sizes as `#define`s, the status codes, the caller-owned
//!   storage type (size and alignment) and the prototypes; written here, never by hand;
//! - `capi/Cargo.toml`: package `<name>_capi`, crate types `staticlib` (for C/C++) and `rlib` (for
//!   Rust tests of the ABI), depending on the generated crate by path;
//! - `capi/src/lib.rs`: the `extern "C"` functions. It is the only file of a generated crate with
//!   `unsafe` code (raw pointers from C), each block with a `// SAFETY:` comment; the solver crate
//!   itself stays `#![forbid(unsafe_code)]`.
//!
//! The ABI is a separate package rather than a `staticlib` crate type of the solver crate because
//! cargo builds every crate type of a library even when it is only a dependency: a `staticlib`
//! needs a `#[panic_handler]`, and one in the solver crate would collide with the firmware's own
//! (e.g. `panic-halt`) in every Rust user of the crate.
//!
//! The ABI uses only the public API of `Mpc` (`new`, `initialize`, `set_guess`, `prepare`,
//! `feedback`, `solve`, `shift`, `set_disturbance`, `planned_inputs`, `predicted_states`) and `discrete_dynamics`.

use super::{Float, GenerateOptions, QpMethod};
use crate::model::Model;
use crate::mpc_options::MpcOptions;

/// The template of `capi/src/ffi.rs`.
pub const FFI_RS: &str = include_str!("../../../templates/capi/ffi.rs");

/// Version of the ABI (function set and status codes); `<NAME>_ABI_VERSION` in the header.
pub const ABI_VERSION: u32 = 1;

/// Alignment of the caller-owned storage in bytes (`<NAME>_STORAGE_ALIGN`).
pub const STORAGE_ALIGN: usize = 16;

/// Status codes: `(C suffix, value, meaning)`. 0..=5 are the solver's `Status` (an input is
/// returned and safe to apply); negative codes reject the call, which changes nothing.
pub const STATUS_CODES: &[(&str, i32, &str)] = &[
    ("OK", 0, "the call succeeded (same value as SOLVED)"),
    ("SOLVED", 0, "the QP was solved to optimality"),
    (
        "ITERATION_CAP",
        1,
        "the QP hit MAX_QP_ITERATIONS or MAX_QP_WORK; the best bounded iterate was applied",
    ),
    (
        "HESSIAN_REGULARISED",
        2,
        "the condensed Hessian needed a multiple of I to be positive definite",
    ),
    (
        "INVALID_INPUT",
        3,
        "a non-finite state or reference: the previous plan is kept, u0 is its first input",
    ),
    (
        "NUMERICAL_FAILURE",
        4,
        "a non-finite value in the linearisation or the step: the previous plan is kept",
    ),
    (
        "OUT_OF_ENVELOPE",
        5,
        "x0 or the reference lies outside ENVELOPE_LO..ENVELOPE_HI of the Rust crate (the model's envelope): the input is finite and within the bounds, the plan means nothing",
    ),
    ("NULL_POINTER", -1, "a pointer argument is NULL"),
    (
        "MISALIGNED",
        -2,
        "the storage is not aligned to STORAGE_ALIGN (arrays may have any alignment)",
    ),
    (
        "STORAGE_TOO_SMALL",
        -3,
        "storage_size is smaller than the solver needs (see storage_size())",
    ),
    (
        "NOT_INITIALISED",
        -4,
        "the storage was not initialised by init() of this model",
    ),
    ("OVERLAP", -5, "an array argument overlaps the storage"),
    ("NO_SOLUTION", -6, "no feedback() or solve() since init()"),
];

/// `<NAME>_STORAGE_SIZE`: the solver state's size in bytes, from the sizes and the QP solver.
///
/// The generator does not compile the crate, so it cannot know `size_of::<Slot>()` exactly; it
/// counts the fields of the template's `Mpc` (and of its QP solver's workspace), which are all
/// arrays of reals sized by NX, NU, N and NV = N·NU:
///
/// - condensed (`mpc.rs` + `qp.rs`): guess, reference, free response ((N+1)·NX each), inputs
///   (N·NU), u₋₁ (NU), Aₖ (N·NX²), Bₖ and the condensing's chains (N·NX·NU each), cₖ (N·NX), the
///   Hessian and the QP's factor (NV² each), 9 vectors of NV, the disturbance (NX); NV + 1 index
///   words (counted as 8 bytes, the largest `usize`) and 2·NV bytes of bound states and groups;
/// - riccati (`mpc_riccati.rs` + `riccati.rs`): 5 trajectories of (N+1)·NX (guess, reference,
///   defects' workspace, the IPM's x and dx), 16 of N·NU (inputs, box, the IPM's iterate,
///   direction, corrector and steps), u₋₁ (NU), Aₖ (N·NX²), Bₖ and the
///   feedback gains (N·NX·NU each), cₖ (N·NX), the input Hessians' factors (N·NU²), the
///   disturbance (NX);
///
/// plus the C ABI's own header (magic number, the latest input, status, iterations and cost) and
/// 64 bytes of flags and padding, with a headroom of 1/64 and 512 bytes (rounded up to 64), so that
/// a few more fields in the template do not break the build. `capi/src/lib.rs` asserts at compile
/// time that the solver fits (a solver that outgrows the figure fails to build instead of overrunning
/// the caller's buffer) and that the figure is at most 1/32 + 2 KiB above the solver's real size
/// (the caller's buffer is not wasted); `<name>_storage_size()` returns the exact size at run time.
pub fn storage_bound(nx: usize, nu: usize, n: usize, float: Float, qp: QpMethod) -> usize {
    let nv = n * nu;
    let (reals, words, bytes) = match qp {
        QpMethod::Condensed => (
            3 * (n + 1) * nx + n * nu + nu + n * nx * nx + 2 * n * nx * nu + n * nx + 2 * nv * nv + 9 * nv + nx,
            nv + 1,
            2 * nv,
        ),
        QpMethod::Riccati => (
            5 * (n + 1) * nx + 16 * n * nu + nu + n * nx * nx + 2 * n * nx * nu + n * nx + n * nu * nu + nx,
            0,
            0,
        ),
    };
    let real = match float {
        Float::F64 => 8,
        Float::F32 => 4,
    };
    // The ABI's header: the magic number, and `Last` (u0, status, iterations, cost).
    let abi = 8 + real * (nu + 1) + 8;
    let size = real * reals + 8 * words + bytes + abi + 64;
    (size + size / 64 + 512).div_ceil(64) * 64
}

/// How much `STORAGE_SIZE` may exceed the solver's real size (`size_of::<Slot>()`), asserted at
/// compile time by `capi/src/lib.rs`: 1/32 of it and 2 KiB.
pub fn storage_slack(size: usize) -> usize {
    size / 32 + 2048
}

/// The identifier prefix of the C symbols: the crate name with `-` as `_`.
pub fn prefix(crate_name: &str) -> String {
    crate_name.replace('-', "_")
}

/// The magic number that marks initialised storage: the first 8 bytes of the model's SHA-256,
/// so storage initialised by another model's `init` is refused too.
fn magic(model: &Model) -> u64 {
    let hex = model.source.sha256.get(..16).unwrap_or("");
    u64::from_str_radix(hex, 16).unwrap_or(0x7561_7667_656e_0001) | 1
}

fn c_float(value: f64, float: Float) -> String {
    match float {
        Float::F64 => {
            let s = format!("{value:?}");
            if s.contains(['.', 'e', 'E']) {
                s
            } else {
                format!("{s}.0")
            }
        }
        Float::F32 => {
            let s = format!("{:?}", value as f32);
            let s = if s.contains(['.', 'e', 'E']) {
                s
            } else {
                format!("{s}.0")
            };
            format!("{s}f")
        }
    }
}

fn c_array(values: &[f64], float: Float) -> String {
    let items: Vec<String> = values.iter().map(|&v| c_float(v, float)).collect();
    format!("{{ {} }}", items.join(", "))
}

fn c_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_ascii() && !c.is_ascii_control() => out.push(c),
            c => {
                let mut buf = [0u8; 4];
                for b in c.encode_utf8(&mut buf).bytes() {
                    out.push_str(&format!("\\{b:03o}"));
                }
            }
        }
    }
    out.push('"');
    out
}

/// Everything about a model the C header and the ABI crate need.
pub struct CApi<'a> {
    pub crate_name: &'a str,
    /// The QP solver the crate carries (its storage differs).
    pub qp: QpMethod,
    pub model: &'a Model,
    pub options: &'a GenerateOptions,
    pub mpc: &'a MpcOptions,
    pub substeps: usize,
    pub header: &'a [String],
}

impl CApi<'_> {
    fn sizes(&self) -> (usize, usize, usize) {
        (self.model.nx(), self.model.nu(), self.options.horizon)
    }

    /// The files to add to the generated crate.
    pub fn files(&self) -> Result<Vec<(std::path::PathBuf, String)>, String> {
        let p = prefix(self.crate_name);
        let rs_header: String = self.header.iter().map(|l| format!("// {l}\n")).collect();
        let ffi = self.ffi_rs()?;
        syn::parse_file(&ffi).map_err(|e| format!("capi/src/ffi.rs does not parse: {e}"))?;
        Ok(vec![
            (format!("include/{p}.h").into(), self.header_h()),
            ("capi/Cargo.toml".into(), self.cargo_toml()),
            ("capi/src/lib.rs".into(), rs_header.clone() + &self.lib_rs()),
            ("capi/src/ffi.rs".into(), rs_header + &ffi),
        ])
    }

    fn cargo_toml(&self) -> String {
        let head: String = self.header.iter().map(|l| format!("# {l}\n")).collect();
        format!(
            "{head}[package]\nname = \"{name}_capi\"\nversion = \"0.1.0\"\nedition = \"2021\"\npublish = false\n\
             description = \"C ABI (staticlib) of the uavgen-generated MPC crate {name}\"\n\n\
             # staticlib: lib{lib}_capi.a for C and C++; rlib: Rust tests of the ABI.\n\
             [lib]\ncrate-type = [\"staticlib\", \"rlib\"]\ndoctest = false\n\n\
             [features]\n\
             # A halting #[panic_handler] instead of std's (which prints and aborts). On by itself on\n\
             # targets without an OS (target_os = \"none\"); turn it on for other targets without std.\n\
             panic-handler = []\n\n\
             [dependencies]\n{name} = {{ path = \"..\" }}\n",
            name = self.crate_name,
            lib = prefix(self.crate_name),
        )
    }

    /// `include/<name>.h`.
    pub fn header_h(&self) -> String {
        let p = prefix(self.crate_name);
        let up = p.to_ascii_uppercase();
        let (nx, nu, n) = self.sizes();
        let float = self.options.float;
        let real = match float {
            Float::F64 => "double",
            Float::F32 => "float",
        };
        let storage = storage_bound(nx, nu, n, float, self.qp);
        let mut h = String::new();
        for l in self.header {
            h.push_str(&format!("/* {} */\n", l.replace("*/", "* /")));
        }
        let model = self.model;
        let states = model.states.join(", ");
        let inputs = model.inputs.join(", ");
        let names = |v: &[String]| v.iter().map(|s| c_string(s)).collect::<Vec<_>>().join(", ");
        // As the Rust crate's INPUT_DELAY_SAMPLES and INPUT_LEAD.
        let delay_samples = crate::ir::delay_samples(&model.input_delays(), 1.0 / self.options.rate_hz);
        let input_lead = crate::ir::input_lead(&delay_samples);
        let int_array = |v: &[usize]| {
            format!(
                "{{ {} }}",
                v.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")
            )
        };
        h.push_str(&format!(
            r#"
/*
 * C ABI of the uavgen-generated MPC crate `{crate_name}` (model `{model_name}`), see uavgen's
 * docs/c-api.md. Link with lib{p}_capi.a, built by
 *     cargo build --release --manifest-path capi/Cargo.toml [--target thumbv7em-none-eabihf]
 *
 * x = [{states}]
 * u = [{inputs}]
 * Arrays are row-major: reference[k * {up}_NX + i] is state i at stage k. They may have any
 * alignment but must not overlap the storage. The caller owns the storage (static, stack or heap;
 * aligned to {up}_STORAGE_ALIGN, zero-filled or initialised by {p}_init) and must not use one
 * storage from two threads at once. Every function checks its pointers: NULL, a misaligned or
 * uninitialised storage and overlapping arrays are refused with a negative status and change
 * nothing. Status 0..5 (the solver's) means an input was produced and is safe to apply: finite and
 * within [U_MIN, U_MAX] whatever the status. No function allocates, blocks or panics.
 */
#ifndef {up}_H
#define {up}_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {{
#endif

#define {up}_ABI_VERSION {abi}
#define {up}_MODEL_NAME {model_name_c}
#define {up}_MODEL_SHA256 "{sha}"

/* Sizes. */
#define {up}_NX {nx}
#define {up}_NU {nu}
#define {up}_N {n}
/* Sample period in seconds (1 / {rate} Hz) and RK4 substeps per sample. */
#define {up}_DT {dt}
#define {up}_SUBSTEPS {substeps}
/* Initialisers: `static const char *names[{up}_NX] = {up}_STATE_NAMES;` */
#define {up}_STATE_NAMES {{ {state_names} }}
#define {up}_INPUT_NAMES {{ {input_names} }}
/* Input bounds (initialisers of {p}_real[{up}_NU]). */
#define {up}_U_MIN {u_min}
#define {up}_U_MAX {u_max}
/* Input delays in samples (the model's corrections.latency, rounded) and each input's lead over the
 * delay all inputs share (initialisers of int[{up}_NU]). Give the solver the state predicted over
 * the shared delay min(INPUT_DELAY_SAMPLES) with the inputs already sent; the solver handles the
 * leads (it holds each input's commands already sent and returns the one for now). uavgen's
 * docs/runtime.md, "Input delays". */
#define {up}_INPUT_DELAY_SAMPLES {delay_samples}
#define {up}_INPUT_LEAD {input_lead}
/* Offset-free tracking: the disturbance observer's gain L and its bound b[i] on |e_i| per sample
 * (initialiser of {p}_real[{up}_NX]; 0: state i not estimated). At each fresh measurement x (one
 * that differs from the last), m samples after the last, with x_hat the prediction
 * x_hat = F(x_hat, u_acted) + e run from it: e_i = clamp(e_i + L (x_i - x_hat_i) / m, -b_i, b_i);
 * then {p}_set_disturbance(e) before the next prepare. uavgen's docs/mpc.md, "Offset-free tracking". */
#define {up}_DISTURBANCE_GAIN {disturbance_gain}
#define {up}_DISTURBANCE_BOUND {disturbance_bound}

/* Caller-owned solver storage: the solver's size with a little headroom (at most 1/32 + 2 KiB above
 * it, checked when the library is built; {p}_storage_size() returns the exact size) and its alignment. */
#define {up}_STORAGE_SIZE {storage}
#define {up}_STORAGE_ALIGN {align}

{stack}
typedef {real} {p}_real;

#if defined(__cplusplus)
#define {up}_ALIGNAS(n) alignas(n)
#else
#define {up}_ALIGNAS(n) _Alignas(n)
#endif

typedef struct {p}_storage {{
    {up}_ALIGNAS({up}_STORAGE_ALIGN) unsigned char bytes[{up}_STORAGE_SIZE];
}} {p}_storage;

/* Status codes: 0..5 are the solver's statuses (an input was produced); negative codes reject the
 * call and change nothing. */
typedef int32_t {p}_status;
enum {p}_status_code {{
{codes}}};

"#,
            crate_name = self.crate_name,
            model_name = model.name.replace("*/", "* /"),
            model_name_c = c_string(&model.name),
            sha = model.source.sha256,
            abi = ABI_VERSION,
            rate = self.options.rate_hz,
            dt = c_float(1.0 / self.options.rate_hz, Float::F64),
            substeps = self.substeps,
            state_names = names(&model.states),
            input_names = names(&model.inputs),
            u_min = c_array(&self.mpc.u_min, float),
            u_max = c_array(&self.mpc.u_max, float),
            delay_samples = int_array(&delay_samples),
            input_lead = int_array(&input_lead),
            disturbance_gain = c_float(self.mpc.disturbance_gain, float),
            disturbance_bound = c_array(
                &self.mpc.disturbance_bound(&model.states, 1.0 / self.options.rate_hz),
                float
            ),
            align = STORAGE_ALIGN,
            stack = super::stack_bounds::header_defines(self.crate_name, self.header),
            codes = STATUS_CODES
                .iter()
                .map(|(name, value, doc)| format!("    {up}_{name} = {value}, /* {doc} */\n"))
                .collect::<String>(),
        ));
        let r = format!("{p}_real");
        let s = format!("{p}_storage");
        let st = format!("{p}_status");
        let protos: Vec<(String, String)> = vec![
            (
                "Exact size and alignment of the solver state in bytes (at most STORAGE_SIZE and STORAGE_ALIGN).".into(),
                format!("size_t {p}_storage_size(void);\nsize_t {p}_storage_align(void);"),
            ),
            (
                "Initialise the storage: the guess x_k = x0 for all k and u_k = u (clamped into the bounds).\n\
                 storage_size: sizeof the storage (at least storage_size()). INVALID_INPUT if x0 or u is not\n\
                 finite (the storage is then initialised with an all-zero guess)."
                    .into(),
                format!("{st} {p}_init({s} *storage, size_t storage_size, const {r} x0[{up}_NX], const {r} u[{up}_NU]);"),
            ),
            (
                "Set the whole guess: xs[(N+1)*NX], us[N*NU] (inputs clamped).\nINVALID_INPUT, changing nothing, if a value is not finite.".into(),
                format!("{st} {p}_set_guess({s} *storage, const {r} xs[({up}_N + 1) * {up}_NX], const {r} us[{up}_N * {up}_NU]);"),
            ),
            (
                "Linearise along the guess, condense and factorise for reference[(N+1)*NX]: all the work that\ndoes not need the measurement (run it after shift, while waiting for the next state).".into(),
                format!("{st} {p}_prepare({s} *storage, const {r} reference[({up}_N + 1) * {up}_NX]);"),
            ),
            (
                "Finish the step with the measured state x0 (QP, guess update): the input to apply now goes to u0.".into(),
                format!("{st} {p}_feedback({s} *storage, const {r} x0[{up}_NX], {r} u0[{up}_NU]);"),
            ),
            (
                "prepare + feedback.".into(),
                format!("{st} {p}_solve({s} *storage, const {r} x0[{up}_NX], const {r} reference[({up}_N + 1) * {up}_NX], {r} u0[{up}_NU]);"),
            ),
            (
                "Move the guess and the stored reference one sample ahead (call after applying u0, before the next prepare).".into(),
                format!("{st} {p}_shift({s} *storage);"),
            ),
            (
                "Predict with x_{k+1} = F(x_k, u_k) + e from the next prepare on: offset-free tracking, e estimated\n\
                 by the caller's disturbance observer (DISTURBANCE_GAIN, DISTURBANCE_BOUND above). INVALID_INPUT,\n\
                 changing nothing, if a value is not finite."
                    .into(),
                format!("{st} {p}_set_disturbance({s} *storage, const {r} e[{up}_NX]);"),
            ),
            (
                "The latest feedback/solve: its status, input, QP iterations and cost. Before the first,\n\
                 last_status returns NO_SOLUTION and the others return it without writing anything."
                    .into(),
                format!(
                    "{st} {p}_last_status(const {s} *storage);\n\
                     {st} {p}_first_input(const {s} *storage, {r} u0[{up}_NU]);\n\
                     {st} {p}_qp_iterations(const {s} *storage, uint32_t *iterations);\n\
                     {st} {p}_cost(const {s} *storage, {r} *cost);"
                ),
            ),
            (
                "The plan of the current guess: inputs u_0..u_{N-1} and predicted states x_0..x_N.".into(),
                format!(
                    "{st} {p}_planned_inputs(const {s} *storage, {r} us[{up}_N * {up}_NU]);\n\
                     {st} {p}_predicted_states(const {s} *storage, {r} xs[({up}_N + 1) * {up}_NX]);"
                ),
            ),
            (
                "The model's discrete dynamics x_next = F(x, u) over one sample DT (no storage needed).".into(),
                format!("{st} {p}_discrete_dynamics(const {r} x[{up}_NX], const {r} u[{up}_NU], {r} x_next[{up}_NX]);"),
            ),
        ];
        for (doc, proto) in protos {
            let lines: Vec<&str> = doc.lines().collect();
            for (i, l) in lines.iter().enumerate() {
                let open = if i == 0 { "/* " } else { " * " };
                let close = if i + 1 == lines.len() { " */" } else { "" };
                h.push_str(&format!("{open}{l}{close}\n"));
            }
            h.push_str(&proto);
            h.push_str("\n\n");
        }
        h.push_str(&format!(
            "#ifdef __cplusplus\n}} /* extern \"C\" */\n#endif\n\n#endif /* {up}_H */\n"
        ));
        h
    }

    /// `capi/src/lib.rs`: the crate root (no `unsafe`): docs, the panic handler, the `ffi` module.
    fn lib_rs(&self) -> String {
        let p = prefix(self.crate_name);
        format!(
            r#"//! C ABI of the uavgen-generated MPC crate `{p}`: the functions of `include/{p}.h`, as
//! `lib{p}_capi.a` (uavgen's docs/c-api.md).
//!
//! Build it with `cargo build --release --manifest-path capi/Cargo.toml`, for a flight controller
//! with `--target thumbv7em-none-eabihf` too. `no_std` and no allocation: the caller owns the
//! solver's storage. On a hosted target the library links `std` only for its panic handler (print,
//! then abort the process); on `target_os = "none"`, or with the feature `panic-handler`, a panic
//! halts in a loop. The ABI cannot reach a panic: every pointer is checked, every index is in
//! range by construction.
//!
//! All `unsafe` code is in `src/ffi.rs`.
#![no_std]
#![deny(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

#[cfg(not(any(target_os = "none", feature = "panic-handler")))]
extern crate std;

#[rustfmt::skip]
mod ffi;

pub use ffi::*;

/// No ABI function can panic; should one ever, halt: there is no OS to abort to.
#[cfg(any(target_os = "none", feature = "panic-handler"))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {{
    loop {{
        core::hint::spin_loop();
    }}
}}
"#
        )
    }

    /// `capi/src/ffi.rs`: the template with the model's names and values.
    fn ffi_rs(&self) -> Result<String, String> {
        let p = prefix(self.crate_name);
        let (nx, nu, n) = self.sizes();
        let codes: String = STATUS_CODES
            .iter()
            .map(|(name, value, doc)| format!("    /// {doc}.\n    pub const {name}: i32 = {value};\n"))
            .collect();
        let real_bytes = match self.options.float {
            Float::F64 => 8,
            Float::F32 => 4,
        };
        let mut text = FFI_RS.replace("uavgen_model", &p);
        for (key, value) in [
            ("@STATUS_CODES@", codes),
            (
                "@STORAGE_SIZE@",
                storage_bound(nx, nu, n, self.options.float, self.qp).to_string(),
            ),
            ("@STORAGE_ALIGN@", STORAGE_ALIGN.to_string()),
            ("@NX@", nx.to_string()),
            ("@NU@", nu.to_string()),
            ("@N@", n.to_string()),
            ("@REAL_BYTES@", real_bytes.to_string()),
            ("@MAGIC@", format!("{:#018x}", magic(self.model))),
        ] {
            if !text.contains(key) {
                return Err(format!("templates/capi/ffi.rs has no placeholder {key}"));
            }
            text = text.replace(key, &value);
        }
        // Every placeholder is `@` + capitals and `_` + `@`: none may be left.
        let left = text
            .split('@')
            .skip(1)
            .step_by(2)
            .find(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_uppercase() || c == '_'));
        if let Some(w) = left {
            return Err(format!("templates/capi/ffi.rs: placeholder @{w}@ has no value"));
        }
        Ok(text)
    }
}
