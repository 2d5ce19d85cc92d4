//! `capsule-mpc bench --states 2000 --json FILE` writes the documented fields
//! with sane values (timings are machine-dependent: only their shape is checked).

use std::process::Command;

/// `capsule-mpc bench ARGS --json PATH`, which must succeed: its JSON.
fn bench_json(args: &[&str], path: &std::path::Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"))
        .arg("bench")
        .args(args)
        .arg("--json")
        .arg(path)
        .output()
        .expect("run capsule-mpc");
    assert!(
        out.status.success(),
        "bench failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn bench_writes_json_with_sane_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.json");
    let v = bench_json(&["--states", "2000", "--peer-states", "60"], &path);
    assert_eq!(v["states"], 2000);
    for key in ["step_ns", "solver_ns", "step_cold_ns", "solver_cold_ns"] {
        let t = &v[key];
        let (median, p99, p999, max) = (
            t["median"].as_u64().unwrap(),
            t["p99"].as_u64().unwrap(),
            t["p999"].as_u64().unwrap(),
            t["max"].as_u64().unwrap(),
        );
        assert!(median > 0, "{key}: {t}");
        assert!(median <= p99 && p99 <= p999 && p999 <= max, "{key}: {t}");
    }
    let it = &v["iterations"];
    let max_it = it["max"].as_u64().unwrap();
    assert!(max_it >= 1 && max_it <= it["qp_max_iterations_bound"].as_u64().unwrap());
    let hist = it["histogram"].as_object().unwrap();
    // Two timed solves per state (cold and warm).
    assert_eq!(
        hist.values().map(|c| c.as_u64().unwrap()).sum::<u64>(),
        4000
    );
    assert!(hist.keys().all(|k| k.parse::<u64>().unwrap() <= max_it));
    for peer in ["clarabel", "open", "active-set"] {
        let p = &v["peers"][peer];
        let (median, max) = (
            p["median_ns"].as_u64().unwrap(),
            p["max_ns"].as_u64().unwrap(),
        );
        assert!(median > 0 && max >= median, "{peer}: {p}");
        assert!(p["max_abs_du"].as_f64().unwrap().is_finite(), "{peer}: {p}");
    }
    // OSQP is present either measured or marked skipped (feature peers-osqp).
    assert!(v["peers"]["osqp"].is_object());
    // The reference loop with the active-set engine reproduces the generated solver.
    assert!(
        v["peers"]["reference_check"]["max_abs_u0_vs_generated"]
            .as_f64()
            .unwrap()
            < 1e-6
    );
    assert_eq!(v["allocations_per_step"], 0);
    assert!(v["workspace_bytes"].as_u64().unwrap() > 0);
    assert!(v["table_bytes"].as_u64().unwrap() > 0);
    assert_eq!(v["worst_states"].as_array().unwrap().len(), 5);
}

/// `bench --config configs/three-capsules.toml`: the three-capsule
/// controller step, timed over its own states; a config with no compiled
/// controller is refused with a message that says how to generate one.
#[test]
fn bench_times_the_three_capsule_module() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench3.json");
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/three-capsules.toml");
    let v = bench_json(
        &[
            "--config",
            config,
            "--sampling",
            "variable",
            "--states",
            "300",
        ],
        &path,
    );
    assert_eq!(v["capsules"], 3);
    assert_eq!(v["module"], "three_capsules");
    assert_eq!(v["sampling"], "variable");
    for (key, t) in v["controller_step_ns"].as_object().unwrap() {
        let (median, p99, max) = (
            t["median"].as_u64().unwrap(),
            t["p99"].as_u64().unwrap(),
            t["max"].as_u64().unwrap(),
        );
        assert!(median > 0 && median <= p99 && p99 <= max, "{key}: {t}");
    }

    let other = dir.path().join("other.toml");
    let text = std::fs::read_to_string(config).unwrap();
    assert!(text.contains("0.47"), "the preset's drag coefficient moved");
    std::fs::write(&other, text.replacen("0.47", "0.48", 1)).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"))
        .args(["bench", "--config"])
        .arg(&other)
        .output()
        .expect("run capsule-mpc");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("no compiled controller"), "{stderr}");
}
