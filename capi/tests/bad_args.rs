//! Every exported function with bad arguments (error codes, nothing
//! changes). The good path through the C functions is `good_path.rs`.

// The two-capsule library (the default build).
#![cfg(not(feature = "three-capsules"))]

use capsule_mpc_capi::*;
use core::ffi::c_void;
use core::ptr::{null, null_mut};

#[path = "common/first_frame.rs"]
mod first_frame;
#[path = "common/handle.rs"]
mod handle;
use first_frame::aim_at_c_with_a_frame;
use handle::*;

/// A pointer to a double that is not 8-byte aligned (inside `bytes`).
fn misaligned_f64(bytes: &mut [u64; 8]) -> *mut f64 {
    unsafe { bytes.as_mut_ptr().cast::<u8>().add(1).cast() }
}

/// Actuation start of the single cycles below, s (measurement at 0).
const T_ACT: f64 = 0.02;

fn horizon() -> usize {
    let (mut m, mut n, mut k, mut dt, mut u) = (0u32, 0u32, 0u32, 0.0, 0.0);
    assert_eq!(
        unsafe { capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, &mut u) },
        CAPSULE_MPC_OK
    );
    n as usize
}

#[test]
fn constant_queries() {
    assert_eq!(capsule_mpc_abi_version(), CAPSULE_MPC_ABI_VERSION);
    let size = capsule_mpc_workspace_size();
    let align = capsule_mpc_workspace_align();
    assert!(size > 0 && size <= 1 << 16, "{size}");
    assert!(align.is_power_of_two() && align <= 64);
    let (mut m, mut n, mut k, mut dt, mut u) = (0u32, 0u32, 0u32, 0.0, 0.0);
    assert_eq!(
        unsafe { capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, &mut u) },
        CAPSULE_MPC_OK
    );
    assert_eq!(m, 2);
    assert!(n >= 1 && k >= n);
    assert_eq!(dt, 0.02);
    assert_eq!(u, 0.04);
}

#[test]
fn dimensions_bad_pointers() {
    let (mut m, mut n, mut k, mut dt, mut u) = (7u32, 7u32, 7u32, 7.0, 7.0);
    unsafe {
        assert_eq!(
            capsule_mpc_dimensions(null_mut(), &mut n, &mut k, &mut dt, &mut u),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_dimensions(&mut m, null_mut(), &mut k, &mut dt, &mut u),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, null_mut(), &mut dt, &mut u),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, &mut k, null_mut(), &mut u),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, null_mut()),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        let mut words = [0u64; 8];
        let bad_u32 = words.as_mut_ptr().cast::<u8>().add(1).cast::<u32>();
        assert_eq!(
            capsule_mpc_dimensions(bad_u32, &mut n, &mut k, &mut dt, &mut u),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        let bad_f64 = misaligned_f64(&mut words);
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, &mut k, bad_f64, &mut u),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
    }
    // Nothing was written.
    assert_eq!((m, n, k, dt, u), (7, 7, 7, 7.0, 7.0));
}

