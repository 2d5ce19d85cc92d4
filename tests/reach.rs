//! Issue 13: every target in the workspace is accepted and reached, close to
//! the minimum rest-to-rest time the generator computed, from rest anywhere
//! and from a moving state when the target changes mid-run.

use capsule_mpc_generator::config::{Config, DisturbanceConfig, DisturbanceKind, RefineMode};
use capsule_mpc_generator::model::Model;
use capsule_mpc_sim::closed_loop::{run, Retarget, RunOptions, Sampling};
use capsule_mpc_sim::metrics::Metrics;
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::reach::{reach_map, ReachOptions, ReachPoint, ReachSummary};

fn cm(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x * 100.0).collect()
}

fn reach(range_m: f64, step_m: f64, start_m: Vec<f64>) -> (Vec<ReachPoint>, ReachSummary) {
    reach_with(&Config::embedded_default(), range_m, step_m, start_m)
}

fn reach_with(
    config: &Config,
    range_m: f64,
    step_m: f64,
    start_m: Vec<f64>,
) -> (Vec<ReachPoint>, ReachSummary) {
    let points = reach_map(config, &ideal_options(range_m, step_m, start_m), &|| {}).unwrap();
    let summary = ReachSummary::of(&points);
    (points, summary)
}

/// A grid from `start_m` under ideal sampling with no disturbance.
fn ideal_options(range_m: f64, step_m: f64, start_m: Vec<f64>) -> ReachOptions {
    ReachOptions {
        range_m,
        step_m,
        sampling: Sampling::Ideal,
        disturbance: DisturbanceLevel::None,
        disturbance_kind: DisturbanceKind::Random,
        seed: 1,
        start_m,
        duration_s: None,
        extra_delay_s: None,
        mismatch: Default::default(),
        known_factors: None,
        known_factor_std: capsule_mpc_sim::closed_loop::KNOWN_FACTOR_STD,
        shooting: None,
    }
}

fn failures(points: &[ReachPoint]) -> Vec<String> {
    points
        .iter()
        .filter(|p| p.refused.is_some() || p.settle_time_s.is_none())
        .map(|p| format!("{:?} cm: {:?}", cm(&p.target_m), p.refused))
        .collect()
}

/// The 1 cm grid over +-4 cm: all 80 targets accepted and settled; prints
/// and returns settle / bound at the median and at worst.
fn settled_grid_ratios(label: &str, points: &[ReachPoint], s: &ReachSummary) -> (f64, f64) {
    assert_eq!(s.targets, 80);
    assert!(failures(points).is_empty(), "{:?}", failures(points));
    let (median, worst) = (
        s.median_settle_over_bound.unwrap(),
        s.worst_settle_over_bound.unwrap(),
    );
    println!(
        "{label}, settle / bound: median {median:.3}, worst {worst:.3} at {:?} cm; settle median {:.3} s, worst {:.3} s",
        cm(s.worst_ratio_target_m.as_ref().unwrap()),
        s.median_settle_time_s.unwrap(),
        s.worst_settle_time_s.unwrap()
    );
    (median, worst)
}

/// The grid: 80 targets of a 1 cm grid over +-4 cm from rest at the
/// origin, ideal sampling, no disturbance. Every target is accepted and
/// settles; settle / bound <= 1.25 at the median and <= 1.6 at worst.
#[test]
fn every_target_of_the_4_cm_grid_settles_near_its_minimum_time() {
    let (points, s) = reach(0.04, 0.01, Vec::new());
    let (median, worst) = settled_grid_ratios("refined", &points, &s);
    assert!(median <= 1.25, "median ratio {median}");
    // Issue 13's <= 1.6, met: measured 1.29 at (3, -3) cm. It was 1.65 at
    // (0, +-1) cm (bound 0.16 s) while the shortest plans were finished
    // with two samples instead of one (the closed loop arrived at speed and
    // overshot to 20 mm/s in the second), and 1.88 at (-2, -3) cm before
    // the centred hold.
    assert!(worst <= 1.6, "worst ratio {worst}: {s:?}");
    // Every bound is a real time: positive and finite.
    for p in &points {
        let b = p.min_time_bound_s.unwrap();
        assert!(b.is_finite() && b > 0.0, "{:?}: bound {b}", cm(&p.target_m));
    }
}

