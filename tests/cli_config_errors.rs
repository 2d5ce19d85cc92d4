//! The binary's contract on bad configs: non-zero exit, one `error:` line that
//! names the field, no panic; and `inspect --json` on the default config.

use capsule_mpc_generator::config::DEFAULT_CONFIG_TOML;
use std::process::{Command, Output};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"));
    // A backtrace request must not turn an error into a multi-line dump.
    c.env("RUST_BACKTRACE", "1");
    c
}

fn inspect_with(toml: &str) -> Output {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, toml).unwrap();
    bin()
        .args(["inspect", "--config"])
        .arg(&path)
        .output()
        .unwrap()
}

fn assert_one_line_error(out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "exit status {:?}, stderr {stderr}",
        out.status
    );
    assert_eq!(out.status.code(), Some(1), "stderr {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "stderr must be one line: {stderr:?}");
    assert!(lines[0].starts_with("error: "), "{stderr:?}");
    assert!(lines[0].contains(needle), "`{needle}` not in {stderr:?}");
    assert!(
        !stderr.contains("panicked") && !stderr.contains("RUST_BACKTRACE"),
        "{stderr:?}"
    );
    assert!(out.stdout.is_empty(), "nothing on stdout on error");
}

fn edited(from: &str, to: &str) -> String {
    assert!(
        DEFAULT_CONFIG_TOML.contains(from),
        "default config lacks `{from}`"
    );
    DEFAULT_CONFIG_TOML.replacen(from, to, 1)
}

#[test]
fn negative_radius() {
    let out = inspect_with(&edited(
        "sphere_radius_m = 0.0015",
        "sphere_radius_m = -0.0015",
    ));
    assert_one_line_error(&out, "capsule[0].sphere_radius_m");
}

#[test]
fn capsule_smaller_than_sphere() {
    let out = inspect_with(&edited(
        "capsule_radius_m = 0.0045",
        "capsule_radius_m = 0.001",
    ));
    assert_one_line_error(&out, "capsule[0].capsule_radius_m");
}

#[test]
fn nan_value() {
    let out = inspect_with(&edited("sphere_radius_m = 0.0030", "sphere_radius_m = nan"));
    assert_one_line_error(&out, "capsule[1].sphere_radius_m");
}

#[test]
fn zero_capsules() {
    let rest = DEFAULT_CONFIG_TOML.split("[fluid]").nth(1).unwrap();
    let out = inspect_with(&format!("capsule = []\n[fluid]{rest}"));
    assert_one_line_error(&out, "`capsule`");
}

#[test]
fn unknown_field() {
    let out = inspect_with(&edited("[fluid]", "[fluid]\ntemperature_k = 310.0"));
    assert_one_line_error(&out, "temperature_k");
}

#[test]
fn missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("does-not-exist.toml");
    let out = bin()
        .args(["inspect", "--config"])
        .arg(&path)
        .output()
        .unwrap();
    assert_one_line_error(&out, "does-not-exist.toml");
}