#[test]
fn init_bad_args() {
    let mut b = zeroed_buf();
    let size = b.0.len();
    let need = capsule_mpc_workspace_size();
    let buf: *mut c_void = b.0.as_mut_ptr().cast();
    let mut words = [0u64; 8];
    let nan = [f64::NAN, 0.0];
    let inf = [0.0, f64::INFINITY];
    unsafe {
        assert_eq!(
            capsule_mpc_init(null_mut(), size, ORIGIN.as_ptr(), 2),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_init(buf, 0, ORIGIN.as_ptr(), 2),
            CAPSULE_MPC_ERR_BAD_SIZE
        );
        assert_eq!(
            capsule_mpc_init(buf, need - 1, ORIGIN.as_ptr(), 2),
            CAPSULE_MPC_ERR_BAD_SIZE
        );
        let misaligned: *mut c_void = b.0.as_mut_ptr().add(1).cast();
        assert_eq!(
            capsule_mpc_init(misaligned, size - 1, ORIGIN.as_ptr(), 2),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_init(buf, size, null(), 2),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_init(buf, size, misaligned_f64(&mut words), 2),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_init(buf, size, ORIGIN.as_ptr(), 1),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_init(buf, size, ORIGIN.as_ptr(), 3),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_init(buf, size, ORIGIN.as_ptr(), 0),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_init(buf, size, nan.as_ptr(), 2),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        assert_eq!(
            capsule_mpc_init(buf, size, inf.as_ptr(), 2),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        // Far outside the workspace (an unconverted unit, a wild frame):
        // refused like a target there, for each capsule.
        for far in [[1.0e6, 0.0], [0.0, -1.0e6], [0.0601, 0.0], [0.0, -0.0601]] {
            assert_eq!(
                capsule_mpc_init(buf, size, far.as_ptr(), 2),
                CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE,
                "{far:?}"
            );
        }
    }
    // No failed init wrote anything: the buffer is still all zero.
    assert!(b.0.iter().all(|&x| x == 0));
    let mut status = 0;
    assert_eq!(
        unsafe { capsule_mpc_last_status(handle(&mut b), &mut status) },
        CAPSULE_MPC_ERR_NOT_INITIALIZED
    );
    // Exactly the advertised size is enough.
    assert_eq!(
        unsafe { capsule_mpc_init(buf, need, ORIGIN.as_ptr(), 2) },
        CAPSULE_MPC_OK
    );
    // reset checks the same, and a refused reset changes nothing.
    let mut before = [0.0; 4];
    let mut after = [0.0; 4];
    unsafe {
        assert_eq!(
            capsule_mpc_estimate(handle(&mut b), before.as_mut_ptr(), 4),
            CAPSULE_MPC_OK
        );
        let far = [0.0, 1.0e6];
        assert_eq!(
            capsule_mpc_reset(handle(&mut b), far.as_ptr(), 2),
            CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE
        );
        assert_eq!(
            capsule_mpc_estimate(handle(&mut b), after.as_mut_ptr(), 4),
            CAPSULE_MPC_OK
        );
    }
    assert_eq!(before, after);
}

/// Calls every handle function on `h` and checks each returns `expected`.
fn every_handle_fn_returns(h: *mut CapsuleMpc, expected: i32) {
    let mut grads = [0.0; 256];
    let (mut samples, mut status) = (0u32, 0i32);
    let mut x = [0.0; 4];
    unsafe {
        assert_eq!(capsule_mpc_reset(h, ORIGIN.as_ptr(), 2), expected, "reset");
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            expected,
            "set_target"
        );
        assert_eq!(
            capsule_mpc_set_sampling(h, CAPSULE_MPC_SAMPLING_VARIABLE),
            expected,
            "set_sampling"
        );
        assert_eq!(capsule_mpc_set_timing(h, 0.02, 0.0), expected, "set_timing");
        assert_eq!(
            capsule_mpc_set_disturbance_bound(h, 5e-4),
            expected,
            "set_disturbance_bound"
        );
        assert_eq!(capsule_mpc_set_shooting(h, 1), expected, "set_shooting");
        assert_eq!(
            capsule_mpc_set_model_factors(h, 0, 1.0, 1.2, 0.01, 0.01),
            expected,
            "set_model_factors"
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, 0.0, 0),
            expected,
            "feed_tracking"
        );
        assert_eq!(
            capsule_mpc_feed_state(h, TARGET_C.as_ptr(), 4),
            expected,
            "feed_state"
        );
        assert_eq!(
            capsule_mpc_next_actuation(
                h,
                T_ACT,
                grads.as_mut_ptr(),
                grads.len(),
                &mut samples,
                &mut status
            ),
            expected,
            "next_actuation"
        );
        assert_eq!(
            capsule_mpc_last_status(h, &mut status),
            expected,
            "last_status"
        );
        assert_eq!(
            capsule_mpc_set_refine(h, CAPSULE_MPC_REFINE_NONE),
            expected,
            "set_refine"
        );
        assert_eq!(capsule_mpc_last_tier(h, &mut status), expected, "last_tier");
        assert_eq!(
            capsule_mpc_estimate(h, x.as_mut_ptr(), 4),
            expected,
            "estimate"
        );
    }
}

