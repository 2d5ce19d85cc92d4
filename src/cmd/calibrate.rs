//! `capsule-mpc calibrate`: fit the capsules' gain and drag to a tracking
//! log, or design the excitation that identifies them.

use crate::cli::{load_config, CalibrateArgs};
use anyhow::{bail, Context, Result};
use capsule_mpc_calibrate::{
    design_excitation, fit, fitted_config, Excitation, FitSettings, TrackingLog,
};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::config::DisturbanceConfig;
use capsule_mpc_generator::generate::write_file_atomically;
use capsule_mpc_generator::model::Model;
use capsule_mpc_pulseq::{write_sequence_file, ActuationSample, PlayedRun, TrackingPhase};
use capsule_mpc_sim::plant::{Phase, Plant};
use capsule_mpc_sim::report::write_json_atomic;

/// How to tell a controller built for the config what the fit found,
/// without regenerating: the simulator's flags (one deviation for all, the
/// largest) or, beyond the runtime's factor range, regenerate.
fn tell_line(cal: &capsule_mpc_calibrate::Calibration) -> String {
    use capsule_mpc_runtime::controller::{MODEL_FACTOR_MAX, MODEL_FACTOR_MIN};
    let factors = |k: usize| -> Vec<String> {
        cal.capsules
            .iter()
            .map(|c| format!("{:.4}", c.told_factors[k]))
            .collect()
    };
    let in_range = cal.capsules.iter().all(|c| {
        c.told_factors
            .iter()
            .all(|f| (MODEL_FACTOR_MIN..=MODEL_FACTOR_MAX).contains(f))
    });
    if !in_range {
        return format!(
            "a factor is outside [{MODEL_FACTOR_MIN}, {MODEL_FACTOR_MAX}] of the config's values: regenerate for the fitted capsules (--out)"
        );
    }
    let std = cal
        .capsules
        .iter()
        .flat_map(|c| c.told_std)
        .fold(0.0, f64::max);
    format!(
        "tell the controller without regenerating: --calibrated-gain-scale {} --calibrated-drag-scale {} --calibrated-std {std:.3} (simulate, reach; set_model_factors per capsule: docs/calibrate.md)",
        factors(0).join(","),
        factors(1).join(","),
    )
}

pub fn run(args: &CalibrateArgs) -> Result<()> {
    let config = load_config(args.config.as_deref())?;
    if args.design {
        return design(args, &config);
    }
    let path = args
        .log
        .as_ref()
        .context("--log FILE is required (or --design)")?;
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the log {}", path.display()))?;
    let m = config.capsule_count();
    let log = if text.trim_start().starts_with('{') {
        TrackingLog::from_run_json(&text, m, args.min_measurements)
    } else {
        TrackingLog::from_csv(&text, m, args.min_measurements)
    }
    .with_context(|| format!("log {}", path.display()))?;
    let cal = fit(&log, &config, &FitSettings::default()).map_err(anyhow::Error::msg)?;
    // Everything checked before anything is written.
    let fitted = fitted_config(&config, &cal);
    fitted.validate().context("the fitted config")?;
    let fitted_toml = toml::to_string(&fitted).context("writing the fitted config as TOML")?;
    for c in &cal.capsules {
        crate::out!(
            "{}: gain {:.3} m/s^2 per T/m (+- {:.3}, config {:.3}), drag {:.4} 1/m (+- {:.4}, config {:.4}); {} frames, residual {:.3} mm",
            c.name,
            c.gain,
            c.gain_stderr,
            c.gain_model,
            c.drag,
            c.drag_stderr,
            c.drag_model,
            c.measurements,
            1e3 * c.residual_rms_m
        )?;
    }
    crate::out!(
        "residual RMS {:.3} mm ({} drag law)",
        1e3 * cal.residual_rms_m,
        cal.drag_law
    )?;
    crate::out!("{}", tell_line(&cal))?;
    for w in &cal.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(p) = &args.json {
        write_json_atomic(p, &cal)?;
    }
    if let Some(dir) = &args.plot {
        for f in crate::figures::calibration::plot_calibration(&log, &cal, &config, dir)? {
            crate::out!("wrote {}", f.display())?;
        }
    }
    if let Some(p) = &args.out {
        let header = "# Written by `capsule-mpc calibrate`: the base config with each capsule's fitted\n\
                      # gain_m_per_s2_per_t_per_m and drag_per_m (overrides of the derived values).\n";
        write_file_atomically(p, format!("{header}{fitted_toml}").as_bytes())?;
        crate::out!(
            "wrote {} (regenerate with `capsule-mpc generate --config {}`)",
            p.display(),
            p.display()
        )?;
    }
    Ok(())
}

