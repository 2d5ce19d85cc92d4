//! A loop aimed at target C with its first frame fed, ready for its first
//! actuation, for the C ABI tests that call or refuse that actuation.

use super::handle::{ORIGIN, TARGET_C};
use capsule_mpc_capi::*;

/// Sets target C on `h` and feeds a frame at the origin at 0 s.
pub fn aim_at_c_with_a_frame(h: *mut CapsuleMpc) {
    unsafe {
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
        assert_eq!(
            capsule_mpc_feed_tracking(h, ORIGIN.as_ptr(), 2, 0.0, 0),
            CAPSULE_MPC_OK
        );
    }
}
