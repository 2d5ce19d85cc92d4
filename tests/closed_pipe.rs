//! A reader that closes the pipe early (`capsule-mpc simulate ... | head -1`)
//! is the reader's choice: the command still writes its files and exits 0,
//! with no panic on stderr.

use std::process::{Command, Stdio};

/// Runs the binary with `args`, its stdout a pipe whose read end is closed
/// before the command writes; returns (success, stderr).
fn run_with_closed_stdout(args: &[&str]) -> (bool, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn simulate_and_reach_into_a_closed_pipe_still_write_their_json() {
    let dir = tempfile::tempdir().unwrap();
    let run_json = dir.path().join("run.json");
    let (ok, stderr) = run_with_closed_stdout(&[
        "simulate",
        "--scenario",
        "C",
        "--sampling",
        "ideal",
        "--disturbance",
        "none",
        "--duration",
        "1",
        "--json",
        run_json.to_str().unwrap(),
    ]);
    assert!(ok, "simulate failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&run_json).unwrap()).unwrap();
    assert!(run["metrics"]["settle_time_s"].as_f64().is_some());

    let reach_json = dir.path().join("reach.json");
    let (ok, stderr) = run_with_closed_stdout(&[
        "reach",
        "--range-cm",
        "1",
        "--json",
        reach_json.to_str().unwrap(),
    ]);
    assert!(ok, "reach failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let reach: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&reach_json).unwrap()).unwrap();
    assert_eq!(reach["summary"]["targets"].as_u64(), Some(8));
}
