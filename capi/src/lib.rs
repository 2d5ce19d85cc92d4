//! C ABI for the capsule-mpc runtime: the two-capsule
//! [`capsule_mpc_runtime::DefaultController`], or with the cargo feature
//! `three-capsules` the [`capsule_mpc_runtime::ThreeCapsuleController`]
//! (one controller per library build, as the generated crate holds one
//! module per config; the header is the same, and hosts read the capsule
//! count and sizes from `capsule_mpc_dimensions`).
//!
//! The caller owns all memory: it asks for [`capsule_mpc_workspace_size`] and
//! [`capsule_mpc_workspace_align`], provides a buffer, and
//! [`capsule_mpc_init`] constructs the controller in it. The handle is the
//! buffer pointer. No call allocates. Every function returns an `int32_t`
//! error code (`CAPSULE_MPC_OK` = 0, errors < 0) except the four constant
//! queries; on error nothing changes and no output is written.
//!
//! The header `include/capsule_mpc.h` is hand-written; `tests/header.rs`
//! checks that it declares every function here with the same parameter
//! count and the same constant values.
//!
//! `std` is kept for this crate (the runtime and solver below it are
//! `no_std`): a `no_std` staticlib/cdylib needs `panic = "abort"`, which the
//! workspace profile does not set, and the integration tests link the rlib
//! together with `std`. No `std` API is used here, only `core`; see README.md.

#![deny(unsafe_op_in_unsafe_fn)]

use capsule_mpc_runtime::controller::{ControllerSettings, Refine, Sampling};
use capsule_mpc_runtime::generated::{PlanSolver, Tier};
use capsule_mpc_runtime::{RuntimeError, RuntimeStatus};

#[cfg(not(feature = "three-capsules"))]
use capsule_mpc_runtime::{
    generated::controller::{spec, Solver},
    DefaultController as LibController,
};
#[cfg(feature = "three-capsules")]
use capsule_mpc_runtime::{
    generated::three_capsules::{spec, Solver},
    ThreeCapsuleController as LibController,
};
use core::mem::{align_of, size_of};
use core::ptr;

/// ABI version: bumped on any change of a signature, struct or constant.
pub const CAPSULE_MPC_ABI_VERSION: u32 = 6;

pub const CAPSULE_MPC_OK: i32 = 0;
pub const CAPSULE_MPC_ERR_NULL_POINTER: i32 = -1;
pub const CAPSULE_MPC_ERR_BAD_SIZE: i32 = -2;
pub const CAPSULE_MPC_ERR_BAD_ALIGN: i32 = -3;
pub const CAPSULE_MPC_ERR_WRONG_LENGTH: i32 = -4;
pub const CAPSULE_MPC_ERR_NON_FINITE: i32 = -5;
pub const CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE: i32 = -6;
pub const CAPSULE_MPC_ERR_BAD_MODE: i32 = -7;
pub const CAPSULE_MPC_ERR_NOT_INITIALIZED: i32 = -8;
pub const CAPSULE_MPC_ERR_BAD_SETTING: i32 = -9;
pub const CAPSULE_MPC_ERR_BAD_TIME: i32 = -10;
pub const CAPSULE_MPC_ERR_WRONG_FEED: i32 = -11;
pub const CAPSULE_MPC_ERR_LOOP_RUNNING: i32 = -12;
pub const CAPSULE_MPC_ERR_TARGET_NOT_AT_REST: i32 = -13;
/// The compiled-in table file failed its integrity check (SHA-256).
pub const CAPSULE_MPC_ERR_CORRUPT_TABLES: i32 = -14;
/// Tracking + delay beyond the proven range (`capsule_mpc_max_gap_s`).
pub const CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN: i32 = -15;

pub const CAPSULE_MPC_SAMPLING_IDEAL: i32 = 0;
pub const CAPSULE_MPC_SAMPLING_CONSTANT: i32 = 1;
pub const CAPSULE_MPC_SAMPLING_VARIABLE: i32 = 2;

pub const CAPSULE_MPC_REFINE_NONE: i32 = 0;
pub const CAPSULE_MPC_REFINE_ONCE: i32 = 1;
pub const CAPSULE_MPC_REFINE_PER_SAMPLE: i32 = 2;

