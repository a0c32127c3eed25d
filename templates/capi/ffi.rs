//! The `extern "C"` functions of the header (`include/uavgen_model.h`): the only file of the crate
//! with `unsafe` code.
//!
//! Every pointer from C is checked before it is used: NULL, the storage's alignment and magic
//! number, and overlap of an array with the storage are refused with a negative status, changing
//! nothing. Arrays are then copied in and out with unaligned reads and writes, so they may have any
//! alignment, and the solver only ever sees Rust arrays. One `&mut` to the solver exists per call,
//! created after the inputs were copied and dropped before the outputs are written. Each `unsafe`
//! block states why it is sound; the contract every function relies on is the header's: the
//! storage is zero-filled or initialised by `init`, the arrays have the documented lengths, and one
//! storage is not used from two threads at once.
//!
//! Generated from uavgen's template `templates/capi/ffi.rs`: its placeholder crate name and values
//! replaced by this model's.
// Each function runs its body as a closure so that `?` turns a rejected pointer into its status.
#![allow(clippy::redundant_closure_call)]

use core::ffi::c_void;
use core::mem::{align_of, size_of};
use core::ptr;

use uavgen_model::{discrete_dynamics, Mpc, Real, Solution, Status, N, NU, NX};

/// The status codes of the header (`<NAME>_<CODE>`). 0..=5 are the solver's statuses (an input was
/// produced and is safe to apply); negative codes reject the call, which changes nothing.
pub mod status {
@STATUS_CODES@}

/// `<NAME>_STORAGE_SIZE`: the size of the solver state with a little headroom (at least
/// [`storage_size`](uavgen_model_storage_size), at most 1/32 + 2 KiB more), computed by the
/// generator from the sizes and the QP solver.
pub const STORAGE_SIZE: usize = @STORAGE_SIZE@;
/// `<NAME>_STORAGE_ALIGN`.
pub const STORAGE_ALIGN: usize = @STORAGE_ALIGN@;

// The header was generated for these sizes and this `Real`; the solver must fit its storage. A
// solver that outgrew the bound fails to build here instead of overrunning the caller's buffer.
const _: () = assert!(NX == @NX@ && NU == @NU@ && N == @N@, "the solver's sizes differ from the header's");
const _: () = assert!(size_of::<Real>() == @REAL_BYTES@, "Real differs from the header's typedef");
const _: () = assert!(size_of::<Slot>() <= STORAGE_SIZE, "the solver outgrew STORAGE_SIZE (uavgen: c_api::storage_bound)");
// Nor may the header ask for much more than the solver needs (uavgen: c_api::storage_slack).
const _: () = assert!(
    STORAGE_SIZE <= size_of::<Slot>() + size_of::<Slot>() / 32 + 2048,
    "STORAGE_SIZE is far larger than the solver (uavgen: c_api::storage_bound)"
);
const _: () = assert!(align_of::<Slot>() <= STORAGE_ALIGN, "the solver needs more than STORAGE_ALIGN");

/// Marks storage initialised by this model's `init`: the first 8 bytes of the model's SHA-256.
const MAGIC: u64 = @MAGIC@;

/// The latest feedback or solve.
#[derive(Clone, Copy)]
struct Last {
    u0: [Real; NU],
    status: i32,
    qp_iterations: u32,
    cost: Real,
}

/// What the caller's storage holds; the magic number first, so that it can be checked before the
/// rest is touched.
#[repr(C)]
struct Slot {
    magic: u64,
    last: Last,
    mpc: Mpc,
}

type Result<T> = core::result::Result<T, i32>;

fn code(result: Result<i32>) -> i32 {
    result.unwrap_or_else(|e| e)
}

fn status_code(status: Status) -> i32 {
    match status {
        Status::Solved => status::SOLVED,
        Status::IterationCap => status::ITERATION_CAP,
        Status::HessianRegularised => status::HESSIAN_REGULARISED,
        Status::InvalidInput => status::INVALID_INPUT,
        Status::NumericalFailure => status::NUMERICAL_FAILURE,
        Status::OutOfEnvelope => status::OUT_OF_ENVELOPE,
    }
}

/// Do `bytes` bytes at `p` overlap the storage at `slot` (NULL: no storage)?
fn overlaps<T>(slot: *const Slot, p: *const T, bytes: usize) -> bool {
    let (s, a) = (slot as usize, p as usize);
    !slot.is_null() && a < s.saturating_add(size_of::<Slot>()) && s < a.saturating_add(bytes)
}

/// The storage pointer checked for NULL and alignment (nothing is read).
fn storage_ptr(storage: *const c_void) -> Result<*mut Slot> {
    let slot = storage.cast::<Slot>().cast_mut();
    if slot.is_null() {
        return Err(status::NULL_POINTER);
    }
    if !slot.is_aligned() {
        return Err(status::MISALIGNED);
    }
    Ok(slot)
}