#[test]
fn uninitialized_null_and_misaligned_handles() {
    let mut b = zeroed_buf();
    every_handle_fn_returns(handle(&mut b), CAPSULE_MPC_ERR_NOT_INITIALIZED);
    every_handle_fn_returns(null_mut(), CAPSULE_MPC_ERR_NULL_POINTER);
    let misaligned = unsafe { b.0.as_mut_ptr().add(4).cast::<CapsuleMpc>() };
    every_handle_fn_returns(misaligned, CAPSULE_MPC_ERR_BAD_ALIGN);
    // Garbage (not zero) is detected too.
    b.0.fill(0xa5);
    every_handle_fn_returns(handle(&mut b), CAPSULE_MPC_ERR_NOT_INITIALIZED);
    // Nothing wrote to the buffer.
    assert!(b.0.iter().all(|&x| x == 0xa5));
}

fn estimate(h: *mut CapsuleMpc) -> [f64; 4] {
    let mut x = [f64::NAN; 4];
    assert_eq!(
        unsafe { capsule_mpc_estimate(h, x.as_mut_ptr(), 4) },
        CAPSULE_MPC_OK
    );
    x
}

#[test]
fn reset_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    let mut words = [0u64; 8];
    let before = estimate(h);
    unsafe {
        assert_eq!(
            capsule_mpc_reset(h, null(), 2),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_reset(h, misaligned_f64(&mut words), 2),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_reset(h, [0.01].as_ptr(), 1),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_reset(h, [0.01, 0.0, 0.0].as_ptr(), 3),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_reset(h, [0.01, f64::NAN].as_ptr(), 2),
            CAPSULE_MPC_ERR_NON_FINITE
        );
    }
    assert_eq!(estimate(h), before);
    assert_eq!(
        unsafe { capsule_mpc_reset(h, [0.01, -0.01].as_ptr(), 2) },
        CAPSULE_MPC_OK
    );
    assert_eq!(estimate(h), [0.01, 0.0, -0.01, 0.0]);
}

#[test]
fn set_target_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    let mut words = [0u64; 8];
    unsafe {
        assert_eq!(
            capsule_mpc_set_target(h, null(), 4),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_set_target(h, misaligned_f64(&mut words), 4),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 2),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 3),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_set_target(h, [0.02, f64::NAN, 0.0, 0.0].as_ptr(), 4),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        assert_eq!(
            capsule_mpc_set_target(h, [0.02, 0.0, f64::NEG_INFINITY, 0.0].as_ptr(), 4),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        assert_eq!(
            capsule_mpc_set_target(h, [0.5, 0.0, 0.0, 0.0].as_ptr(), 4),
            CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE
        );
        assert_eq!(
            capsule_mpc_set_target(h, [0.0, 0.0, -0.5, 0.0].as_ptr(), 4),
            CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE
        );
    }
    // No target was set: a cycle reports NO_TARGET and a zero gradient.
    let mut grads = [1.0; 64];
    let (mut samples, mut status) = (0u32, -1i32);
    assert_eq!(
        unsafe {
            capsule_mpc_next_actuation(
                h,
                T_ACT,
                grads.as_mut_ptr(),
                grads.len(),
                &mut samples,
                &mut status,
            )
        },
        CAPSULE_MPC_OK
    );
    assert_eq!(status, CAPSULE_MPC_STATUS_NO_TARGET);
    assert_eq!(grads[0], 0.0);
    assert_eq!(
        unsafe { capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4) },
        CAPSULE_MPC_OK
    );
}

#[test]
fn set_sampling_bad_mode() {
    let mut b = initialized();
    let h = handle(&mut b);
    unsafe {
        for mode in [-1, 3, 100, i32::MIN, i32::MAX] {
            assert_eq!(
                capsule_mpc_set_sampling(h, mode),
                CAPSULE_MPC_ERR_BAD_MODE,
                "mode {mode}"
            );
        }
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        for mode in [
            CAPSULE_MPC_SAMPLING_IDEAL,
            CAPSULE_MPC_SAMPLING_VARIABLE,
            CAPSULE_MPC_SAMPLING_CONSTANT,
        ] {
            assert_eq!(
                capsule_mpc_set_sampling(h, mode),
                CAPSULE_MPC_OK,
                "mode {mode}"
            );
        }
    }
}