/// The last cycle solved nothing (no target, hold, fallback).
pub const CAPSULE_MPC_TIER_NONE: i32 = -1;
pub const CAPSULE_MPC_TIER_EXPLICIT: i32 = 0;
pub const CAPSULE_MPC_TIER_REFINED: i32 = 1;

pub const CAPSULE_MPC_STATUS_OK: i32 = RuntimeStatus::Ok as i32;
pub const CAPSULE_MPC_STATUS_FALLBACK: i32 = RuntimeStatus::Fallback as i32;
pub const CAPSULE_MPC_STATUS_ITERATION_LIMIT: i32 = RuntimeStatus::IterationLimit as i32;
pub const CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED: i32 = RuntimeStatus::MeasurementRejected as i32;
pub const CAPSULE_MPC_STATUS_MEASUREMENT_LOST: i32 = RuntimeStatus::MeasurementLost as i32;
pub const CAPSULE_MPC_STATUS_NO_TARGET: i32 = RuntimeStatus::NoTarget as i32;
pub const CAPSULE_MPC_STATUS_REACQUIRED: i32 = RuntimeStatus::Reacquired as i32;
pub const CAPSULE_MPC_STATUS_ABOVE_ITERATION_MAP: i32 = RuntimeStatus::AboveIterationMap as i32;
pub const CAPSULE_MPC_STATUS_RECOVERING: i32 = RuntimeStatus::Recovering as i32;

const M: usize = <Solver as PlanSolver<NX, K>>::M;
const NX: usize = spec::NX;
const K: usize = spec::K;
const N: usize = <Solver as PlanSolver<NX, K>>::N;

/// "CAPSMPC1": written last by a successful init, checked by every call.
const MAGIC: u64 = 0x4341_5053_4d50_4331;

/// What the host fed since the last actuation request.
#[derive(Debug, Clone, Copy)]
enum Pending {
    /// Nothing fed (treated as a lost frame).
    Nothing,
    /// The tracking frame measured at this time, s, was lost.
    Lost(f64),
    /// Positions measured at the start of the tracking phase, m, and the
    /// time they were measured, s.
    Positions([f64; M], f64),
    /// Full state (ideal sampling), SI.
    FullState([f64; NX]),
}

/// The workspace behind a `capsule_mpc_t*` handle (opaque to C).
#[repr(C)]
pub struct CapsuleMpc {
    /// First field, so a zeroed or foreign buffer is detected.
    magic: u64,
    pending: Pending,
    last_status: RuntimeStatus,
    /// `CAPSULE_MPC_TIER_*` of the last cycle's plan.
    last_tier: i32,
    /// A cycle ran since init or the last reset (the sampling mode is then
    /// fixed until the next reset).
    running: bool,
    controller: LibController,
}

type Res = Result<(), i32>;

fn code(r: Res) -> i32 {
    match r {
        Ok(()) => CAPSULE_MPC_OK,
        Err(e) => e,
    }
}

fn map_err(e: RuntimeError) -> i32 {
    match e {
        RuntimeError::NonFinite(_) => CAPSULE_MPC_ERR_NON_FINITE,
        RuntimeError::WrongLength(_) => CAPSULE_MPC_ERR_WRONG_LENGTH,
        // Outside the workspace: not a target the controller can reach.
        RuntimeError::TargetOutOfRange | RuntimeError::OutsideWorkspace { .. } => {
            CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE
        }
        RuntimeError::BadSetting(_) => CAPSULE_MPC_ERR_BAD_SETTING,
        RuntimeError::BadTime(_) => CAPSULE_MPC_ERR_BAD_TIME,
        RuntimeError::TargetNotAtRest => CAPSULE_MPC_ERR_TARGET_NOT_AT_REST,
        RuntimeError::CorruptTables(_) => CAPSULE_MPC_ERR_CORRUPT_TABLES,
        RuntimeError::GapBeyondProven { .. } => CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN,
    }
}

/// Null and alignment check of a pointer the caller passes.
fn check_ptr<T>(p: *const T) -> Res {
    if p.is_null() {
        Err(CAPSULE_MPC_ERR_NULL_POINTER)
    } else if !p.is_aligned() {
        Err(CAPSULE_MPC_ERR_BAD_ALIGN)
    } else {
        Ok(())
    }
}