/// The storage pointer, checked as by [`storage_ptr`] and for the magic number.
///
/// # Safety
/// `storage` is NULL or points to at least `size_of::<Slot>()` bytes that are zero or were
/// initialised by `init`.
unsafe fn initialised(storage: *const c_void) -> Result<*mut Slot> {
    let slot = storage_ptr(storage)?;
    // SAFETY: `slot` is non-null and aligned, and by the contract its first 8 bytes are readable
    // and initialised (zero, or the magic number `init` wrote).
    let magic = unsafe { ptr::addr_of!((*slot).magic).read() };
    if magic != MAGIC {
        return Err(status::NOT_INITIALISED);
    }
    Ok(slot)
}

/// Copy a `T` (an array of `Real`s) in from C.
///
/// # Safety
/// `p` is NULL or points to `size_of::<T>()` readable bytes.
unsafe fn read<T: Copy>(slot: *const Slot, p: *const Real) -> Result<T> {
    if p.is_null() {
        return Err(status::NULL_POINTER);
    }
    if overlaps(slot, p, size_of::<T>()) {
        return Err(status::OVERLAP);
    }
    // SAFETY: non-null and readable by the contract; `read_unaligned` needs no alignment, and every
    // bit pattern is a valid array of floats.
    Ok(unsafe { p.cast::<T>().read_unaligned() })
}

/// Check that `size_of::<T>()` bytes may be written at `p`: non-null and outside the storage.
fn writable<T>(slot: *const Slot, p: *mut T) -> Result<()> {
    if p.is_null() {
        return Err(status::NULL_POINTER);
    }
    if overlaps(slot, p, size_of::<T>()) {
        return Err(status::OVERLAP);
    }
    Ok(())
}

/// Copy `value` out to C memory that passed [`writable`].
///
/// # Safety
/// `p` passed [`writable`] and points to `size_of::<T>()` writable bytes.
unsafe fn write<T: Copy>(p: *mut T, value: &T) {
    // SAFETY: non-null, writable and outside the storage (checked by `writable`, and by the
    // contract); `write_unaligned` needs no alignment.
    unsafe { p.write_unaligned(*value) }
}

/// The solver behind a checked, initialised storage pointer.
///
/// # Safety
/// `slot` came from [`initialised`] in this call, and no other reference to it exists.
unsafe fn solver<'a>(slot: *mut Slot) -> &'a mut Slot {
    // SAFETY: non-null, aligned, initialised by `init` (magic checked), and by the contract not
    // accessed by anyone else during the call.
    unsafe { &mut *slot }
}

fn record(slot: &mut Slot, solution: Solution) -> i32 {
    let status = status_code(solution.status);
    slot.last = Last {
        u0: solution.u0,
        status,
        qp_iterations: u32::try_from(solution.qp_iterations).unwrap_or(u32::MAX),
        cost: solution.cost,
    };
    status
}

/// The exact size of the solver state in bytes (at most `STORAGE_SIZE`).
#[no_mangle]
pub extern "C" fn uavgen_model_storage_size() -> usize {
    size_of::<Slot>()
}

/// The alignment the storage needs (at most `STORAGE_ALIGN`).
#[no_mangle]
pub extern "C" fn uavgen_model_storage_align() -> usize {
    align_of::<Slot>()
}

/// Initialise `storage`: a zero guess, then `Mpc::initialize(x0, u)`. `INVALID_INPUT` if `x0` or
/// `u` is not finite (the storage is initialised with the zero guess).
///
/// # Safety
/// `storage` is NULL or points to `storage_size` writable bytes; `x0` and `u` are NULL or point to
/// NX and NU readable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_init(
    storage: *mut c_void,
    storage_size: usize,
    x0: *const Real,
    u: *const Real,
) -> i32 {
    code((|| {
        let slot = storage_ptr(storage)?;
        if storage_size < size_of::<Slot>() {
            return Err(status::STORAGE_TOO_SMALL);
        }
        // SAFETY: by the contract.
        let (x0, u): ([Real; NX], [Real; NU]) = unsafe { (read(slot, x0)?, read(slot, u)?) };
        // SAFETY: `slot` is non-null, aligned and points to at least size_of::<Slot>() writable
        // bytes (checked above); the fields are written in place, nothing is dropped (no drop
        // glue), and the magic number goes last, so that a storage is never half initialised and
        // marked. The solver is written from a constant (`const { Mpc::new() }`, all zero bits: a
        // memset into the storage), not from a value built at run time, which rustc would build
        // in this function's frame first (a solver-sized stack temporary: 310 KB for sindy_m100).
        unsafe {
            ptr::addr_of_mut!((*slot).mpc).write(const { Mpc::new() });
            ptr::addr_of_mut!((*slot).last).write(Last {
                u0: [0.0; NU],
                status: status::NO_SOLUTION,
                qp_iterations: 0,
                cost: 0.0,
            });
            ptr::addr_of_mut!((*slot).magic).write(MAGIC);
        }
        // SAFETY: initialised just now; no other reference exists during the call.
        let slot = unsafe { solver(slot) };
        if !x0.iter().chain(&u).all(|v| v.is_finite()) {
            return Ok(status::INVALID_INPUT);
        }
        slot.mpc.initialize(&x0, &u);
        slot.last.u0 = slot.mpc.planned_inputs()[0];
        Ok(status::OK)
    })())
}

