//! A handle in caller-owned memory, as a C host holds it, for the C ABI
//! tests.

use capsule_mpc_capi::*;

#[repr(C, align(64))]
pub struct Buf(pub [u8; 1 << 16]);

pub fn zeroed_buf() -> Box<Buf> {
    Box::new(Buf([0; 1 << 16]))
}

pub fn handle(b: &mut Buf) -> *mut CapsuleMpc {
    b.0.as_mut_ptr().cast()
}

pub const ORIGIN: [f64; 2] = [0.0, 0.0];
pub const TARGET_C: [f64; 4] = [0.02, 0.0, -0.01, 0.0];

pub fn initialized() -> Box<Buf> {
    let mut b = zeroed_buf();
    let size = b.0.len();
    let rc = unsafe { capsule_mpc_init(b.0.as_mut_ptr().cast(), size, ORIGIN.as_ptr(), 2) };
    assert_eq!(rc, CAPSULE_MPC_OK);
    b
}