/// Reads `n == expected` doubles from `p` (checked) into an array.
///
/// # Safety
/// If `p` is non-null and aligned it must point to `n` readable doubles.
unsafe fn read_array<const L: usize>(p: *const f64, n: usize) -> Result<[f64; L], i32> {
    check_ptr(p)?;
    if n != L {
        return Err(CAPSULE_MPC_ERR_WRONG_LENGTH);
    }
    let mut a = [0.0; L];
    // SAFETY: p is non-null, aligned, and the caller guarantees n = L doubles.
    a.copy_from_slice(unsafe { core::slice::from_raw_parts(p, L) });
    if a.iter().any(|v| !v.is_finite()) {
        return Err(CAPSULE_MPC_ERR_NON_FINITE);
    }
    Ok(a)
}

/// Borrows the workspace behind a handle after null, alignment and magic
/// checks.
///
/// # Safety
/// A non-null aligned `h` must point to at least `capsule_mpc_workspace_size()`
/// initialized bytes (a zeroed buffer is detected as uninitialized), not
/// accessed concurrently.
unsafe fn workspace<'a>(h: *mut CapsuleMpc) -> Result<&'a mut CapsuleMpc, i32> {
    check_ptr(h)?;
    // SAFETY: h is non-null and aligned; the magic word is a plain u64, valid
    // for any initialized bit pattern.
    let magic = unsafe { ptr::addr_of!((*h).magic).read() };
    if magic != MAGIC {
        return Err(CAPSULE_MPC_ERR_NOT_INITIALIZED);
    }
    // SAFETY: the magic is only written by capsule_mpc_init after the whole
    // struct was written, so the struct is valid.
    Ok(unsafe { &mut *h })
}

/// Writes `v` through an output pointer (checked).
///
/// # Safety
/// A non-null aligned `p` must be valid for a write of `T`.
unsafe fn write_out<T>(p: *mut T, v: T) {
    // SAFETY: checked by the caller with check_ptr; valid per the contract.
    unsafe { p.write(v) }
}

/// ABI version of this library (`CAPSULE_MPC_ABI_VERSION`).
#[no_mangle]
pub extern "C" fn capsule_mpc_abi_version() -> u32 {
    CAPSULE_MPC_ABI_VERSION
}

/// Bytes the caller must provide to `capsule_mpc_init`.
#[no_mangle]
pub extern "C" fn capsule_mpc_workspace_size() -> usize {
    size_of::<CapsuleMpc>()
}

/// Alignment the buffer given to `capsule_mpc_init` must have.
#[no_mangle]
pub extern "C" fn capsule_mpc_workspace_align() -> usize {
    align_of::<CapsuleMpc>()
}

/// The longest tracking + delay per cycle (end of one actuation phase to
/// the start of the next) the loop is proven to settle with, s; longer
/// ones are refused with `CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN`.
#[no_mangle]
pub extern "C" fn capsule_mpc_max_gap_s() -> f64 {
    LibController::MAX_GAP_S
}

/// The build's dimensions, so a host checks it links what it expects.
///
/// # Safety
/// Every pointer must be valid for one write of its type.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_dimensions(
    capsules: *mut u32,
    horizon: *mut u32,
    plan_len: *mut u32,
    sample_time_s: *mut f64,
    u_max_t_per_m: *mut f64,
) -> i32 {
    let r = (|| {
        check_ptr(capsules)?;
        check_ptr(horizon)?;
        check_ptr(plan_len)?;
        check_ptr(sample_time_s)?;
        check_ptr(u_max_t_per_m)?;
        // SAFETY: every pointer checked above; valid per the contract.
        unsafe {
            write_out(capsules, M as u32);
            write_out(horizon, N as u32);
            write_out(plan_len, K as u32);
            write_out(sample_time_s, <Solver as PlanSolver<NX, K>>::DT_S);
            write_out(u_max_t_per_m, <Solver as PlanSolver<NX, K>>::U_MAX_T_PER_M);
        }
        Ok(())
    })();
    code(r)
}

