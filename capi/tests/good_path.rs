//! The good path through the C functions: scenario C closed through the
//! ABI under each sampling mode, and a wrong reset mid-run that the loop
//! re-acquires.

use capsule_mpc_capi::*;

#[path = "common/handle.rs"]
mod handle;
use handle::*;

#[path = "common/plant.rs"]
mod plant;

/// Holds `u` for 20 ms at 1 ms RK4 steps.
fn hold(s: &mut [f64; 4], u: f64) {
    plant::hold_for(s, u, 0.02);
}

/// Scenario C through the C functions; returns the final plant state.
fn closed_loop(mode: i32) -> [f64; 4] {
    let mut b = initialized();
    let h = handle(&mut b);
    let (mut m, mut n, mut k, mut dt, mut u_max) = (0u32, 0u32, 0u32, 0.0, 0.0);
    let mut grads = vec![0.0; 256];
    let mut s = [0.0; 4];
    let mut t = 0.0;
    unsafe {
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, &mut u_max),
            CAPSULE_MPC_OK
        );
        assert_eq!(capsule_mpc_set_sampling(h, mode), CAPSULE_MPC_OK);
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        while t < 3.0 - 1e-9 {
            if mode == CAPSULE_MPC_SAMPLING_IDEAL {
                assert_eq!(capsule_mpc_feed_state(h, s.as_ptr(), 4), CAPSULE_MPC_OK);
            } else {
                let z = [s[0], s[2]];
                hold(&mut s, 0.0);
                assert_eq!(
                    capsule_mpc_feed_tracking(h, z.as_ptr(), 2, t, 0),
                    CAPSULE_MPC_OK
                );
                t += 0.02;
            }
            let (mut samples, mut status) = (0u32, -1i32);
            let rc = capsule_mpc_next_actuation(
                h,
                t,
                grads.as_mut_ptr(),
                k as usize,
                &mut samples,
                &mut status,
            );
            assert_eq!(rc, CAPSULE_MPC_OK);
            assert!(samples >= 1 && samples <= n);
            for &u in &grads[..samples as usize] {
                assert!(u.abs() <= u_max);
                hold(&mut s, u);
                t += dt;
            }
        }
    }
    s
}

#[test]
fn good_path_closed_loop_scenario_c() {
    for mode in [CAPSULE_MPC_SAMPLING_CONSTANT, CAPSULE_MPC_SAMPLING_IDEAL] {
        let s = closed_loop(mode);
        let e1 = (s[0] - TARGET_C[0]).abs();
        let e2 = (s[2] - TARGET_C[2]).abs();
        assert!(e1 <= 1e-3 && e2 <= 1e-3, "mode {mode}: final state {s:?}");
    }
}

/// A wrong `capsule_mpc_reset` mid-run (15 and 12 mm off): the next frames
/// are rejected, the REACQUIRE_AFTER_REJECTIONS-th reports
/// CAPSULE_MPC_STATUS_REACQUIRED (also from last_status), and the loop
/// still reaches scenario C with |u| <= u_max. The reset comes at 0.5 s,
/// mid-manoeuvre (the minimum-time plans move fast then); the run lasts
/// 6 s, room for the re-acquired plan (one table variant measured 3.6 mm
/// off and still moving at 4 s).
#[test]
fn wrong_reset_is_reacquired_through_the_c_abi() {
    const END_S: f64 = 6.0;
    use capsule_mpc_runtime::controller::REACQUIRE_AFTER_REJECTIONS;
    let mut b = initialized();
    let h = handle(&mut b);
    let (mut m, mut n, mut k, mut dt, mut u_max) = (0u32, 0u32, 0u32, 0.0, 0.0);
    let mut grads = vec![0.0; 256];
    let mut s = [0.0; 4];
    let mut t = 0.0;
    let mut statuses = Vec::new();
    let mut reset_at = None;
    unsafe {
        assert_eq!(
            capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, &mut u_max),
            CAPSULE_MPC_OK
        );
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        while t < END_S - 1e-9 {
            if reset_at.is_none() && t >= 0.5 {
                let wrong = [s[0] + 0.015, s[2] - 0.012];
                assert_eq!(capsule_mpc_reset(h, wrong.as_ptr(), 2), CAPSULE_MPC_OK);
                reset_at = Some(statuses.len());
            }
            let z = [s[0], s[2]];
            hold(&mut s, 0.0);
            assert_eq!(
                capsule_mpc_feed_tracking(h, z.as_ptr(), 2, t, 0),
                CAPSULE_MPC_OK
            );
            t += 0.02;
            let (mut samples, mut status) = (0u32, -1i32);
            let rc = capsule_mpc_next_actuation(
                h,
                t,
                grads.as_mut_ptr(),
                k as usize,
                &mut samples,
                &mut status,
            );
            assert_eq!(rc, CAPSULE_MPC_OK);
            let mut last = -1;
            assert_eq!(capsule_mpc_last_status(h, &mut last), CAPSULE_MPC_OK);
            assert_eq!(last, status);
            statuses.push(status);
            for &u in &grads[..samples as usize] {
                assert!(u.abs() <= u_max);
                hold(&mut s, u);
                t += dt;
            }
        }
    }
    let after = &statuses[reset_at.expect("reset happened")..];
    let n_reject = REACQUIRE_AFTER_REJECTIONS - 1;
    assert!(
        after[..n_reject]
            .iter()
            .all(|&st| st == CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED),
        "{after:?}"
    );
    assert_eq!(after[n_reject], CAPSULE_MPC_STATUS_REACQUIRED, "{after:?}");
    assert!(
        !after[n_reject + 1..].contains(&CAPSULE_MPC_STATUS_REACQUIRED),
        "{after:?}"
    );
    let e1 = (s[0] - TARGET_C[0]).abs();
    let e2 = (s[2] - TARGET_C[2]).abs();
    assert!(e1 <= 1e-3 && e2 <= 1e-3, "final state {s:?}");
}