/// The explicit law alone (`refine = none`: stored plans followed sample by
/// sample through their linearizations, no online optimization) on the same
/// grid: every target settles within issue 26's floors for the law (1.15 x
/// the best known minimum time at the median, 1.4 x at worst, +15 %).
#[test]
fn the_explicit_law_alone_reaches_every_target_of_the_4_cm_grid() {
    let mut config = Config::embedded_default();
    config.controller.refine = RefineMode::None;
    let (points, s) = reach_with(&config, 0.04, 0.01, Vec::new());
    let (median, worst) = settled_grid_ratios("law alone", &points, &s);
    // Measured 1.06 / 1.19 (1.15 while the law alone entered the hold
    // only below 5 mm/s).
    assert!(median <= 1.15 * 1.15, "median ratio {median}");
    assert!(worst <= 1.4 * 1.15, "worst ratio {worst}: {s:?}");
}

/// Issue 26's scanner floor for constant sampling: the 1 cm grid over
/// +-4 cm (80 targets) x seeds 1-8 with the paper disturbance, strict
/// settle within 1.3 x the coasted schedule's minimum time at the median
/// and 1.8 x at worst, every run.
#[test]
fn the_constant_scanner_grid_settles_near_its_schedule_bound() {
    let ratios = constant_scanner_ratios(&Config::embedded_default());
    let median = ratios[ratios.len() / 2].0;
    let worst = ratios.last().unwrap();
    println!("constant, settle / coasted bound: median {median:.3}, worst {worst:?}");
    // Measured 1.00 / 1.66; the worst was 2.31 ((0, -1) cm, seed 7) while
    // the hold was entered only below 4 mm/s.
    assert!(median <= 1.3, "median ratio {median}");
    assert!(worst.0 <= 1.8, "worst ratio {worst:?}");
}

/// The explicit law alone on the same grid: within 1.15 x the refined
/// floors (1.3 / 1.8) but for at most two runs, none far beyond. Measured
/// 1.07 / 2.09, one run above 2.07 ((0, -1) cm, seed 3, 0.50 s); 34 runs
/// above 2x (worst 5.97) while the hold took the law's arrivals only below
/// 5 mm/s, as the refined loop's.
#[test]
fn the_explicit_law_alone_settles_the_constant_scanner_grid_near_its_schedule_bound() {
    let mut config = Config::embedded_default();
    config.controller.refine = RefineMode::None;
    let ratios = constant_scanner_ratios(&config);
    let median = ratios[ratios.len() / 2].0;
    let worst = ratios.last().unwrap();
    let beyond: Vec<_> = ratios.iter().filter(|r| r.0 > 1.8 * 1.15).collect();
    println!("law alone, constant: median {median:.3}, worst {worst:?}, beyond {beyond:?}");
    assert!(median <= 1.3 * 1.15, "median ratio {median}");
    assert!(beyond.len() <= 2, "runs above 2.07: {beyond:?}");
    assert!(worst.0 <= 2.5, "worst ratio {worst:?}");
}

/// Settle over the coasted schedule's bound on the 1 cm grid, constant
/// sampling, seeds 1-8, sorted: (ratio, seed, target in cm). Every run
/// settles.
fn constant_scanner_ratios(config: &Config) -> Vec<(f64, u64, Vec<f64>)> {
    let mut ratios = Vec::new();
    for seed in 1..=8 {
        let points = scanner_points(config, Sampling::Constant, seed);
        assert!(
            failures(&points).is_empty(),
            "seed {seed}: {:?}",
            failures(&points)
        );
        for p in &points {
            let r = p
                .settle_over_schedule_bound
                .expect("coasted bound on the 1 cm grid");
            ratios.push((r, seed, cm(&p.target_m)));
        }
    }
    ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
    ratios
}

/// The 1 cm grid over +-4 cm under the scanner cycle `sampling`, paper
/// disturbance, `seed`.
fn scanner_points(config: &Config, sampling: Sampling, seed: u64) -> Vec<ReachPoint> {
    let mut opts = ideal_options(0.04, 0.01, Vec::new());
    opts.sampling = sampling;
    opts.disturbance = DisturbanceLevel::Paper;
    opts.seed = seed;
    reach_map(config, &opts, &|| {}).unwrap()
}

