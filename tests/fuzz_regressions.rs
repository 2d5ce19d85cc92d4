//! Replays the fuzz inputs kept in the repository through the fuzz
//! harnesses (`fuzz/src/lib.rs`, included here as a module) in a normal
//! `cargo test`: every crash the fuzzers found (`fuzz/regressions/<target>/`)
//! and the seed corpus (`fuzz/seeds/<target>/`). A harness panics when a
//! contract breaks, so a regression fails this test. See fuzz/README.md.

#[path = "../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod harness;

use std::path::{Path, PathBuf};

/// Files under `fuzz/<kind>/<target>/`, sorted (none if the folder is missing).
fn inputs(kind: &str, target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz")
        .join(kind)
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}

fn replay(target: &str, harness: fn(&[u8])) {
    let seeds = inputs("seeds", target);
    assert!(!seeds.is_empty(), "no seeds for {target}");
    for path in seeds.iter().chain(&inputs("regressions", target)) {
        let data = std::fs::read(path).unwrap();
        let outcome = std::panic::catch_unwind(|| harness(&data));
        assert!(
            outcome.is_ok(),
            "{target}: {} breaks a contract (see the panic above)",
            path.display()
        );
    }
}

#[test]
fn config_inputs() {
    replay("config", harness::config);
}

#[test]
fn capi_inputs() {
    replay("capi", harness::capi);
}

#[test]
fn runtime_inputs() {
    replay("runtime", harness::runtime);
}