/// Constructs a controller in `buffer` (`size` bytes, aligned to
/// `capsule_mpc_workspace_align()`), every capsule at rest at `positions_m`
/// (`n_positions` = capsule count), constant sampling, no target. The handle
/// is `buffer`.
///
/// # Safety
/// `buffer` must be valid for writes of `size` bytes; `positions_m` must
/// point to `n_positions` doubles.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_init(
    buffer: *mut core::ffi::c_void,
    size: usize,
    positions_m: *const f64,
    n_positions: usize,
) -> i32 {
    let r = (|| {
        let h = buffer.cast::<CapsuleMpc>();
        if h.is_null() {
            return Err(CAPSULE_MPC_ERR_NULL_POINTER);
        }
        if size < size_of::<CapsuleMpc>() {
            return Err(CAPSULE_MPC_ERR_BAD_SIZE);
        }
        if !h.is_aligned() {
            return Err(CAPSULE_MPC_ERR_BAD_ALIGN);
        }
        // SAFETY: read_array checks null, alignment and length.
        let p: [f64; M] = unsafe { read_array(positions_m, n_positions) }?;
        let controller =
            LibController::new(LibController::default_settings(), &p).map_err(map_err)?;
        let ws = CapsuleMpc {
            magic: MAGIC,
            pending: Pending::Nothing,
            last_status: RuntimeStatus::NoTarget,
            last_tier: CAPSULE_MPC_TIER_NONE,
            running: false,
            controller,
        };
        // SAFETY: h is non-null, aligned, and the buffer holds size >=
        // size_of::<CapsuleMpc>() writable bytes. ptr::write does not read
        // or drop the old contents.
        unsafe { ptr::write(h, ws) };
        Ok(())
    })();
    code(r)
}

/// Restarts the estimate at rest at `positions_m`, keeping the target and
/// the sampling mode; drops any fed frame and the time base (the next
/// frame may carry any time), and allows `capsule_mpc_set_sampling` again.
///
/// # Safety
/// `handle` must come from `capsule_mpc_init` (or be a zeroed buffer);
/// `positions_m` must point to `n` doubles.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_reset(
    handle: *mut CapsuleMpc,
    positions_m: *const f64,
    n: usize,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        let p: [f64; M] = unsafe { read_array(positions_m, n) }?;
        ws.controller.reset(&p).map_err(map_err)?;
        ws.pending = Pending::Nothing;
        ws.running = false;
        Ok(())
    })();
    code(r)
}

/// Sets the target state `[x1, v1, x2, v2, ...]` (`n` = 2 x capsules; SI).
/// The speeds must be 0 (TARGET_NOT_AT_REST otherwise: the plans end at
/// rest). Refused with TARGET_OUT_OF_RANGE when the stored plans do not
/// cover it from the current estimate. Reached from wherever the capsules
/// are, moving or not; the way there may leave the workspace (a
/// minimum-time move swings the low-drag capsule past its target:
/// docs/known-limits.md).
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `target` must point to `n` doubles.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_target(
    handle: *mut CapsuleMpc,
    target: *const f64,
    n: usize,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        let t: [f64; NX] = unsafe { read_array(target, n) }?;
        ws.controller.set_target(&t).map_err(map_err)
    })();
    code(r)
}

/// Sampling mode: 0 ideal (feed the full state with
/// `capsule_mpc_feed_state`), 1 constant (one actuation sample per tracking
/// phase, the default), 2 variable (the switching rule decides). Changing
/// the mode restarts the estimate at rest at the current estimated positions
/// (keeping the target), so it is only allowed before the loop: after
/// `capsule_mpc_init` or `capsule_mpc_reset` and before the next
/// `capsule_mpc_next_actuation`; afterwards LOOP_RUNNING (setting the mode
/// it already has is always OK).
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_sampling(handle: *mut CapsuleMpc, mode: i32) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        let sampling = match mode {
            CAPSULE_MPC_SAMPLING_IDEAL => Sampling::Ideal,
            CAPSULE_MPC_SAMPLING_CONSTANT => Sampling::Constant,
            CAPSULE_MPC_SAMPLING_VARIABLE => Sampling::Variable,
            _ => return Err(CAPSULE_MPC_ERR_BAD_MODE),
        };
        if ws.controller.settings().sampling == sampling {
            return Ok(());
        }
        change_before_loop(ws, |s| s.sampling = sampling)
    })();
    code(r)
}