/// `Mpc::set_guess(xs, us)`; `INVALID_INPUT`, changing nothing, if a value is not finite.
///
/// # Safety
/// `storage` is NULL or zero-filled or initialised by `init`; `xs` and `us` are NULL or point to
/// (N+1)·NX and N·NU readable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_set_guess(storage: *mut c_void, xs: *const Real, us: *const Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: by the contract.
        let (xs, us): ([[Real; NX]; N + 1], [[Real; NU]; N]) = unsafe { (read(slot, xs)?, read(slot, us)?) };
        // SAFETY: from `initialised`, and the only reference.
        let slot = unsafe { solver(slot) };
        Ok(if slot.mpc.set_guess(&xs, &us) {
            status::OK
        } else {
            status::INVALID_INPUT
        })
    })())
}

/// `Mpc::prepare(reference)`.
///
/// # Safety
/// `storage` as for `set_guess`; `reference` is NULL or points to (N+1)·NX readable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_prepare(storage: *mut c_void, reference: *const Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: by the contract.
        let reference: [[Real; NX]; N + 1] = unsafe { read(slot, reference)? };
        // SAFETY: from `initialised`, and the only reference.
        let slot = unsafe { solver(slot) };
        Ok(status_code(slot.mpc.prepare(&reference)))
    })())
}

/// `Mpc::feedback(x0)`; the input to apply goes to `u0`.
///
/// # Safety
/// `storage` as for `set_guess`; `x0` is NULL or points to NX readable `Real`s, `u0` to NU
/// writable ones.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_feedback(storage: *mut c_void, x0: *const Real, u0: *mut Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: by the contract.
        let x0: [Real; NX] = unsafe { read(slot, x0)? };
        let u0 = u0.cast::<[Real; NU]>();
        writable(slot, u0)?;
        // SAFETY: from `initialised`, and the only reference.
        let slot = unsafe { solver(slot) };
        let solution = slot.mpc.feedback(&x0);
        // SAFETY: checked by `writable`.
        unsafe { write(u0, &solution.u0) };
        Ok(record(slot, solution))
    })())
}

/// `Mpc::solve(x0, reference)` (prepare + feedback); the input to apply goes to `u0`.
///
/// # Safety
/// As for `prepare` and `feedback`.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_solve(
    storage: *mut c_void,
    x0: *const Real,
    reference: *const Real,
    u0: *mut Real,
) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: by the contract.
        let (x0, reference): ([Real; NX], [[Real; NX]; N + 1]) = unsafe { (read(slot, x0)?, read(slot, reference)?) };
        let u0 = u0.cast::<[Real; NU]>();
        writable(slot, u0)?;
        // SAFETY: from `initialised`, and the only reference.
        let slot = unsafe { solver(slot) };
        let solution = slot.mpc.solve(&x0, &reference);
        // SAFETY: checked by `writable`.
        unsafe { write(u0, &solution.u0) };
        Ok(record(slot, solution))
    })())
}

/// `Mpc::shift()`: the guess and the stored reference one sample ahead.
///
/// # Safety
/// `storage` as for `set_guess`.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_shift(storage: *mut c_void) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: from `initialised`, and the only reference.
        unsafe { solver(slot) }.mpc.shift();
        Ok(status::OK)
    })())
}

/// `Mpc::set_disturbance(e)`: predict with x_{k+1} = F(x_k, u_k) + e from the next `prepare` on
/// (offset-free tracking); `INVALID_INPUT`, changing nothing, if a value is not finite.
///
/// # Safety
/// `storage` as for `set_guess`; `e` is NULL or points to NX readable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_set_disturbance(storage: *mut c_void, e: *const Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { initialised(storage)? };
        // SAFETY: by the contract.
        let e: [Real; NX] = unsafe { read(slot, e)? };
        // SAFETY: from `initialised`, and the only reference.
        let slot = unsafe { solver(slot) };
        Ok(if slot.mpc.set_disturbance(&e) {
            status::OK
        } else {
            status::INVALID_INPUT
        })
    })())
}