/// The explicit law alone under variable sampling, the same grid and seeds
/// 1-8: every run settles, and the median settle is within issue 26's
/// floor for the law alone, 1.5 x the ideal minimum time + 15 %. Measured:
/// 640 of 640, median 1.55 (one sample per phase on the coasted plans
/// while the learned products agree); 2.05 with the back-to-back plans in
/// the rule's phases, and 594 settled while coasts cut into their final
/// manoeuvres.
#[test]
fn the_explicit_law_alone_settles_every_variable_scanner_run() {
    let mut config = Config::embedded_default();
    config.controller.refine = RefineMode::None;
    let mut unsettled = Vec::new();
    let mut ratios = Vec::new();
    for seed in 1..=8 {
        for p in scanner_points(&config, Sampling::Variable, seed) {
            match p.settle_over_bound {
                Some(r) => ratios.push(r),
                None => unsettled.push((seed, cm(&p.target_m))),
            }
        }
    }
    assert!(unsettled.is_empty(), "unsettled: {unsettled:?}");
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    assert!(median <= 1.5 * 1.15, "median {median} of the ideal bound");
}

/// Off the table lattice, from a start that is not the origin, over the
/// whole workspace: nothing is refused and everything settles.
#[test]
fn an_off_lattice_grid_from_an_off_centre_start_is_covered() {
    let (points, s) = reach(0.052, 0.013, vec![0.007, -0.011]);
    let inside: Vec<&ReachPoint> = points
        .iter()
        .filter(|p| p.target_m.iter().all(|x| x.abs() <= 0.06))
        .collect();
    assert!(inside.len() >= 60, "{}", inside.len());
    for p in &points {
        let outside = p.target_m.iter().any(|x| x.abs() > 0.06);
        match (&p.refused, outside) {
            (Some(reason), true) => assert!(reason.contains("outside the workspace"), "{reason}"),
            (Some(reason), false) => panic!("{:?} cm refused: {reason}", cm(&p.target_m)),
            (None, true) => panic!("{:?} cm is outside but accepted", cm(&p.target_m)),
            (None, false) => assert!(
                p.settle_time_s.is_some(),
                "{:?} cm never settled",
                cm(&p.target_m)
            ),
        }
    }
    println!("{s:?}");
}

#[test]
fn scenarios_a_and_c_settle_within_0_8_s() {
    let config = Config::embedded_default();
    for target in [[0.02, 0.0, 0.03, 0.0], [0.02, 0.0, -0.01, 0.0]] {
        let mut opts = RunOptions::new(&config, target.to_vec(), Sampling::Ideal);
        opts.duration_s = 3.0;
        let m = run(&config, &opts).unwrap().metrics;
        let settle = m.settle_time_s.expect("settles");
        println!(
            "{:?} cm: settle {settle:.3} s, bound {:?} s",
            cm(&target),
            m.min_time_bound_s
        );
        assert!(settle <= 0.8, "{target:?}: {m:?}");
    }
}

fn far_run(start: [f64; 2], target: [f64; 2], sampling: Sampling, seed: u64) -> Metrics {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let state = vec![target[0], 0.0, target[1], 0.0];
    let mut opts = RunOptions::new(&config, state, sampling);
    opts.start_m = start.to_vec();
    opts.seed = seed;
    opts.duration_s = 14.0;
    opts.disturbance = match sampling {
        Sampling::Ideal => DisturbanceConfig::default(),
        _ => DisturbanceLevel::Paper.config(&model, seed),
    };
    run(&config, &opts).unwrap().metrics
}

/// 12 cm moves across the workspace (chained legs), under every sampling
/// mode; the scanner cycles with noise and the paper's disturbance.
#[test]
fn far_moves_across_the_workspace_settle_under_every_sampling() {
    let moves = [
        ([-0.06, -0.06], [0.06, 0.06]),
        ([-0.06, 0.06], [0.06, -0.06]),
        ([0.06, -0.02], [-0.05, 0.045]),
    ];
    for (start, target) in moves {
        for sampling in [Sampling::Ideal, Sampling::Constant, Sampling::Variable] {
            let m = far_run(start, target, sampling, 1);
            println!(
                "{:?} -> {:?} cm, {}: settle {:?} s, bound {:?} s",
                cm(&start),
                cm(&target),
                sampling.name(),
                m.settle_held_s,
                m.min_time_bound_s
            );
            // Arrival, held 1 s (the relative drift can take the capsules
            // out of the band seconds later: docs/known-limits.md).
            let settle = m
                .settle_held_s
                .unwrap_or_else(|| panic!("{start:?} -> {target:?} {sampling:?}: {m:?}"));
            if sampling == Sampling::Ideal {
                // A chained move keeps close to its chained bound.
                let ratio = m.settle_over_bound.unwrap();
                assert!(
                    ratio <= 1.6,
                    "{start:?} -> {target:?}: ratio {ratio} ({settle} s)"
                );
            }
        }
    }
}

