//! `capsule-mpc calibrate` through the binary: malformed logs get one
//! clear error line each (line and column), and nothing is written; a log
//! written by another program in the documented CSV format is read and
//! fitted; `--design` writes the excitation as CSV and Pulseq.

use std::path::Path;
use std::process::{Command, Output};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"));
    c.env("RUST_BACKTRACE", "1");
    c
}

fn calibrate(dir: &Path, log: &str) -> Output {
    let path = dir.join("log.csv");
    std::fs::write(&path, log).unwrap();
    bin()
        .args(["calibrate", "--min-measurements", "2", "--log"])
        .arg(&path)
        .arg("--out")
        .arg(dir.join("fitted.toml"))
        .arg("--json")
        .arg(dir.join("cal.json"))
        .output()
        .unwrap()
}

#[test]
fn malformed_logs_get_one_error_line_and_nothing_is_written() {
    let header = "t_s,gradient_t_per_m,x1_m,x2_m\n";
    let cases = [
        (
            "t_s,gradient_t_per_m,x1_m\n0,0,0\n",
            "line 1, column 4: missing column `x2_m`",
        ),
        (
            &format!("{header}0,0,0,0\n0.02,x,,\n0.04,0,0,0\n"),
            "line 3, column 2: gradient `x` is not a number",
        ),
        (
            &format!("{header}0,0,0,0\n0.02,0,1e-3,0\n0.01,0,0,0\n"),
            "line 4, column 1: time 0.01 s does not follow 0.02 s",
        ),
        (
            &format!("{header}0,0,0,0\n"),
            "capsule 1 has 1 measurements, at least 2 needed",
        ),
        (
            &format!("{header}0,0,0,0\n0.02,0,inf,0\n"),
            "line 3, column 3: position inf is not finite",
        ),
        (
            &format!("{header}0,0,0,0,0\n"),
            "line 2, column 5: 5 fields, expected 4",
        ),
    ];
    for (log, needle) in cases {
        let dir = tempfile::tempdir().unwrap();
        let out = calibrate(dir.path(), log);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "one line: {stderr:?}");
        assert!(
            lines[0].starts_with("error: ") && lines[0].contains(needle),
            "`{needle}` not in {stderr:?}"
        );
        assert!(!dir.path().join("fitted.toml").exists() && !dir.path().join("cal.json").exists());
    }
}

/// Another program's log: a coasting and pushed capsule pair written by
/// hand with the documented header (positions on tracking rows only),
/// made from the model itself: the fit recovers the config's constants.
#[test]
fn a_log_in_the_documented_format_is_read_and_fitted() {
    let dir = tempfile::tempdir().unwrap();
    let design = dir.path().join("exc.csv");
    let seq = dir.path().join("exc.seq");
    let out = bin()
        .args(["calibrate", "--design", "--duration", "6", "--csv"])
        .arg(&design)
        .arg("--pulseq")
        .arg(&seq)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::read_to_string(&seq).unwrap().contains("[BLOCKS]"));
    // Fill in the positions with the model (this test's own integrator,
    // 0.1 ms RK4): another program measuring the plant.
    let text = std::fs::read_to_string(&design).unwrap();
    let model = capsule_mpc_generator::model::Model::from_config(
        &capsule_mpc_generator::config::Config::embedded_default(),
    );
    let mut state = [[0.0f64; 2]; 2];
    let mut rows: Vec<(f64, f64)> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        rows.push((f[0].parse().unwrap(), f[1].parse().unwrap()));
    }
    let mut csv = String::from("t_s,gradient_t_per_m,x1_m,x2_m\n");
    for k in 0..rows.len() {
        let (t, u) = rows[k];
        if u == 0.0 {
            csv.push_str(&format!("{t},{u},{},{}\n", state[0][0], state[1][0]));
        } else {
            csv.push_str(&format!("{t},{u},,\n"));
        }
        if k + 1 < rows.len() {
            let dt = rows[k + 1].0 - t;
            let n = (dt / 1e-4).ceil() as usize;
            let h = dt / n as f64;
            for (i, c) in model.capsules.iter().enumerate() {
                for _ in 0..n {
                    let f = |v: f64| c.drag.accel_and_slope(v).0 + c.g * u;
                    let [x, v] = state[i];
                    let (k1, k2) = (f(v), f(v + 0.5 * h * f(v)));
                    let k3 = f(v + 0.5 * h * k2);
                    let k4 = f(v + h * k3);
                    let (l1, l2, l3, l4) = (v, v + 0.5 * h * k1, v + 0.5 * h * k2, v + h * k3);
                    state[i] = [
                        x + h / 6.0 * (l1 + 2.0 * l2 + 2.0 * l3 + l4),
                        v + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4),
                    ];
                }
            }
        }
    }
    let out = calibrate(dir.path(), &csv);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cal: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("cal.json")).unwrap())
            .unwrap();
    for (i, c) in cal["capsules"].as_array().unwrap().iter().enumerate() {
        let (g, b) = (c["gain"].as_f64().unwrap(), c["drag"].as_f64().unwrap());
        let (g0, b0) = (
            model.capsules[i].g,
            model.capsules[i].drag.effective_b_per_m(0.1),
        );
        assert!(
            (g / g0 - 1.0).abs() < 1e-3 && (b / b0 - 1.0).abs() < 1e-3,
            "capsule {i}: {g} vs {g0}, {b} vs {b0}"
        );
        assert!(c["gain_stderr"].as_f64().unwrap() >= 0.0 && c["drag_stderr"].is_number());
    }
    assert!(cal["residual_rms_m"].as_f64().unwrap() < 1e-6);
    // The fitted config is one `generate` takes: it loads and validates.
    let fitted =
        capsule_mpc_generator::config::Config::from_file(&dir.path().join("fitted.toml")).unwrap();
    assert!(fitted
        .capsule
        .iter()
        .all(|c| c.gain_m_per_s2_per_t_per_m.is_some() && c.drag_per_m.is_some()));
}
