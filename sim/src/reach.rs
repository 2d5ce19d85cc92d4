//! The reach map: the closed loop run to every target of a grid, the map a
//! user needs before planning an experiment ("can it take them there, and
//! how fast?").
//!
//! Targets are every combination of capsule positions `start + k step`
//! with |k step| <= range (the start itself excluded), at rest. Each run
//! reports whether the target was refused (and why), its settle time, the
//! generator's minimum rest-to-rest time for that move and their ratio.
//! Runs are independent, so they go across cores (rayon).

use crate::closed_loop::{run, RunOptions, Sampling};
use crate::plant::DisturbanceLevel;
use anyhow::{bail, Result};
use capsule_mpc_generator::config::{Config, DisturbanceConfig, DisturbanceKind};
use capsule_mpc_generator::model::Model;
use rayon::prelude::*;
use serde::Serialize;

/// Most targets one reach map runs (keeps a typo in the step from asking
/// for millions of runs).
pub const MAX_REACH_TARGETS: usize = 20_000;

/// What a reach map runs.
#[derive(Debug, Clone)]
pub struct ReachOptions {
    /// Half-width of the target grid around the start, per capsule, m.
    pub range_m: f64,
    /// Grid spacing, m.
    pub step_m: f64,
    pub sampling: Sampling,
    pub disturbance: DisturbanceLevel,
    /// How the disturbance varies in time (its size is `disturbance`).
    pub disturbance_kind: DisturbanceKind,
    pub seed: u64,
    /// Start positions (at rest), m; the origin when empty.
    pub start_m: Vec<f64>,
    /// Simulated time per run, s; None: long enough for the grid's moves
    /// (see [`default_duration_s`]).
    pub duration_s: Option<f64>,
    /// Extra delay after each tracking phase, s (odd scanner timing); None:
    /// the config's `scanner.extra_delay_s`.
    pub extra_delay_s: Option<f64>,
    /// How the simulated capsules differ from the model (none by default).
    pub mismatch: crate::mismatch::PlantMismatch,
    /// Factors the controller is told at the start of every run
    /// (`RunOptions::known_factors`); None: it starts from the model.
    pub known_factors: Option<crate::mismatch::PlantMismatch>,
    /// Their standard deviation (`RunOptions::known_factor_std`).
    pub known_factor_std: f64,
    /// Minimum-time shots (`RunOptions::shooting`; None: the controller's
    /// default).
    pub shooting: Option<bool>,
}

/// Simulated time per run when none is given: 3 s plus 0.5 s per cm of the
/// grid's half-width (ideal sampling), 1.5 times that on the scanner cycle,
/// at most 30 s: the slowest moves of the default grid arrive within its
/// first half, and an arrival counts once the capsules have stayed in the
/// band for 1 s (`settle_held_s`).
pub fn default_duration_s(range_m: f64, sampling: Sampling) -> f64 {
    let ideal = 3.0 + 50.0 * range_m;
    let s = match sampling {
        Sampling::Ideal => ideal,
        Sampling::Constant | Sampling::Variable => 1.5 * ideal,
    };
    s.min(30.0)
}

/// The outcome of one target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReachPoint {
    /// Target positions, m (speeds 0).
    pub target_m: Vec<f64>,
    /// Why the target was refused (None: it was run).
    pub refused: Option<String>,
    /// Strict settle: in the settle band from then to the end of the run
    /// (`Metrics::settle_time_s`).
    pub settle_time_s: Option<f64>,
    pub min_time_bound_s: Option<f64>,
    /// settle_time_s / min_time_bound_s.
    pub settle_over_bound: Option<f64>,
    /// The played schedule's minimum time and the settle's ratio to it
    /// (`Metrics::schedule_min_time_s`; constant sampling: the coasted plan).
    pub schedule_min_time_s: Option<f64>,
    pub settle_over_schedule_bound: Option<f64>,
    /// The held settle (in the band for 1 s, `Metrics::settle_held_s`),
    /// labelled as such.
    pub held_settle_time_s: Option<f64>,
    pub final_position_error_m: Option<f64>,
    /// How far a capsule went outside the config's workspace on the way,
    /// m (0: it stayed inside; `Metrics::workspace_excursion_m`).
    pub workspace_excursion_m: Option<f64>,
}

