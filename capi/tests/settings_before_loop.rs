//! The settings a host makes before the loop: `capsule_mpc_set_timing`
//! (the gap the plans model) and `capsule_mpc_set_disturbance_bound` (the
//! disturbance the estimator assumes); bad values refused with their code,
//! a refused call changing nothing, and both refused once the loop runs.

// The two-capsule library (the default build).
#![cfg(not(feature = "three-capsules"))]

use capsule_mpc_capi::*;

#[path = "common/first_frame.rs"]
mod first_frame;
#[path = "common/handle.rs"]
mod handle;
use first_frame::aim_at_c_with_a_frame;
use handle::*;

/// Starts the loop on `h`: target C, a frame at 0 s, an actuation from
/// 0.02 s; returns the samples it plays.
fn start_loop(h: *mut CapsuleMpc) -> u32 {
    let mut grads = [0.0; 256];
    let (mut samples, mut status) = (0u32, 0i32);
    aim_at_c_with_a_frame(h);
    unsafe {
        assert_eq!(
            capsule_mpc_next_actuation(h, 0.02, grads.as_mut_ptr(), 256, &mut samples, &mut status),
            CAPSULE_MPC_OK
        );
    }
    samples
}

/// The disturbance bound: negative, above 1e3 or non-finite refused (and
/// nothing changed), after the loop started refused; 0 and the paper's
/// 5e-4 accepted before it.
#[test]
fn set_disturbance_bound_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    let estimate = |h| {
        let mut x = [0.0; 4];
        assert_eq!(
            unsafe { capsule_mpc_estimate(h, x.as_mut_ptr(), 4) },
            CAPSULE_MPC_OK
        );
        x
    };
    let before = estimate(h);
    unsafe {
        assert_eq!(
            capsule_mpc_set_disturbance_bound(h, -1e-6),
            CAPSULE_MPC_ERR_BAD_SETTING
        );
        assert_eq!(
            capsule_mpc_set_disturbance_bound(h, 2e3),
            CAPSULE_MPC_ERR_BAD_SETTING
        );
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(
                capsule_mpc_set_disturbance_bound(h, bad),
                CAPSULE_MPC_ERR_NON_FINITE
            );
        }
        assert_eq!(estimate(h), before);
        assert_eq!(capsule_mpc_set_disturbance_bound(h, 0.0), CAPSULE_MPC_OK);
        assert_eq!(capsule_mpc_set_disturbance_bound(h, 5e-4), CAPSULE_MPC_OK);
        start_loop(h);
        assert_eq!(
            capsule_mpc_set_disturbance_bound(h, 0.0),
            CAPSULE_MPC_ERR_LOOP_RUNNING
        );
    }
}

/// The tracking time and delay: beyond the proven range refused at set-up
/// (GAP_BEYOND_PROVEN), negative or non-finite refused, after the loop
/// started refused; at the range's end accepted.
#[test]
fn set_timing_refuses_beyond_the_proven_range() {
    let max_gap_s = capsule_mpc_max_gap_s();
    // The default config: 20 ms tracking, 10 ms more proven.
    assert!((max_gap_s - 0.03).abs() < 1e-12, "{max_gap_s}");
    let mut b = initialized();
    let h = handle(&mut b);
    unsafe {
        for (tracking_s, delay_s) in [(0.1, 0.0), (0.02, 0.012), (0.0, 0.04), (1.0, 1.0)] {
            assert_eq!(
                capsule_mpc_set_timing(h, tracking_s, delay_s),
                CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN,
                "{tracking_s} + {delay_s}"
            );
        }
        for (tracking_s, delay_s) in [(-0.01, 0.0), (0.02, -1e-3)] {
            assert_eq!(
                capsule_mpc_set_timing(h, tracking_s, delay_s),
                CAPSULE_MPC_ERR_BAD_SETTING,
                "{tracking_s} + {delay_s}"
            );
        }
        for bad in [f64::NAN, f64::INFINITY] {
            assert_eq!(
                capsule_mpc_set_timing(h, bad, 0.0),
                CAPSULE_MPC_ERR_NON_FINITE
            );
            assert_eq!(
                capsule_mpc_set_timing(h, 0.02, bad),
                CAPSULE_MPC_ERR_NON_FINITE
            );
        }
        assert_eq!(capsule_mpc_set_timing(h, 0.025, 0.005), CAPSULE_MPC_OK);
        assert_eq!(capsule_mpc_set_timing(h, 0.02, 0.0), CAPSULE_MPC_OK);
        let mut samples = start_loop(h);
        let mut grads = [0.0; 256];
        let mut status = 0i32;
        assert_eq!(
            capsule_mpc_set_timing(h, 0.03, 0.0),
            CAPSULE_MPC_ERR_LOOP_RUNNING
        );
        // The next frame more than the proven gap after the actuation end.
        let end_s = 0.02 + samples as f64 * 0.02;
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, end_s + max_gap_s + 0.002, 0),
            CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN
        );
        // Within it, then an actuation start that makes the gap too long.
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, end_s + 0.001, 0),
            CAPSULE_MPC_OK
        );
        assert_eq!(
            capsule_mpc_next_actuation(
                h,
                end_s + max_gap_s + 0.002,
                grads.as_mut_ptr(),
                256,
                &mut samples,
                &mut status
            ),
            CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN
        );
        assert_eq!(
            capsule_mpc_next_actuation(
                h,
                end_s + max_gap_s,
                grads.as_mut_ptr(),
                256,
                &mut samples,
                &mut status
            ),
            CAPSULE_MPC_OK
        );
    }
}