/// Sets the tracking phase and the extra delay after it, s, that the plans
/// model until the first time-stamped cycles have measured the gaps
/// (default: the generated config's). Before the loop starts
/// (LOOP_RUNNING after; reset first). Refused with GAP_BEYOND_PROVEN when
/// their sum exceeds `capsule_mpc_max_gap_s()`, BAD_SETTING when one is
/// negative, NON_FINITE when one is not finite.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_timing(
    handle: *mut CapsuleMpc,
    tracking_time_s: f64,
    extra_delay_s: f64,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        if !tracking_time_s.is_finite() || !extra_delay_s.is_finite() {
            return Err(CAPSULE_MPC_ERR_NON_FINITE);
        }
        change_before_loop(ws, |s| {
            s.tracking_time_s = tracking_time_s;
            s.extra_delay_s = extra_delay_s;
        })
    })();
    code(r)
}

/// The disturbance the estimator assumes: a bound on the norm of the
/// additive disturbance of the state derivative, SI (m/s on the position
/// rates, m/s^2 on the accelerations; the paper's 0.05 cm units are 5e-4).
/// Default: the generated config's `[disturbance]` bound (5e-4 for the
/// default config), with which every figure in the docs was measured; 0
/// tells the estimator the capsules move exactly as modelled. Before the
/// loop, as `capsule_mpc_set_timing` (LOOP_RUNNING after; reset first).
/// BAD_SETTING when negative or above 1e3, NON_FINITE when not finite.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_disturbance_bound(
    handle: *mut CapsuleMpc,
    bound_si: f64,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        if !bound_si.is_finite() {
            return Err(CAPSULE_MPC_ERR_NON_FINITE);
        }
        change_before_loop(ws, |s| s.disturbance_bound = bound_si)
    })();
    code(r)
}

/// A setting that only the set-up may change: LOOP_RUNNING once the loop
/// has started, else the controller rebuilt with `change` applied.
fn change_before_loop(ws: &mut CapsuleMpc, change: impl FnOnce(&mut ControllerSettings)) -> Res {
    if ws.running {
        return Err(CAPSULE_MPC_ERR_LOOP_RUNNING);
    }
    let mut settings = *ws.controller.settings();
    change(&mut settings);
    rebuild(ws, settings)
}

/// The runtime fixes settings at construction: rebuilds the controller
/// with `settings` at the current estimate and target, then commits (on
/// error nothing changes).
fn rebuild(ws: &mut CapsuleMpc, settings: ControllerSettings) -> Res {
    let x = ws.controller.estimate();
    let mut positions = [0.0; M];
    for (i, p) in positions.iter_mut().enumerate() {
        *p = x[2 * i];
    }
    let mut c = LibController::new(settings, &positions).map_err(map_err)?;
    if let Some(t) = ws.controller.target() {
        c.set_target(t).map_err(map_err)?;
    }
    ws.controller = c;
    ws.pending = Pending::Nothing;
    Ok(())
}

/// Feeds one tracking frame (constant or variable sampling; WRONG_FEED
/// under ideal sampling): `positions_m` (`n` = capsules) measured at the
/// start of the tracking phase that just ended, at scanner time
/// `t_measured_s`. With `lost != 0` the frame is lost: `positions_m` may be
/// NULL and `n` is ignored. A later feed replaces an earlier one.
/// `t_measured_s` is refused with BAD_TIME when it lies before the end of
/// the last actuation phase returned (by more than 1 ms: time going
/// backwards), with GAP_BEYOND_PROVEN when it lies more than
/// `capsule_mpc_max_gap_s()` after it.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `positions_m` must point to `n`
/// doubles unless `lost != 0`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_feed_tracking(
    handle: *mut CapsuleMpc,
    positions_m: *const f64,
    n: usize,
    t_measured_s: f64,
    lost: i32,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        if ws.controller.settings().sampling == Sampling::Ideal {
            return Err(CAPSULE_MPC_ERR_WRONG_FEED);
        }
        ws.controller
            .check_measurement_time(t_measured_s)
            .map_err(map_err)?;
        let pending = if lost != 0 {
            Pending::Lost(t_measured_s)
        } else {
            Pending::Positions(unsafe { read_array(positions_m, n) }?, t_measured_s)
        };
        ws.pending = pending;
        Ok(())
    })();
    code(r)
}