/// Figures over a reach map (worst cases, not means of the easy ones).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReachSummary {
    pub targets: usize,
    pub refused: usize,
    pub never_settled: usize,
    pub median_settle_over_bound: Option<f64>,
    pub worst_settle_over_bound: Option<f64>,
    /// The same against the played schedule's minimum time.
    pub median_settle_over_schedule_bound: Option<f64>,
    pub worst_settle_over_schedule_bound: Option<f64>,
    /// The target of the worst ratio, m.
    pub worst_ratio_target_m: Option<Vec<f64>>,
    pub median_settle_time_s: Option<f64>,
    pub worst_settle_time_s: Option<f64>,
    /// Targets on whose way a capsule left the workspace, and the farthest
    /// it went outside, m, with that target (the plans keep the capsules'
    /// errors to the target within the state bound, not their positions
    /// within the workspace: docs/known-limits.md).
    pub left_workspace: usize,
    pub worst_workspace_excursion_m: Option<f64>,
    pub worst_excursion_target_m: Option<Vec<f64>>,
}

/// The grid's targets (positions only), row-major with the first capsule
/// slowest; the start itself is left out.
pub fn grid_targets(start_m: &[f64], range_m: f64, step_m: f64) -> Result<Vec<Vec<f64>>> {
    if !(step_m.is_finite() && step_m > 0.0 && range_m.is_finite() && range_m >= 0.0) {
        bail!("reach grid: range {range_m} m and step {step_m} m must be finite, step > 0");
    }
    // Counted in floating point: a tiny step must get the error, not an
    // overflowed count.
    let half_f = (range_m / step_m + 1e-9).floor();
    let count_f = (2.0 * half_f + 1.0).powi(start_m.len() as i32);
    if count_f > MAX_REACH_TARGETS as f64 {
        bail!(
            "reach grid: {count_f:.3e} targets (range {range_m} m, step {step_m} m, {} capsules) exceed {MAX_REACH_TARGETS}; use a larger step",
            start_m.len()
        );
    }
    let half = half_f as i64;
    let per_axis = (2 * half + 1) as usize;
    let count = per_axis.pow(start_m.len() as u32);
    let mut targets = Vec::with_capacity(count);
    for flat in 0..count {
        let mut rest = flat;
        let mut t = vec![0.0; start_m.len()];
        let mut offsets_zero = true;
        for i in (0..start_m.len()).rev() {
            let k = (rest % per_axis) as i64 - half;
            rest /= per_axis;
            offsets_zero &= k == 0;
            // Rounded to the nanometre so that printed targets read cleanly.
            t[i] = ((start_m[i] + k as f64 * step_m) * 1e9).round() / 1e9;
        }
        if !offsets_zero {
            targets.push(t);
        }
    }
    Ok(targets)
}

