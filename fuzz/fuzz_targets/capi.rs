//! cargo-fuzz target: see `capsule_mpc_fuzz::capi`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| capsule_mpc_fuzz::capi(data));
