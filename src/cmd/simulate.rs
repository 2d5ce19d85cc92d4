//! `capsule-mpc simulate`: one closed-loop run from the command line, its
//! summary line, and optionally its JSON report and plots.

use crate::cli::{load_config, SimulateArgs};
use crate::figures::plot_run;
use anyhow::Result;
use capsule_mpc_generator::config::DisturbanceKind;
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::Mode;
use capsule_mpc_sim::closed_loop::{Preset, Sampling};
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::request::SimulateRequest;

/// `capsule-mpc simulate`.
pub fn run(args: &SimulateArgs) -> Result<()> {
    let (sampling, disturbance, preset) = (
        Sampling::from(args.sampling),
        DisturbanceLevel::from(args.disturbance),
        Preset::from(args.preset),
    );
    let config = load_config(args.config.as_deref())?;
    let model = Model::from_config(&config);
    let mut request = SimulateRequest::new(
        args.target_state(model.state_count())?,
        args.scenario_name(),
    );
    request.start_m = args.start_positions(model.capsule_count())?;
    request.retarget = args
        .retarget
        .clone()
        .zip(args.retarget_at)
        .map(|(target, at_s)| capsule_mpc_sim::closed_loop::Retarget { at_s, target });
    request.sampling = sampling;
    request.disturbance = disturbance;
    request.disturbance_kind = DisturbanceKind::from(args.disturbance_model);
    request.seed = args.seed;
    request.duration_s = args.duration;
    request.preset = preset;
    request.switching = args.switching.into();
    request.compensate_delay = !args.no_delay_compensation;
    request.lose_every = args.lose_every;
    request.hold = !args.no_hold;
    request.shooting = crate::cli::shooting_choice(args.shooting, args.no_shooting);
    request.mismatch = args.plant.mismatch();
    (request.known_factors, request.known_factor_std) = args.plant.told()?;
    request.refine = args.refine.map(Into::into);
    request.extra_delay_s = crate::cli::extra_delay_for(args.sampling, args.extra_delay)?;
    let opts = request.options(&config)?;
    if args.pulseq.is_some() {
        crate::pulseq_export::check_timing_on_raster(&config, opts.extra_delay_s)?;
    }
    let report = request.run(&config)?;
    let m = &report.metrics;
    crate::out!(
        "scenario {}{} ({} sampling, {:?} preset, disturbance {}, seed {}): settle {}{}{} | in band {} | final error {:.3} mm | max |u| {:.1} mT/m | duty {:.2} ({:.2} until settled) | bound violations {} | max step {:.1} us",
        args.scenario_name(),
        report.retarget.as_ref().map_or(String::new(), |r| format!(
            ", target changed at {:.3} s to {:?} m",
            r.at_s,
            report.target.iter().step_by(2).collect::<Vec<_>>()
        )),
        sampling.name(),
        preset,
        report.disturbance.as_deref().unwrap_or("none"),
        args.seed,
        m.settle_time_s.map_or("never".to_string(), |t| format!("{t:.3} s")),
        m.min_time_bound_s.map_or(String::new(), |b| format!(
            " (min-time bound {b:.3} s{}{})",
            m.settle_over_bound.map_or(String::new(), |r| format!(", ratio {r:.2}")),
            match (sampling, m.schedule_min_time_s) {
                (Sampling::Constant, Some(c)) => format!(
                    "; coasted schedule {c:.3} s{}",
                    m.settle_over_schedule_bound
                        .map_or(String::new(), |r| format!(", ratio {r:.2}"))
                ),
                _ => String::new(),
            }
        )),
        match m.settle_held_s {
            Some(h) if Some(h) != m.settle_time_s => format!(" (held 1 s from {h:.3} s)"),
            _ => String::new(),
        },
        match (m.first_in_band_s, m.time_in_band_after_entry) {
            (Some(t), Some(f)) => format!("{:.1} % from {t:.3} s", 100.0 * f),
            _ => "never".to_string(),
        },
        m.final_position_error_m * 1e3,
        m.max_abs_u * 1e3,
        m.duty_cycle,
        m.duty_cycle_until_settled,
        m.state_bound_violations,
        m.max_step_compute_ns as f64 / 1e3
    )?;
    if let Some(t) = report.tier_cycles {
        crate::out!(
            "refine {}: plans from the explicit tier in {} cycles, from the refinement in {}",
            match opts.refine {
                capsule_mpc_generator::config::RefineMode::None => "none",
                capsule_mpc_generator::config::RefineMode::Once => "once",
                capsule_mpc_generator::config::RefineMode::PerSample => "per-sample",
            },
            t.explicit,
            t.refined
        )?;
    }
    if let Some(modes) = &report.modes {
        let last_hold = modes.iter().rev().find(|m| m.mode == Mode::Hold.name());
        crate::out!(
            "mode entries over {} changes: {}{}",
            modes.len().saturating_sub(1),
            Mode::ALL
                .iter()
                .map(|m| format!(
                    "{} {}",
                    m.name(),
                    modes.iter().filter(|c| c.mode == m.name()).count()
                ))
                .collect::<Vec<_>>()
                .join(", "),
            last_hold.map_or(String::new(), |h| format!(
                "; last entered the hold at {:.3} s",
                h.t_s
            ))
        )?;
    }
    if m.workspace_excursion_m > 0.0 {
        // The plans bound the errors to the target, not the positions.
        crate::out!(
            "on the way a capsule left the workspace by {:.1} mm (config section [workspace]; docs/known-limits.md)",
            m.workspace_excursion_m * 1e3
        )?;
    }
    if let Some(path) = &args.json {
        report.write_json(path)?;
    }
    if let Some(path) = &args.pulseq {
        let seq = crate::pulseq_export::write_pulseq(path, &report, &config)?;
        crate::out!(
            "wrote {} ({} blocks: {} actuation, {} tracking, {} pause; {:.3} s)",
            path.display(),
            seq.blocks,
            seq.actuation_blocks,
            seq.tracking_blocks,
            seq.delay_blocks,
            seq.duration_s
        )?;
    }
    if let Some(dir) = &args.plot {
        for path in plot_run(&report, dir)? {
            crate::out!("wrote {}", path.display())?;
        }
    }
    Ok(())
}