#[test]
fn inspect_json_on_the_default() {
    let out = bin().args(["inspect", "--json"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let g: Vec<f64> = serde_json::from_value(v["g"].clone()).unwrap();
    let b: Vec<f64> = serde_json::from_value(v["b"].clone()).unwrap();
    assert_eq!(g.len(), 2);
    for gi in &g {
        assert!((gi - 173.25).abs() / 173.25 < 1e-3, "g = {gi}");
    }
    assert!((b[0] - 134.7).abs() / 134.7 < 1e-3, "b1 = {}", b[0]);
    assert!((b[1] - 16.84).abs() / 16.84 < 1e-3, "b2 = {}", b[1]);
    let capsules = v["capsules"].as_array().unwrap();
    assert_eq!(capsules.len(), 2);
    for (c, key) in capsules.iter().zip(["small", "large"]) {
        assert_eq!(c["name"], key);
        for field in [
            "g",
            "b",
            "mass_kg",
            "terminal_speed_m_per_s",
            "reynolds_at_terminal_speed",
        ] {
            assert!(c[field].as_f64().is_some_and(f64::is_finite), "{field}");
        }
    }
    assert!((capsules[0]["terminal_speed_m_per_s"].as_f64().unwrap() - 0.227).abs() < 1e-3);
    assert!(v["lipschitz_f"].as_f64().unwrap() >= 1.0);
    assert_eq!(v["config"]["capsule"].as_array().unwrap().len(), 2);
}

/// Issue 13: targets and starts outside the workspace, from the command
/// line: one error line naming the capsule, the bound and the excess; a
/// bad workspace section names its field.
#[test]
fn workspace_errors_name_the_capsule_bound_and_excess() {
    let out = bin()
        .args([
            "simulate",
            "--target",
            "0.02,0,-0.075,0",
            "--sampling",
            "ideal",
        ])
        .output()
        .unwrap();
    assert_one_line_error(
        &out,
        "capsule 2 at -0.075 m is outside the workspace [-0.06, 0.06] m by 0.0150 m (below the lower bound",
    );
    let out = bin()
        .args(["simulate", "--start", "0.07,0", "--scenario", "A"])
        .output()
        .unwrap();
    assert_one_line_error(
        &out,
        "start [0.07, 0.0] m: capsule 1 at 0.07 m is outside the workspace",
    );
    let out = bin()
        .args(["reach", "--start", "0,-0.1", "--range-cm", "1"])
        .output()
        .unwrap();
    assert_one_line_error(&out, "start: capsule 2 at -0.1 m is outside the workspace");
    let out = bin()
        .args(["simulate", "--start", "0.01", "--scenario", "A"])
        .output()
        .unwrap();
    assert_one_line_error(&out, "--start has 1 positions; the config has 2 capsules");
    let out = inspect_with(&format!(
        "{DEFAULT_CONFIG_TOML}\n[workspace]\nposition_min_m = 0.02\nposition_max_m = 0.01\n"
    ));
    assert_one_line_error(&out, "workspace.position_max_m");
}

/// A run longer than the simulator keeps in memory is refused up front
/// with the bound, not run for hours (or until memory runs out).
#[test]
fn an_overlong_run_is_refused_with_the_bound() {
    for command in ["simulate", "reach"] {
        let out = bin()
            .args([command, "--duration", "1e9"])
            .output()
            .expect("runs");
        assert_one_line_error(&out, "run duration 1000000000 s is outside (0, 600] s");
    }
}

/// `--extra-delay` is checked before anything runs: refused with ideal
/// sampling (no tracking phase to delay) and outside [0, 1] s.
#[test]
fn extra_delay_is_refused_where_it_means_nothing_or_is_out_of_range() {
    let cases: [(&[&str], &str); 4] = [
        (
            &["reach", "--range-cm", "1", "--extra-delay", "0.02"],
            "--extra-delay 0.02 applies to the scanner cycle",
        ),
        (
            &["simulate", "--sampling", "ideal", "--extra-delay", "0.02"],
            "ideal sampling has no tracking phase",
        ),
        (
            &[
                "reach",
                "--range-cm",
                "1",
                "--sampling",
                "constant",
                "--extra-delay",
                "2",
            ],
            "extra delay 2 s is outside [0, 1] s",
        ),
        (
            &["simulate", "--sampling", "constant", "--extra-delay=-0.5"],
            "extra delay -0.5 s is outside [0, 1] s",
        ),
    ];
    for (args, needle) in cases {
        let out = bin().args(args).output().unwrap();
        assert_one_line_error(&out, needle);
    }
}

/// `--lose-every 0` would lose no frame while it reads as "lose them":
/// refused, naming what N counts.
#[test]
fn losing_every_zeroth_frame_is_refused() {
    let out = bin()
        .args(["simulate", "--sampling", "constant", "--lose-every", "0"])
        .output()
        .unwrap();
    assert_one_line_error(&out, "lose every 0: N counts the tracking frames");
}

/// `--calibrated-std` is checked before anything runs: a fraction within
/// the runtime's [0.001, 1], and only with the factors it qualifies.
#[test]
fn calibrated_std_is_refused_out_of_range_or_without_factors() {
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "simulate",
                "--calibrated-gain-scale",
                "1",
                "--calibrated-std",
                "-0.1",
            ],
            "calibrated std -0.1 is outside [0.001, 1]",
        ),
        (
            &[
                "reach",
                "--calibrated-drag-scale",
                "1.2",
                "--calibrated-std",
                "nan",
            ],
            "calibrated std NaN is outside [0.001, 1]",
        ),
        (
            &[
                "reach",
                "--calibrated-drag-scale",
                "1.2",
                "--calibrated-std",
                "3",
            ],
            "calibrated std 3 is outside [0.001, 1]",
        ),
        (
            &["simulate", "--calibrated-std", "0.01"],
            "calibrated std 0.01 needs the factors it qualifies",
        ),
    ];
    for (args, needle) in cases {
        let out = bin().args(args).output().unwrap();
        assert_one_line_error(&out, needle);
    }
}

/// `--retarget` / `--retarget-at` are checked before anything runs: the
/// change must fall within the run, the new target must be a rest state
/// of the config's length inside the workspace.
#[test]
fn a_retarget_is_refused_outside_the_run_or_the_workspace() {
    let cases: [(&str, &str, &str); 6] = [
        (
            "0.02,0,-0.01,0",
            "-0.5",
            "retarget at -0.5 s: the target can change only during the run, [0, 3) s",
        ),
        (
            "0.02,0,-0.01,0",
            "3",
            "retarget at 3 s: the target can change only during the run, [0, 3) s",
        ),
        (
            "0.02,0,-0.01,0",
            "NaN",
            "retarget at NaN s: the target can change only during the run",
        ),
        (
            "0.02,0,-0.01",
            "1",
            "retarget has 3 entries; the config has 4 states",
        ),
        (
            "0.02,0,-0.09,0",
            "1",
            "capsule 2 at -0.09 m is outside the workspace [-0.06, 0.06] m by 0.0300 m",
        ),
        (
            "0.02,0.1,-0.01,0",
            "1",
            "target speeds [0.1, 0.0] m/s are not 0",
        ),
    ];
    for (target, at_s, needle) in cases {
        let out = bin()
            .args(["simulate", "--retarget", target, "--retarget-at", at_s])
            .output()
            .unwrap();
        assert_one_line_error(&out, needle);
    }
}