/// Feeds the full state `[x1, v1, x2, v2, ...]` (`n` = 2 x capsules), for
/// ideal sampling only (WRONG_FEED otherwise): the next actuation is
/// planned from it directly.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `state` must point to `n` doubles.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_feed_state(
    handle: *mut CapsuleMpc,
    state: *const f64,
    n: usize,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        if ws.controller.settings().sampling != Sampling::Ideal {
            return Err(CAPSULE_MPC_ERR_WRONG_FEED);
        }
        ws.pending = Pending::FullState(unsafe { read_array(state, n) }?);
        Ok(())
    })();
    code(r)
}

/// Runs one controller cycle on the fed frame (nothing fed counts as a lost
/// frame) for an actuation that starts at scanner time
/// `t_actuation_start_s`, and writes the plan:
/// `gradients_t_per_m[0..min(capacity, plan_len)]` in T/m, of which the
/// first `*samples` are to be played (one per sample time, 20 ms) from the
/// actuation start; `*status` is a `CAPSULE_MPC_STATUS_*` value.
/// `capacity` must be at least the horizon (the largest `*samples`).
///
/// Constant and variable sampling predict the estimate from the end of the
/// previous actuation phase through the measurement to
/// `t_actuation_start_s` and plan for the gaps these times show: tracking
/// lengths may vary up to `capsule_mpc_max_gap_s()`. BAD_TIME when
/// `t_actuation_start_s` is before the frame's measurement time;
/// GAP_BEYOND_PROVEN when it lies more than `capsule_mpc_max_gap_s()`
/// after the end of the previous actuation phase (the first cycle after
/// init or reset: after the measurement). Under ideal sampling the time
/// must be finite and is otherwise unused.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `gradients_t_per_m` must be valid
/// for `capacity` writes; `samples` and `status` for one write each.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_next_actuation(
    handle: *mut CapsuleMpc,
    t_actuation_start_s: f64,
    gradients_t_per_m: *mut f64,
    capacity: usize,
    samples: *mut u32,
    status: *mut i32,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        check_ptr(gradients_t_per_m)?;
        check_ptr(samples)?;
        check_ptr(status)?;
        if capacity < N {
            return Err(CAPSULE_MPC_ERR_WRONG_LENGTH);
        }
        if !t_actuation_start_s.is_finite() {
            return Err(CAPSULE_MPC_ERR_NON_FINITE);
        }
        let t = t_actuation_start_s;
        let ideal = ws.controller.settings().sampling == Sampling::Ideal;
        let out = match ws.pending {
            // Ideal sampling without a fed state: a lost frame.
            Pending::Nothing if ideal => ws.controller.cycle(None),
            Pending::Nothing => ws.controller.cycle_at(None, t, t),
            Pending::Lost(t_meas) => ws.controller.cycle_at(None, t_meas, t),
            Pending::Positions(z, t_meas) => ws.controller.cycle_at(Some(&z), t_meas, t),
            Pending::FullState(x) => ws.controller.cycle_full_state(&x),
        }
        .map_err(map_err)?;
        ws.pending = Pending::Nothing;
        ws.last_status = out.status;
        ws.last_tier = match out.solve {
            Some(r) if out.status != RuntimeStatus::Fallback => match r.tier {
                Tier::Explicit => CAPSULE_MPC_TIER_EXPLICIT,
                Tier::Refined => CAPSULE_MPC_TIER_REFINED,
            },
            _ => CAPSULE_MPC_TIER_NONE,
        };
        ws.running = true;
        let len = capacity.min(K);
        // SAFETY: the pointers were checked above; the caller guarantees
        // `capacity` doubles at gradients_t_per_m and len <= capacity.
        unsafe {
            core::slice::from_raw_parts_mut(gradients_t_per_m, len)
                .copy_from_slice(&out.gradients_t_per_m[..len]);
            write_out(samples, out.actuation_samples as u32);
            write_out(status, out.status as i32);
        }
        Ok(())
    })();
    code(r)
}

/// When the SQP refinement runs after the explicit tier:
/// `CAPSULE_MPC_REFINE_NONE` (the explicit tier alone), `_ONCE` (one
/// refinement per cycle) or `_PER_SAMPLE` (one per sample the coming phase
/// plays; the default). Allowed at any time; BAD_MODE for another value.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_refine(handle: *mut CapsuleMpc, mode: i32) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        let refine = match mode {
            CAPSULE_MPC_REFINE_NONE => Refine::None,
            CAPSULE_MPC_REFINE_ONCE => Refine::Once,
            CAPSULE_MPC_REFINE_PER_SAMPLE => Refine::PerSample,
            _ => return Err(CAPSULE_MPC_ERR_BAD_MODE),
        };
        ws.controller.set_refine(refine).map_err(map_err)
    })();
    code(r)
}