/// Unknown refinement modes are refused and change nothing; the tier of
/// the last plan follows the mode (explicit alone, or the refinement's
/// choice), NONE before any cycle; a null tier pointer is refused.
#[test]
fn set_refine_bad_mode_and_last_tier() {
    let mut b = initialized();
    let h = handle(&mut b);
    let mut grads = [0.0; 256];
    let (mut samples, mut status, mut tier) = (0u32, 0i32, 7i32);
    unsafe {
        assert_eq!(capsule_mpc_last_tier(h, &mut tier), CAPSULE_MPC_OK);
        assert_eq!(tier, CAPSULE_MPC_TIER_NONE);
        assert_eq!(
            capsule_mpc_last_tier(h, null_mut()),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        for mode in [-1, 3, 100, i32::MIN, i32::MAX] {
            assert_eq!(
                capsule_mpc_set_refine(h, mode),
                CAPSULE_MPC_ERR_BAD_MODE,
                "mode {mode}"
            );
        }
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        assert_eq!(
            capsule_mpc_set_refine(h, CAPSULE_MPC_REFINE_NONE),
            CAPSULE_MPC_OK
        );
        let mut t = T_ACT;
        let mut tiers = Vec::new();
        for mode in [CAPSULE_MPC_REFINE_NONE, CAPSULE_MPC_REFINE_ONCE] {
            assert_eq!(capsule_mpc_set_refine(h, mode), CAPSULE_MPC_OK);
            for _ in 0..3 {
                assert_eq!(
                    capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, t - 0.02, 0),
                    CAPSULE_MPC_OK
                );
                assert_eq!(
                    capsule_mpc_next_actuation(
                        h,
                        t,
                        grads.as_mut_ptr(),
                        grads.len(),
                        &mut samples,
                        &mut status
                    ),
                    CAPSULE_MPC_OK
                );
                assert_eq!(capsule_mpc_last_tier(h, &mut tier), CAPSULE_MPC_OK);
                tiers.push((mode, tier));
                t += 0.02 * samples as f64 + 0.02;
            }
        }
        // The explicit tier alone always reports itself; with refinement
        // each cycle names one of the two tiers.
        for (mode, tier) in tiers {
            if mode == CAPSULE_MPC_REFINE_NONE {
                assert_eq!(tier, CAPSULE_MPC_TIER_EXPLICIT);
            } else {
                assert!(tier == CAPSULE_MPC_TIER_EXPLICIT || tier == CAPSULE_MPC_TIER_REFINED);
            }
        }
    }
}

#[test]
fn feed_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    let mut words = [0u64; 8];
    unsafe {
        // Tracking frames.
        assert_eq!(
            capsule_mpc_feed_tracking(h, null(), 2, 0.0, 0),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, misaligned_f64(&mut words), 2, 0.0, 0),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 1, 0.0, 0),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 4, 0.0, 0),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, [f64::NAN, 0.0].as_ptr(), 2, 0.0, 0),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, f64::NAN, 0),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, f64::INFINITY, 1),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        // A lost frame needs no positions.
        assert_eq!(
            capsule_mpc_feed_tracking(h, null(), 0, 0.0, 1),
            CAPSULE_MPC_OK
        );
        // Constant sampling: a full state does not fit the mode.
        assert_eq!(
            capsule_mpc_feed_state(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_ERR_WRONG_FEED
        );
    }
    // Full states, under ideal sampling (another handle).
    let mut ideal = initialized();
    let hi = handle(&mut ideal);
    unsafe {
        assert_eq!(
            capsule_mpc_set_sampling(hi, CAPSULE_MPC_SAMPLING_IDEAL),
            CAPSULE_MPC_OK
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, null(), 4),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, misaligned_f64(&mut words), 4),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, TARGET_C.as_ptr(), 2),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, TARGET_C.as_ptr(), 5),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, [0.0, f64::NAN, 0.0, 0.0].as_ptr(), 4),
            CAPSULE_MPC_ERR_NON_FINITE
        );
        // Ideal sampling: tracking frames do not fit the mode.
        assert_eq!(
            capsule_mpc_feed_tracking(hi, ORIGIN.as_ptr(), 2, 0.0, 0),
            CAPSULE_MPC_ERR_WRONG_FEED
        );
        assert_eq!(
            capsule_mpc_feed_tracking(hi, null(), 0, 0.0, 1),
            CAPSULE_MPC_ERR_WRONG_FEED
        );
        assert_eq!(
            capsule_mpc_feed_state(hi, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
    }
    // The lost frame is still the pending one: the cycle reports it.
    let mut grads = [0.0; 64];
    let (mut samples, mut status) = (0u32, -1i32);
    assert_eq!(
        unsafe { capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4) },
        CAPSULE_MPC_OK
    );
    assert_eq!(
        unsafe { capsule_mpc_feed_tracking(h, null(), 0, 0.0, 1) },
        CAPSULE_MPC_OK
    );
    assert_eq!(
        unsafe {
            capsule_mpc_next_actuation(
                h,
                T_ACT,
                grads.as_mut_ptr(),
                grads.len(),
                &mut samples,
                &mut status,
            )
        },
        CAPSULE_MPC_OK
    );
    assert_eq!(status, CAPSULE_MPC_STATUS_MEASUREMENT_LOST);
}

