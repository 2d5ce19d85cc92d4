//! `capsule_mpc_set_model_factors`: a calibration's factors, bad values
//! refused with their code, a refused call changing nothing.

// The two-capsule library (the default build).
#![cfg(not(feature = "three-capsules"))]

use capsule_mpc_capi::*;

#[path = "common/handle.rs"]
mod handle;
use handle::*;

#[test]
fn set_model_factors_bad_args() {
    let mut b = initialized();
    let h = handle(&mut b);
    unsafe {
        assert_eq!(
            capsule_mpc_set_model_factors(h, 1, 0.9, 1.2, 0.01, 0.02),
            CAPSULE_MPC_OK
        );
        for (capsule, gain, drag, gs, ds, code) in [
            (2, 1.0, 1.0, 0.01, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (u32::MAX, 1.0, 1.0, 0.01, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (0, f64::NAN, 1.0, 0.01, 0.01, CAPSULE_MPC_ERR_NON_FINITE),
            (
                0,
                1.0,
                f64::INFINITY,
                0.01,
                0.01,
                CAPSULE_MPC_ERR_NON_FINITE,
            ),
            (0, 1.0, 1.0, f64::NAN, 0.01, CAPSULE_MPC_ERR_NON_FINITE),
            (0, 0.1, 1.0, 0.01, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (0, 1.0, 5.0, 0.01, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (0, 1.0, -1.0, 0.01, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (0, 1.0, 1.0, 0.0, 0.01, CAPSULE_MPC_ERR_BAD_SETTING),
            (0, 1.0, 1.0, 0.01, 2.0, CAPSULE_MPC_ERR_BAD_SETTING),
        ] {
            assert_eq!(
                capsule_mpc_set_model_factors(h, capsule, gain, drag, gs, ds),
                code,
                "capsule {capsule} factors ({gain}, {drag}) deviations ({gs}, {ds})"
            );
        }
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        // A refused call leaves the factors it was given before.
        assert_eq!(
            capsule_mpc_set_model_factors(h, 1, 0.9, 1.2, 0.01, 0.02),
            CAPSULE_MPC_OK
        );
    }
}
