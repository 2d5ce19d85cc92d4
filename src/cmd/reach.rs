//! `capsule-mpc reach`: the closed loop to every target of a grid, as a
//! table, a summary of the worst cases, JSON and heatmaps.

use crate::cli::{load_config, start_positions, ReachArgs};
use crate::figures::heatmap::{plot_heatmap, HeatmapValue};
use anyhow::{bail, Result};
use capsule_mpc_sim::closed_loop::Sampling;
use capsule_mpc_sim::plant::{disturbance_kind_name, DisturbanceLevel};
use capsule_mpc_sim::reach::{reach_map, ReachOptions, ReachPoint, ReachSummary};
use capsule_mpc_sim::report::write_json_atomic;
use indicatif::{ProgressBar, ProgressStyle};
use std::time::Instant;

/// `capsule-mpc reach`.
pub fn run(args: &ReachArgs) -> Result<()> {
    let config = load_config(args.config.as_deref())?;
    if !(args.range_cm.is_finite() && args.range_cm >= 0.0) {
        bail!("--range-cm {} must be a finite number >= 0", args.range_cm);
    }
    if !(args.step_cm.is_finite() && args.step_cm > 0.0) {
        bail!("--step-cm {} must be a finite number > 0", args.step_cm);
    }
    let (sampling, disturbance) = (
        Sampling::from(args.sampling),
        DisturbanceLevel::from(args.disturbance),
    );
    let (known_factors, known_factor_std) = args.plant.told()?;
    let opts = ReachOptions {
        range_m: args.range_cm / 100.0,
        step_m: args.step_cm / 100.0,
        sampling,
        disturbance,
        disturbance_kind: args.disturbance_model.into(),
        seed: args.seed,
        start_m: start_positions(args.start.as_deref(), config.capsule_count())?,
        duration_s: args.duration,
        extra_delay_s: crate::cli::extra_delay_for(args.sampling, args.extra_delay)?,
        mismatch: args.plant.mismatch(),
        known_factors,
        known_factor_std,
        shooting: crate::cli::shooting_choice(args.shooting, args.no_shooting),
    };
    opts.mismatch.factors(config.capsule_count())?;
    if let Some(known) = &opts.known_factors {
        known.factors_named(config.capsule_count(), "calibrated")?;
    }
    let targets = capsule_mpc_sim::reach::grid_targets(
        &if opts.start_m.is_empty() {
            vec![0.0; config.capsule_count()]
        } else {
            opts.start_m.clone()
        },
        opts.range_m,
        opts.step_m,
    )?
    .len();
    let bar = ProgressBar::new(targets as u64);
    bar.set_style(
        ProgressStyle::with_template("reach {bar:40} {pos}/{len} targets ({elapsed})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let started = Instant::now();
    let points = reach_map(&config, &opts, &|| bar.inc(1))?;
    bar.finish_and_clear();
    let summary = ReachSummary::of(&points);
    print_table(&points)?;
    let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    // The zero-gradient gap after each actuation phase (tracking + extra
    // delay); ideal sampling has none.
    let gap_s = match sampling {
        Sampling::Ideal => 0.0,
        Sampling::Constant | Sampling::Variable => {
            config.scanner.tracking_time_s
                + opts.extra_delay_s.unwrap_or(config.scanner.extra_delay_s)
        }
    };
    let gap = if gap_s > 0.0 {
        format!(", {:.0} ms gaps", gap_s * 1e3)
    } else {
        String::new()
    };
    crate::out!(
        "{} targets ({} sampling{gap}, disturbance {:?} {}, seed {}) in {:.1} s: {} refused, {} never settled; settle / min-time bound median {} worst {}{}; settle time median {} s worst {} s",
        summary.targets,
        sampling.name(),
        disturbance,
        disturbance_kind_name(opts.disturbance_kind),
        args.seed,
        started.elapsed().as_secs_f64(),
        summary.refused,
        summary.never_settled,
        fmt(summary.median_settle_over_bound),
        fmt(summary.worst_settle_over_bound),
        summary
            .worst_ratio_target_m
            .as_ref()
            .map_or(String::new(), |t| format!(" (at {:?} cm)", t.iter().map(|v| v * 100.0).collect::<Vec<_>>())),
        fmt(summary.median_settle_time_s),
        fmt(summary.worst_settle_time_s),
    )?;
    if let (Some(e), Some(t)) = (
        summary.worst_workspace_excursion_m,
        &summary.worst_excursion_target_m,
    ) {
        crate::out!(
            "on the way a capsule left the workspace for {} of the targets, by up to {:.1} mm (at {:?} cm)",
            summary.left_workspace,
            e * 1e3,
            t.iter().map(|v| v * 100.0).collect::<Vec<_>>()
        )?;
    }
    if sampling == Sampling::Constant {
        crate::out!(
            "settle / coasted-schedule minimum time (constant sampling's own bound, {} targets on its plan grid): median {} worst {}",
            points.iter().filter(|p| p.schedule_min_time_s.is_some()).count(),
            fmt(summary.median_settle_over_schedule_bound),
            fmt(summary.worst_settle_over_schedule_bound),
        )?;
    }
    if let Some(path) = &args.json {
        let mut json = serde_json::json!({
            "sampling": sampling.name(),
            "disturbance": format!("{disturbance:?}").to_lowercase(),
            "disturbance_model": disturbance_kind_name(opts.disturbance_kind),
            "seed": args.seed,
            "gap_s": gap_s,
            "range_m": opts.range_m,
            "step_m": opts.step_m,
            "summary": summary,
            "points": points,
        });
        if !opts.mismatch.is_nominal() {
            let (drag, gain) = opts.mismatch.factors(config.capsule_count())?;
            json["plant"] = serde_json::json!({"drag_scale": drag, "gain_scale": gain});
        }
        write_json_atomic(path, &json)?;
    }
    if let Some(dir) = &args.plot {
        if config.capsule_count() != 2 {
            bail!(
                "--plot draws two-capsule grids; this config has {} capsules",
                config.capsule_count()
            );
        }
        let what = format!(
            "{} sampling, disturbance {:?}",
            sampling.name(),
            disturbance
        )
        .to_lowercase();
        for (value, stem, title) in [
            (
                HeatmapValue::SettleTime,
                "reach_settle",
                format!("Settle time to each target from rest at the start ({what})"),
            ),
            (
                HeatmapValue::SettleOverBound,
                "reach_ratio",
                format!("Settle time / minimum-time bound ({what})"),
            ),
        ] {
            for path in plot_heatmap(&points, value, &title, dir, stem)? {
                crate::out!("wrote {}", path.display())?;
            }
        }
    }
    Ok(())
}

/// Settle times as a matrix for two capsules (rows: capsule 1), else a list.
fn print_table(points: &[ReachPoint]) -> std::io::Result<()> {
    let cell = |p: &ReachPoint| match (&p.refused, p.settle_time_s) {
        (Some(_), _) => " refused".to_string(),
        (None, Some(s)) => format!("{s:8.2}"),
        (None, None) => "   never".to_string(),
    };
    if points.first().is_some_and(|p| p.target_m.len() == 2) {
        crate::out!(
            "settle time (s); rows: capsule 1 target (cm), columns: capsule 2 target (cm)"
        )?;
        let distinct = |i: usize| {
            let mut v: Vec<f64> = points.iter().map(|p| p.target_m[i]).collect();
            v.sort_by(f64::total_cmp);
            v.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            v
        };
        let (rows, cols) = (distinct(0), distinct(1));
        let mut header = "         ".to_string();
        for c in &cols {
            header += &format!("{:8.1}", c * 100.0);
        }
        crate::out!("{header}")?;
        for r in &rows {
            let mut line = format!("{:8.1} ", r * 100.0);
            for c in &cols {
                let found = points
                    .iter()
                    .find(|p| (p.target_m[0] - r).abs() < 1e-9 && (p.target_m[1] - c).abs() < 1e-9);
                line += &found.map_or("       -".to_string(), cell);
            }
            crate::out!("{line}")?;
        }
    } else {
        for p in points {
            crate::out!(
                "{:?} cm: {}",
                p.target_m.iter().map(|v| v * 100.0).collect::<Vec<_>>(),
                cell(p)
            )?;
        }
    }
    Ok(())
}