#[test]
fn next_actuation_last_status_estimate_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    let n = horizon();
    let mut grads = [7.0; 256];
    let (mut samples, mut status) = (7u32, 7i32);
    let mut words = [0u64; 64];
    aim_at_c_with_a_frame(h);
    unsafe {
        let before = estimate(h);
        let g = grads.as_mut_ptr();
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, null_mut(), 64, &mut samples, &mut status),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, 64, null_mut(), &mut status),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, 64, &mut samples, null_mut()),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_next_actuation(
                h,
                T_ACT,
                misaligned_f64(&mut [0u64; 8]),
                4,
                &mut samples,
                &mut status
            ),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        let bad_u32 = words.as_mut_ptr().cast::<u8>().add(1).cast::<u32>();
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, 64, bad_u32, &mut status),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        let bad_i32 = words.as_mut_ptr().cast::<u8>().add(2).cast::<i32>();
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, 64, &mut samples, bad_i32),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, 0, &mut samples, &mut status),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, n - 1, &mut samples, &mut status),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );
        for t in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(
                capsule_mpc_next_actuation(h, t, g, n, &mut samples, &mut status),
                CAPSULE_MPC_ERR_NON_FINITE
            );
        }
        // The frame was measured at 0 s: an actuation before it is
        // refused as time going backwards, one beyond the proven gap after
        // it as such.
        assert_eq!(
            capsule_mpc_next_actuation(h, -0.001, g, n, &mut samples, &mut status),
            CAPSULE_MPC_ERR_BAD_TIME
        );
        let max_gap_s = capsule_mpc_max_gap_s();
        for t in [max_gap_s + 0.002, 0.1, 1.5, 1000.0] {
            assert_eq!(
                capsule_mpc_next_actuation(h, t, g, n, &mut samples, &mut status),
                CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN,
                "{t}"
            );
        }
        // Nothing ran and nothing was written.
        assert_eq!(estimate(h), before);
        assert!(grads.iter().all(|&v| v == 7.0));
        assert_eq!((samples, status), (7, 7));
        assert_eq!(capsule_mpc_last_status(h, &mut status), CAPSULE_MPC_OK);
        assert_eq!(status, CAPSULE_MPC_STATUS_NO_TARGET);

        assert_eq!(
            capsule_mpc_last_status(h, null_mut()),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_last_status(h, bad_i32),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        let mut x = [0.0; 8];
        assert_eq!(
            capsule_mpc_estimate(h, null_mut(), 4),
            CAPSULE_MPC_ERR_NULL_POINTER
        );
        assert_eq!(
            capsule_mpc_estimate(h, misaligned_f64(&mut [0u64; 8]), 4),
            CAPSULE_MPC_ERR_BAD_ALIGN
        );
        assert_eq!(
            capsule_mpc_estimate(h, x.as_mut_ptr(), 3),
            CAPSULE_MPC_ERR_WRONG_LENGTH
        );

        // Capacity = horizon is enough; the pending frame is consumed.
        assert_eq!(
            capsule_mpc_next_actuation(h, T_ACT, g, n, &mut samples, &mut status),
            CAPSULE_MPC_OK
        );
        assert_eq!(status, CAPSULE_MPC_STATUS_OK);
        assert!(samples >= 1 && samples as usize <= n);
        assert!(grads[n..].iter().all(|&v| v == 7.0), "wrote past capacity");
        let mut last = -1;
        assert_eq!(capsule_mpc_last_status(h, &mut last), CAPSULE_MPC_OK);
        assert_eq!(last, status);
    }
}