/// The solver for reading.
///
/// # Safety
/// `storage` as for `set_guess`.
unsafe fn view<'a>(storage: *const c_void) -> Result<&'a Slot> {
    // SAFETY: by the contract.
    let slot = unsafe { initialised(storage)? };
    // SAFETY: non-null, aligned, initialised (magic checked); nothing writes it during the call.
    Ok(unsafe { &*slot })
}

/// The status of the latest feedback/solve (`NO_SOLUTION` before the first).
///
/// # Safety
/// `storage` as for `set_guess`.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_last_status(storage: *const c_void) -> i32 {
    // SAFETY: by the contract.
    code(unsafe { view(storage) }.map(|slot| slot.last.status))
}

/// The input of the latest feedback/solve (`NO_SOLUTION`, writing nothing, before the first).
///
/// # Safety
/// `storage` as for `set_guess`; `u0` is NULL or points to NU writable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_first_input(storage: *const c_void, u0: *mut Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { view(storage)? };
        if slot.last.status == status::NO_SOLUTION {
            return Err(status::NO_SOLUTION);
        }
        let u0 = u0.cast::<[Real; NU]>();
        writable(slot, u0)?;
        // SAFETY: checked by `writable`.
        unsafe { write(u0, &slot.last.u0) };
        Ok(status::OK)
    })())
}

/// Active-set iterations of the latest QP (`NO_SOLUTION`, writing nothing, before the first).
///
/// # Safety
/// `storage` as for `set_guess`; `iterations` is NULL or points to a writable `uint32_t`.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_qp_iterations(storage: *const c_void, iterations: *mut u32) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { view(storage)? };
        if slot.last.status == status::NO_SOLUTION {
            return Err(status::NO_SOLUTION);
        }
        writable(slot, iterations)?;
        // SAFETY: checked by `writable`.
        unsafe { write(iterations, &slot.last.qp_iterations) };
        Ok(status::OK)
    })())
}

/// Cost of the plan after the latest feedback/solve (`NO_SOLUTION`, writing nothing, before the first).
///
/// # Safety
/// `storage` as for `set_guess`; `cost` is NULL or points to a writable `Real`.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_cost(storage: *const c_void, cost: *mut Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { view(storage)? };
        if slot.last.status == status::NO_SOLUTION {
            return Err(status::NO_SOLUTION);
        }
        writable(slot, cost)?;
        // SAFETY: checked by `writable`.
        unsafe { write(cost, &slot.last.cost) };
        Ok(status::OK)
    })())
}

/// The planned inputs ū₀..ū_{N−1} of the current guess (N·NU `Real`s).
///
/// # Safety
/// `storage` as for `set_guess`; `us` is NULL or points to N·NU writable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_planned_inputs(storage: *const c_void, us: *mut Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { view(storage)? };
        let us = us.cast::<[[Real; NU]; N]>();
        writable(slot, us)?;
        // SAFETY: checked by `writable`.
        unsafe { write(us, slot.mpc.planned_inputs()) };
        Ok(status::OK)
    })())
}

/// The predicted states x̄₀..x̄_N of the current guess ((N+1)·NX `Real`s).
///
/// # Safety
/// `storage` as for `set_guess`; `xs` is NULL or points to (N+1)·NX writable `Real`s.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_predicted_states(storage: *const c_void, xs: *mut Real) -> i32 {
    code((|| {
        // SAFETY: by the contract.
        let slot = unsafe { view(storage)? };
        let xs = xs.cast::<[[Real; NX]; N + 1]>();
        writable(slot, xs)?;
        // SAFETY: checked by `writable`.
        unsafe { write(xs, slot.mpc.predicted_states()) };
        Ok(status::OK)
    })())
}

/// `discrete_dynamics(x, u)` into `x_next`: the model over one sample, e.g. as a simulated plant.
///
/// # Safety
/// `x` and `u` are NULL or point to NX and NU readable `Real`s, `x_next` to NX writable ones.
#[no_mangle]
pub unsafe extern "C" fn uavgen_model_discrete_dynamics(x: *const Real, u: *const Real, x_next: *mut Real) -> i32 {
    code((|| {
        let none = ptr::null::<Slot>();
        // SAFETY: by the contract (no storage: nothing to overlap).
        let (x, u): ([Real; NX], [Real; NU]) = unsafe { (read(none, x)?, read(none, u)?) };
        let x_next = x_next.cast::<[Real; NX]>();
        writable(none, x_next)?;
        // SAFETY: checked by `writable`.
        unsafe { write(x_next, &discrete_dynamics(&x, &u)) };
        Ok(status::OK)
    })())
}
