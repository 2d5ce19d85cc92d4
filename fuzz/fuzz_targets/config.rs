//! cargo-fuzz target: see `capsule_mpc_fuzz::config`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| capsule_mpc_fuzz::config(data));
