//! `simulate --pulseq FILE.seq`: the run as it was played, written as a
//! Pulseq sequence by the `capsule-mpc-pulseq` crate.
//!
//! The run report holds the plant's rows (`t`, `u`, `phase`) and the
//! measurements; this module turns them into the played timeline the writer
//! takes: one actuation sample per sample time of each actuation phase, one
//! tracking phase (of the config's tracking time) at each measurement's time,
//! and pauses for the rest (the computation delay after tracking). The limits
//! and the placeholder tracking event come from the config's `[scanner]`.

use anyhow::{bail, Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::tables::{config_hash, hex};
use capsule_mpc_pulseq::{
    gradient_raster_steps, write_sequence_file, ActuationSample, PlayedRun, ScannerLimits,
    Sequence, SequenceOptions, TrackingPhase, TrackingPlaceholder,
};
use capsule_mpc_sim::plant::Phase;
use capsule_mpc_sim::report::RunReport;
use std::path::Path;

/// Times closer than this are the same instant, s (rows accumulate rounding).
const TIME_TOLERANCE_S: f64 = 1e-9;

/// The writer's limits and placeholder from the config's `[scanner]` section.
pub fn sequence_options(config: &Config) -> SequenceOptions {
    let s = &config.scanner;
    SequenceOptions {
        limits: ScannerLimits::new(
            s.max_gradient_t_per_m,
            s.slew_rate_or_default_t_per_m_per_s(),
            s.gradient_raster_or_default_s(),
        ),
        tracking: TrackingPlaceholder {
            rf_duration_s: s.tracking_rf_duration_or_default_s(),
            adc_duration_s: s.tracking_adc_duration_or_default_s(),
            ..TrackingPlaceholder::default()
        },
    }
}

/// Before a run is simulated for `--pulseq`: its sample time, tracking time
/// and extra delay must each be a whole number of the gradient raster, since
/// every block of the file starts on it (a scanner plays on its raster). The
/// error names the setting and the raster, instead of a sample after the run.
pub fn check_timing_on_raster(config: &Config, extra_delay_s: f64) -> Result<()> {
    let raster_s = config.scanner.gradient_raster_or_default_s();
    for (name, value) in [
        ("controller.sample_time_s", config.controller.sample_time_s),
        ("scanner.tracking_time_s", config.scanner.tracking_time_s),
        (
            "the extra delay (--extra-delay or scanner.extra_delay_s)",
            extra_delay_s,
        ),
    ] {
        if let Err(e) = gradient_raster_steps(name, value, raster_s) {
            bail!("--pulseq: {e} (scanner.gradient_raster_s); every block of the sequence starts on the raster");
        }
    }
    Ok(())
}

/// The played timeline of `report`: actuation samples of `sample_time_s`,
/// tracking phases of `tracking_time_s` starting at each measurement (none for
/// ideal sampling, whose measurements take no time), and the run's metadata.
pub fn played_run(
    report: &RunReport,
    config: &Config,
    sample_time_s: f64,
    tracking_time_s: f64,
) -> Result<PlayedRun> {
    for (name, value) in [
        ("sample time", sample_time_s),
        ("tracking time", tracking_time_s),
    ] {
        if !(value.is_finite() && value > 0.0) {
            bail!("the {name} {value} s must be positive and finite");
        }
    }
    let (t, u, phase) = (&report.t, &report.u, &report.phase);
    if t.is_empty() || t.len() != u.len() || t.len() != phase.len() {
        bail!(
            "run report rows are inconsistent: {} times, {} gradients, {} phases",
            t.len(),
            u.len(),
            phase.len()
        );
    }
    let mut run = PlayedRun {
        sample_time_s,
        duration_s: t[t.len() - 1] - t[0],
        ..PlayedRun::default()
    };

    // Actuation phases: maximal runs of rows in Phase::Actuate; rows are
    // sub-steps, so a phase spans a whole number of samples.
    let last = t.len() - 1;
    let mut k = 0;
    while k < last {
        if phase[k] != Phase::Actuate {
            k += 1;
            continue;
        }
        let start = k;
        while k < last && phase[k] == Phase::Actuate {
            k += 1;
        }
        let (t0, t1) = (t[start], t[k]);
        let samples = ((t1 - t0) / sample_time_s).round();
        if samples < 1.0 || (samples * sample_time_s - (t1 - t0)).abs() > TIME_TOLERANCE_S {
            bail!(
                "actuation from {t0} s to {t1} s is not a whole number of {sample_time_s} s samples"
            );
        }
        // Rows are in time order: walk them once, sample by sample.
        let mut r = start;
        for j in 0..samples as usize {
            let s0 = t0 + j as f64 * sample_time_s;
            let s1 = s0 + sample_time_s;
            let mut gradient = None;
            while r < k && t[r] < s1 - TIME_TOLERANCE_S {
                match gradient {
                    None => gradient = Some(u[r]),
                    Some(g) if g != u[r] => {
                        bail!("the gradient changes within the sample starting at {s0} s")
                    }
                    _ => {}
                }
                r += 1;
            }
            let gradient_t_per_m =
                gradient.with_context(|| format!("no row of the run at the sample at {s0} s"))?;
            run.samples.push(ActuationSample {
                start_s: s0 - t[0],
                gradient_t_per_m,
            });
        }
    }

    // Tracking phases: one per measurement that took time (not ideal sampling).
    for m in &report.measurements {
        if m.available_s - m.t_s <= TIME_TOLERANCE_S {
            continue;
        }
        let end = m.t_s + tracking_time_s;
        // The rows from the measurement to the end of its tracking time.
        let from = t.partition_point(|&tr| tr < m.t_s - TIME_TOLERANCE_S);
        let to = t
            .partition_point(|&tr| tr < end - TIME_TOLERANCE_S)
            .min(last);
        let rows_track = from < to && phase[from..to].iter().all(|&p| p == Phase::Track);
        if !rows_track || m.available_s < end - TIME_TOLERANCE_S {
            bail!(
                "the measurement at {} s is not followed by {tracking_time_s} s of tracking in the run",
                m.t_s
            );
        }
        run.tracking.push(TrackingPhase {
            start_s: m.t_s - t[0],
            duration_s: tracking_time_s,
        });
    }

    let target: Vec<String> = report.target.iter().map(|v| format!("{v}")).collect();
    run.metadata = vec![
        (
            "CapsuleMpcVersion".into(),
            env!("CARGO_PKG_VERSION").to_string(),
        ),
        (
            "CapsuleMpcConfigSha256".into(),
            format!("sha256:{}", hex(&config_hash(config))),
        ),
        ("CapsuleMpcTargetSi".into(), target.join(" ")),
    ];
    for (key, value) in [
        ("CapsuleMpcScenario", report.scenario.clone()),
        ("CapsuleMpcSampling", report.sampling.clone()),
        ("CapsuleMpcDisturbance", report.disturbance.clone()),
        ("CapsuleMpcSeed", report.seed.map(|s| s.to_string())),
    ] {
        if let Some(value) = value {
            run.metadata.push((key.into(), value));
        }
    }
    Ok(run)
}

/// Writes `report` as a Pulseq file at `path` (atomically), with the limits and
/// the placeholder tracking event of `config`.
pub fn write_pulseq(path: &Path, report: &RunReport, config: &Config) -> Result<Sequence> {
    let run = played_run(
        report,
        config,
        config.controller.sample_time_s,
        config.scanner.tracking_time_s,
    )
    .context("reading the run's timeline for the Pulseq export")?;
    write_sequence_file(path, &run, &sequence_options(config))
        .with_context(|| format!("writing the Pulseq sequence {}", path.display()))
}