/// The excitation played on the plant simulator from rest at the origin:
/// the log with the measured positions of every tracking row.
fn play(e: &Excitation, config: &Config, args: &CalibrateArgs) -> Result<TrackingLog> {
    let model = Model::from_config(config);
    let plant_model =
        crate::cli::mismatch(&args.plant_drag_scale, &args.plant_gain_scale).apply(&model)?;
    let n = plant_model.state_count();
    let mut plant = Plant::new(
        plant_model,
        vec![0.0; n],
        DisturbanceConfig::default(),
        config.measurement.position_noise_m,
        args.seed,
    )?;
    let mut log = e.log.clone();
    for r in 0..log.t_s.len() {
        let actuating = e.actuation_rows.contains(&r);
        if !actuating {
            log.positions_m[r] = plant.measure_positions().into_iter().map(Some).collect();
        }
        if r + 1 < log.t_s.len() {
            let phase = if actuating {
                Phase::Actuate
            } else {
                Phase::Track
            };
            plant.advance(log.t_s[r + 1] - log.t_s[r], log.gradient_t_per_m[r], phase)?;
        }
    }
    Ok(log)
}

fn design(args: &CalibrateArgs, config: &Config) -> Result<()> {
    let e = design_excitation(config, args.duration).map_err(anyhow::Error::msg)?;
    crate::out!(
        "excitation: {:.1} s, {} actuation samples ({} per push at full gradient), largest excursion on the model {:.1} mm, ends {:.1} mm from the start",
        args.duration,
        e.actuation_rows.len(),
        e.push_samples,
        1e3 * e.max_excursion_m(),
        1e3 * e.end_offset_m()
    )?;
    if args.csv.is_none() && args.pulseq.is_none() {
        bail!("--design writes its sequence to --csv FILE and/or --pulseq FILE.seq");
    }
    if let Some(p) = &args.csv {
        let log = if args.play {
            play(&e, config, args)?
        } else {
            e.log.clone()
        };
        write_file_atomically(p, log.to_csv().as_bytes())?;
        crate::out!("wrote {}", p.display())?;
    }
    if let Some(p) = &args.pulseq {
        let mut run = PlayedRun {
            sample_time_s: e.sample_time_s,
            duration_s: *e.log.t_s.last().unwrap_or(&0.0),
            metadata: vec![("capsule_mpc".into(), "calibration excitation".into())],
            ..Default::default()
        };
        for (r, &t) in e.log.t_s.iter().enumerate() {
            if e.actuation_rows.contains(&r) {
                run.samples.push(ActuationSample {
                    start_s: t,
                    gradient_t_per_m: e.log.gradient_t_per_m[r],
                });
            } else if r + 1 < e.log.t_s.len() {
                run.tracking.push(TrackingPhase {
                    start_s: t,
                    duration_s: config.scanner.tracking_time_s,
                });
            }
        }
        write_sequence_file(p, &run, &crate::pulseq_export::sequence_options(config))
            .with_context(|| format!("writing the Pulseq sequence {}", p.display()))?;
        crate::out!("wrote {}", p.display())?;
    }
    Ok(())
}