/// Runs the closed loop to every grid target; `tick` is called after each
/// run (from any thread).
pub fn reach_map(
    config: &Config,
    opts: &ReachOptions,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<ReachPoint>> {
    // Without a compiled controller every target would be "refused": say so once.
    crate::closed_loop::compiled_controller_for(config)?;
    let model = Model::from_config(config);
    let m = model.capsule_count();
    let start = if opts.start_m.is_empty() {
        vec![0.0; m]
    } else {
        opts.start_m.clone()
    };
    if start.len() != m {
        bail!(
            "start has {} positions; the config has {m} capsules",
            start.len()
        );
    }
    // A start outside the workspace would refuse every target: say so once.
    let ws = &config.workspace;
    for (i, &p) in start.iter().enumerate() {
        if let Some(excess_m) = ws.excess_m(p) {
            bail!(
                "start: capsule {} at {p} m is outside the workspace [{}, {}] m by {:.4} m (config section [workspace])",
                i + 1,
                ws.position_min_m,
                ws.position_max_m,
                excess_m.abs()
            );
        }
    }
    let targets = grid_targets(&start, opts.range_m, opts.step_m)?;
    let duration_s = opts
        .duration_s
        .unwrap_or_else(|| default_duration_s(opts.range_m, opts.sampling));
    // A bad duration would refuse every target: say so once.
    crate::closed_loop::check_duration(duration_s)?;
    if let Some(d) = opts.extra_delay_s {
        if opts.sampling == Sampling::Ideal {
            bail!("extra delay {d} applies to the scanner cycle (constant or variable sampling); ideal sampling has no tracking phase to delay");
        }
        crate::closed_loop::check_extra_delay(config, d)?;
    }
    if opts.known_factors.is_some() {
        crate::closed_loop::check_known_factor_std(opts.known_factor_std)?;
    }
    let points = targets
        .par_iter()
        .map(|t| {
            let state: Vec<f64> = t.iter().flat_map(|&p| [p, 0.0]).collect();
            let mut run_opts = RunOptions::new(config, state, opts.sampling);
            run_opts.start_m = start.clone();
            run_opts.seed = opts.seed;
            run_opts.duration_s = duration_s;
            run_opts.mismatch = opts.mismatch.clone();
            run_opts.known_factors = opts.known_factors.clone();
            run_opts.known_factor_std = opts.known_factor_std;
            run_opts.shooting = opts.shooting;
            if let Some(d) = opts.extra_delay_s {
                run_opts.extra_delay_s = d;
            }
            run_opts.disturbance = match opts.disturbance {
                DisturbanceLevel::None => DisturbanceConfig::default(),
                level => level.config_of_kind(&model, opts.seed, opts.disturbance_kind),
            };
            let point = match run(config, &run_opts) {
                Ok(report) => {
                    let m = report.metrics;
                    ReachPoint {
                        target_m: t.clone(),
                        refused: None,
                        settle_time_s: m.settle_time_s,
                        min_time_bound_s: m.min_time_bound_s,
                        settle_over_bound: m.settle_over_bound,
                        schedule_min_time_s: m.schedule_min_time_s,
                        settle_over_schedule_bound: m.settle_over_schedule_bound,
                        held_settle_time_s: m.settle_held_s,
                        final_position_error_m: Some(m.final_position_error_m),
                        workspace_excursion_m: Some(m.workspace_excursion_m),
                    }
                }
                Err(e) => ReachPoint {
                    target_m: t.clone(),
                    refused: Some(format!("{e:#}")),
                    settle_time_s: None,
                    min_time_bound_s: None,
                    settle_over_bound: None,
                    schedule_min_time_s: None,
                    settle_over_schedule_bound: None,
                    held_settle_time_s: None,
                    final_position_error_m: None,
                    workspace_excursion_m: None,
                },
            };
            tick();
            point
        })
        .collect();
    Ok(points)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

impl ReachSummary {
    pub fn of(points: &[ReachPoint]) -> ReachSummary {
        let ratios: Vec<(f64, &ReachPoint)> = points
            .iter()
            .filter_map(|p| p.settle_over_bound.map(|r| (r, p)))
            .collect();
        let worst = ratios.iter().max_by(|a, b| a.0.total_cmp(&b.0));
        let settles: Vec<f64> = points.iter().filter_map(|p| p.settle_time_s).collect();
        let farthest = points
            .iter()
            .filter_map(|p| p.workspace_excursion_m.map(|e| (e, p)))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        let schedule_ratios: Vec<f64> = points
            .iter()
            .filter_map(|p| p.settle_over_schedule_bound)
            .collect();
        ReachSummary {
            targets: points.len(),
            refused: points.iter().filter(|p| p.refused.is_some()).count(),
            never_settled: points
                .iter()
                .filter(|p| p.refused.is_none() && p.settle_time_s.is_none())
                .count(),
            median_settle_over_bound: median(ratios.iter().map(|r| r.0).collect()),
            worst_settle_over_bound: worst.map(|w| w.0),
            median_settle_over_schedule_bound: median(schedule_ratios.clone()),
            worst_settle_over_schedule_bound: schedule_ratios.into_iter().reduce(f64::max),
            worst_ratio_target_m: worst.map(|w| w.1.target_m.clone()),
            median_settle_time_s: median(settles.clone()),
            worst_settle_time_s: settles.into_iter().reduce(f64::max),
            left_workspace: points
                .iter()
                .filter(|p| p.workspace_excursion_m.is_some_and(|e| e > 0.0))
                .count(),
            worst_workspace_excursion_m: farthest.map(|f| f.0),
            worst_excursion_target_m: farthest.filter(|f| f.0 > 0.0).map(|f| f.1.target_m.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_leaves_out_the_start_and_orders_rows_by_the_first_capsule() {
        let t = grid_targets(&[0.0, 0.01], 0.01, 0.01).unwrap();
        assert_eq!(t.len(), 8);
        assert_eq!(t[0], vec![-0.01, 0.0]);
        assert_eq!(t[1], vec![-0.01, 0.01]);
        assert!(!t.contains(&vec![0.0, 0.01]));
    }

    #[test]
    fn a_huge_grid_is_refused_with_its_size() {
        let err = grid_targets(&[0.0, 0.0], 0.06, 1e-5)
            .unwrap_err()
            .to_string();
        assert!(err.contains("exceed"), "{err}");
        assert!(err.contains("1.440e8 targets"), "{err}");
        assert!(grid_targets(&[0.0], 0.01, 0.0).is_err());
        // A step so small that the count overflows any integer: still the
        // error with its (floating-point) size.
        let err = grid_targets(&[0.0, 0.0], 0.04, 1e-120)
            .unwrap_err()
            .to_string();
        assert!(err.contains("6.400e237 targets"), "{err}");
    }

    #[test]
    fn medians_and_worst_cases() {
        let p = |r: Option<f64>, s: Option<f64>, refused: bool| ReachPoint {
            target_m: vec![s.unwrap_or(0.0)],
            refused: refused.then(|| "x".to_string()),
            settle_time_s: s,
            min_time_bound_s: None,
            settle_over_bound: r,
            schedule_min_time_s: None,
            settle_over_schedule_bound: r,
            held_settle_time_s: s,
            final_position_error_m: None,
            workspace_excursion_m: (!refused).then_some(0.0),
        };
        // The slower run went 2 mm outside the workspace on its way.
        let out = ReachPoint {
            workspace_excursion_m: Some(0.002),
            ..p(Some(1.5), Some(0.9), false)
        };
        let s = ReachSummary::of(&[
            p(Some(1.0), Some(0.5), false),
            out,
            p(None, None, false),
            p(None, None, true),
        ]);
        assert_eq!((s.targets, s.refused, s.never_settled), (4, 1, 1));
        assert_eq!(s.median_settle_over_bound, Some(1.25));
        assert_eq!(s.worst_settle_over_bound, Some(1.5));
        assert_eq!(s.worst_settle_time_s, Some(0.9));
        assert_eq!(s.left_workspace, 1);
        assert_eq!(s.worst_workspace_excursion_m, Some(0.002));
        assert_eq!(s.worst_excursion_target_m, Some(vec![0.9]));
        // A grid that stays inside names no target.
        let inside = ReachSummary::of(&[p(Some(1.0), Some(0.5), false)]);
        assert_eq!(inside.left_workspace, 0);
        assert_eq!(inside.worst_workspace_excursion_m, Some(0.0));
        assert_eq!(inside.worst_excursion_target_m, None);
    }
}