/// The target changes while the capsules move fast toward another one.
#[test]
fn a_target_changed_mid_run_is_reached_from_the_moving_state() {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let cases = [
        ([0.02, 0.0, 0.03, 0.0], [0.02, 0.0, -0.01, 0.0], 0.2),
        ([0.02, 0.0, -0.01, 0.0], [-0.05, 0.0, 0.05, 0.0], 0.3),
        ([0.04, 0.0, -0.04, 0.0], [0.06, 0.0, 0.06, 0.0], 0.5),
        ([-0.03, 0.0, 0.01, 0.0], [0.0, 0.0, 0.0, 0.0], 0.15),
    ];
    for (first, second, at_s) in cases {
        for sampling in [Sampling::Ideal, Sampling::Variable] {
            let mut opts = RunOptions::new(&config, first.to_vec(), sampling);
            opts.retarget = Some(Retarget {
                at_s,
                target: second.to_vec(),
            });
            opts.duration_s = 10.0;
            if sampling != Sampling::Ideal {
                opts.disturbance = DisturbanceLevel::Paper.config(&model, 2);
                opts.seed = 2;
            }
            let report = run(&config, &opts).unwrap();
            let m = &report.metrics;
            println!(
                "{:?} then {:?} cm at {at_s} s, {}: settle {:?} s",
                cm(&first),
                cm(&second),
                sampling.name(),
                m.settle_held_s
            );
            // The capsules were moving when the target changed.
            let k = report.t.iter().position(|&t| t >= at_s).unwrap();
            let speed = report.x[k]
                .iter()
                .skip(1)
                .step_by(2)
                .fold(0.0_f64, |a, v| a.max(v.abs()));
            assert!(speed > 0.02, "not moving at the retarget: {speed} m/s");
            // Arrival held 1 s, then station keeping: the capsules' relative
            // drift (a few tenths of a mm/s left at arrival) takes them out
            // of the band every several seconds for one differential swing
            // (docs/known-limits.md), so a 10 s run can end mid-swing;
            // asserted is the arrival and 80 % of the time in the band
            // after it.
            let arrived = m
                .settle_held_s
                .unwrap_or_else(|| panic!("{first:?} -> {second:?} {sampling:?}: {m:?}"));
            assert!(
                arrived <= 3.0,
                "{first:?} -> {second:?} {sampling:?}: {m:?}"
            );
            let kept = m.time_in_band_after_entry.unwrap_or(0.0);
            assert!(kept >= 0.8, "{first:?} -> {second:?} {sampling:?}: {m:?}");
            assert_eq!(report.target, second.to_vec());
        }
    }
}

#[test]
fn a_target_or_start_outside_the_workspace_is_refused_with_the_bound_and_excess() {
    let config = Config::embedded_default();
    let mut opts = RunOptions::new(&config, vec![0.02, 0.0, -0.075, 0.0], Sampling::Ideal);
    let err = format!("{:#}", run(&config, &opts).unwrap_err());
    assert!(
        err.contains("capsule 2 at -0.075 m is outside the workspace [-0.06, 0.06] m by 0.0150 m (below the lower bound"),
        "{err}"
    );
    opts.target = vec![0.02, 0.0, 0.03, 0.0];
    opts.start_m = vec![0.0605, 0.0];
    let err = format!("{:#}", run(&config, &opts).unwrap_err());
    assert!(err.contains("start"), "{err}");
    assert!(err.contains("by 0.0005 m (above the upper bound"), "{err}");
    opts.start_m = vec![0.0];
    let err = format!("{:#}", run(&config, &opts).unwrap_err());
    assert!(err.contains("start has 1 positions"), "{err}");
}
