//! `simulate --pulseq`: the played timeline taken from a closed-loop run, and
//! the file written from it (the pypulseq round trip is tests/pulseq/run.sh).

use capsule_mpc::pulseq_export::{
    check_timing_on_raster, played_run, sequence_options, write_pulseq,
};
use capsule_mpc_generator::config::Config;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::plant::Phase;
use capsule_mpc_sim::report::RunReport;

const C: [f64; 4] = [0.02, 0.0, -0.01, 0.0];

fn simulate(sampling: Sampling, extra_delay_s: f64) -> (Config, RunReport) {
    let config = Config::embedded_default();
    let mut opts = RunOptions::new(&config, C.to_vec(), sampling);
    opts.duration_s = 0.8;
    opts.extra_delay_s = extra_delay_s;
    opts.lose_every = Some(3);
    let mut report = run(&config, &opts).unwrap();
    report.scenario = Some("C".into());
    (config, report)
}

#[test]
fn the_played_run_follows_the_report() {
    for (sampling, extra_delay_s) in [
        (Sampling::Constant, 0.0),
        (Sampling::Variable, 0.004),
        (Sampling::Ideal, 0.0),
    ] {
        let (config, report) = simulate(sampling, extra_delay_s);
        let dt = config.controller.sample_time_s;
        let played = played_run(&report, &config, dt, config.scanner.tracking_time_s).unwrap();

        // Each sample holds the report's u over its sample time.
        let actuated: f64 = report
            .t
            .windows(2)
            .zip(&report.phase)
            .filter(|(_, p)| **p == Phase::Actuate)
            .map(|(w, _)| w[1] - w[0])
            .sum();
        assert!((played.samples.len() as f64 * dt - actuated).abs() < 1e-9);
        for s in &played.samples {
            let row = report
                .t
                .iter()
                .position(|&t| (t - s.start_s).abs() < 1e-9)
                .expect("a row at each sample start");
            assert_eq!(report.u[row], s.gradient_t_per_m);
        }
        // One tracking phase per measurement (lost ones included), none for ideal.
        let expected = if sampling == Sampling::Ideal {
            0
        } else {
            report.measurements.len()
        };
        assert_eq!(played.tracking.len(), expected, "{sampling:?}");
        assert!(report.measurements.iter().any(|m| m.lost) || sampling == Sampling::Ideal);
        for (phase, m) in played.tracking.iter().zip(&report.measurements) {
            assert_eq!(phase.start_s, m.t_s);
            assert_eq!(phase.duration_s, config.scanner.tracking_time_s);
        }
        assert_eq!(played.duration_s, report.t[report.t.len() - 1]);
        let keys: Vec<&str> = played.metadata.iter().map(|(k, _)| k.as_str()).collect();
        for key in [
            "CapsuleMpcConfigSha256",
            "CapsuleMpcTargetSi",
            "CapsuleMpcSampling",
            "CapsuleMpcScenario",
        ] {
            assert!(keys.contains(&key), "{key} in {keys:?}");
        }

        // Written, the file has a block per sample and per tracking phase,
        // and pauses for the extra delay.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.seq");
        let seq = write_pulseq(&path, &report, &config).unwrap();
        assert_eq!(seq.actuation_blocks, played.samples.len());
        assert_eq!(seq.tracking_blocks, expected);
        let pauses = if extra_delay_s > 0.0 { expected } else { 0 };
        assert_eq!(seq.delay_blocks, pauses, "{sampling:?}");
        assert!((seq.duration_s - played.duration_s).abs() < 1e-9);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\nCapsuleMpcSampling "));
        assert!(text.contains("\nCapsuleMpcConfigSha256 sha256:"));
        assert!(text.contains("\nCapsuleMpcSlewRateTPerMPerS 200\n"));
    }
}

#[test]
fn the_config_sets_the_limits_and_the_placeholder() {
    let mut config = Config::embedded_default();
    let opts = sequence_options(&config);
    assert_eq!(opts.limits.max_gradient_t_per_m, 0.04);
    assert_eq!(opts.limits.slew_rate_t_per_m_per_s, 200.0);
    assert_eq!(opts.limits.gradient_raster_s, 10e-6);
    assert_eq!(opts.tracking.rf_duration_s, 1e-3);
    assert_eq!(opts.tracking.adc_duration_s, 10.24e-3);

    config.scanner.slew_rate_t_per_m_per_s = Some(120.0);
    config.scanner.gradient_raster_s = Some(20e-6);
    config.scanner.tracking_rf_duration_s = Some(0.5e-3);
    config.scanner.tracking_adc_duration_s = Some(5.12e-3);
    let opts = sequence_options(&config);
    assert_eq!(opts.limits.slew_rate_t_per_m_per_s, 120.0);
    assert_eq!(opts.limits.gradient_raster_s, 20e-6);
    assert_eq!(opts.limits.block_duration_raster_s, 20e-6);
    assert_eq!(opts.tracking.rf_duration_s, 0.5e-3);
    assert_eq!(opts.tracking.adc_duration_s, 5.12e-3);
}

#[test]
fn a_slew_limit_the_run_cannot_meet_is_an_error_naming_the_sample() {
    let (mut config, report) = simulate(Sampling::Variable, 0.0);
    // At 1 T/m/s no full-scale step fits in a 20 ms sample.
    config.scanner.slew_rate_t_per_m_per_s = Some(1.0);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.seq");
    let err = format!("{:#}", write_pulseq(&path, &report, &config).unwrap_err());
    assert!(
        err.contains("actuation sample") && err.contains("slew-rate limit of 1 T/m/s"),
        "{err}"
    );
    assert!(!path.exists());
}

/// Timing off the gradient raster is refused before anything is simulated
/// or written, naming the setting; on the raster it passes.
#[test]
fn timing_off_the_raster_is_refused_before_the_run() {
    let config = Config::embedded_default();
    check_timing_on_raster(&config, 0.0).unwrap();
    check_timing_on_raster(&config, 0.013).unwrap();
    let err = check_timing_on_raster(&config, 0.0123456)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("extra delay") && err.contains("0.0123456") && err.contains("raster"),
        "{err}"
    );
    let mut odd = config.clone();
    odd.scanner.tracking_time_s = 0.020_005;
    let err = check_timing_on_raster(&odd, 0.0).unwrap_err().to_string();
    assert!(err.contains("scanner.tracking_time_s"), "{err}");

    // Through the command line: one error line, exit 1, no file written.
    let dir = tempfile::tempdir().unwrap();
    let (seq, json) = (dir.path().join("run.seq"), dir.path().join("run.json"));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_capsule-mpc"))
        .args([
            "simulate",
            "--scenario",
            "A",
            "--sampling",
            "variable",
            "--extra-delay",
            "0.0023456",
        ])
        .arg("--pulseq")
        .arg(&seq)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.starts_with("error: --pulseq: the extra delay"),
        "{stderr}"
    );
    assert!(!seq.exists() && !json.exists());
}