/// Minimum-time shots (`on != 0`) or the refinement of the stored plans
/// alone (`on == 0`). Default (`Shooting::Auto`): on (docs/decisions.md).
/// Allowed at any time.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_shooting(handle: *mut CapsuleMpc, on: i32) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        ws.controller.set_shooting(on != 0);
        Ok(())
    })();
    code(r)
}

/// What is known of capsule `capsule`'s (0-based) gain and drag against
/// the model, e.g. from `capsule-mpc calibrate`: factors (1 = the model)
/// and their standard deviations. They replace the estimate, the plans use
/// them at once where they differ from the model significantly, and the
/// frames keep refining them; kept across `capsule_mpc_reset`. BAD_SETTING
/// for a capsule beyond the count, a factor outside [0.25, 4] or a
/// deviation outside [0.001, 1]; NON_FINITE for NaN or infinity.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_set_model_factors(
    handle: *mut CapsuleMpc,
    capsule: u32,
    gain: f64,
    drag: f64,
    gain_std: f64,
    drag_std: f64,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; workspace checks the handle.
        let ws = unsafe { workspace(handle) }?;
        ws.controller
            .set_model_factors(capsule as usize, [gain, drag], [gain_std, drag_std])
            .map_err(map_err)
    })();
    code(r)
}

/// Which tier produced the last cycle's plan (`CAPSULE_MPC_TIER_*`;
/// `_NONE` when it solved nothing: before any cycle, no target, the
/// terminal hold or the fallback).
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `tier` valid for one write.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_last_tier(handle: *mut CapsuleMpc, tier: *mut i32) -> i32 {
    // SAFETY: the caller's contract is `get_i32`'s.
    unsafe { get_i32(handle, tier, |ws| ws.last_tier) }
}

/// Status of the last cycle (`CAPSULE_MPC_STATUS_NO_TARGET` before any).
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `status` valid for one write.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_last_status(handle: *mut CapsuleMpc, status: *mut i32) -> i32 {
    // SAFETY: the caller's contract is `get_i32`'s.
    unsafe { get_i32(handle, status, |ws| ws.last_status as i32) }
}

/// The getters' shared body: one `i32` of the workspace into `out`.
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `out` valid for one write.
unsafe fn get_i32(
    handle: *mut CapsuleMpc,
    out: *mut i32,
    value: impl FnOnce(&CapsuleMpc) -> i32,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        check_ptr(out)?;
        // SAFETY: checked above.
        unsafe { write_out(out, value(ws)) };
        Ok(())
    })();
    code(r)
}

/// Current state estimate `[x1, v1, x2, v2, ...]` (SI) into `state`
/// (`capacity` >= 2 x capsules). It describes the instant the last
/// actuation phase returned by `capsule_mpc_next_actuation` ends (its start
/// plus `*samples` sample times): the predicted state at the next
/// measurement when tracking starts right after the actuation. After
/// `capsule_mpc_init` or `capsule_mpc_reset`: the rest state given there.
/// Under ideal sampling: the state last fed (the plan's start).
///
/// # Safety
/// `handle` as for `capsule_mpc_reset`; `state` valid for `capacity` writes.
#[no_mangle]
pub unsafe extern "C" fn capsule_mpc_estimate(
    handle: *mut CapsuleMpc,
    state: *mut f64,
    capacity: usize,
) -> i32 {
    let r = (|| {
        // SAFETY: see the function's contract; the helpers check pointers.
        let ws = unsafe { workspace(handle) }?;
        check_ptr(state)?;
        if capacity < NX {
            return Err(CAPSULE_MPC_ERR_WRONG_LENGTH);
        }
        let x = ws.controller.estimate();
        // SAFETY: checked above; capacity >= NX doubles per the contract.
        unsafe { core::slice::from_raw_parts_mut(state, NX).copy_from_slice(&x) };
        Ok(())
    })();
    code(r)
}
