//! Issue 16: the shipped three-capsule preset (`configs/three-capsules.toml`)
//! is compiled next to the default, picked by its config, and steers three
//! capsules to every target of its +-3 cm workspace.

use capsule_mpc_generator::config::{Config, DisturbanceKind};
use capsule_mpc_generator::generate::ControllerModule;
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::generated::{controller, three_capsules};
use capsule_mpc_sim::closed_loop::{compiled_controller_for, run, RunOptions, Sampling};
use capsule_mpc_sim::metrics::Metrics;
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::reach::{reach_map, ReachOptions, ReachPoint, ReachSummary};

fn cm(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x * 100.0).collect()
}

/// Run length, s: long enough for the slowest chained moves (minimum-time
/// bounds up to 3.7 s) and the end game's re-plans.
const RUN_S: f64 = 8.0;

/// Settle times lie on the simulator's 1 ms grid, summed in floating point:
/// a settle of exactly twice the bound may read a few 1e-15 s above it.
const SETTLE_ROUNDING_S: f64 = 1e-9;

/// The scanner tests' targets, cm.
const SCANNER_TARGETS_CM: [[f64; 3]; 10] = [
    [1.0, 1.0, 1.0],
    [3.0, 3.0, 3.0],
    [-3.0, -3.0, -3.0],
    [3.0, -3.0, 3.0],
    [-3.0, 3.0, 0.0],
    [2.0, 0.0, -1.0],
    [0.0, 2.5, -2.5],
    [-1.5, 0.5, 2.0],
    [0.5, -2.0, -0.5],
    [-2.0, -1.0, 3.0],
];

/// One `RUN_S` run of the three-capsule preset from rest at the origin to
/// `target_cm` (at rest); with `seed`, the paper's random disturbance and
/// that seed, else the default seed and no disturbance.
fn run_to(target_cm: [f64; 3], sampling: Sampling, seed: Option<u64>) -> Metrics {
    run_for(target_cm, sampling, seed, RUN_S)
}

/// As [`run_to`], for `duration_s`.
fn run_for(target_cm: [f64; 3], sampling: Sampling, seed: Option<u64>, duration_s: f64) -> Metrics {
    let config = three();
    let state: Vec<f64> = target_cm.iter().flat_map(|&p| [p / 100.0, 0.0]).collect();
    let mut opts = RunOptions::new(&config, state, sampling);
    opts.duration_s = duration_s;
    if let Some(seed) = seed {
        let model = Model::from_config(&config);
        opts.seed = seed;
        opts.disturbance =
            DisturbanceLevel::Paper.config_of_kind(&model, seed, DisturbanceKind::Random);
    }
    run(&config, &opts).unwrap().metrics
}

fn three() -> Config {
    Config::embedded_three_capsules()
}

fn ideal_reach(step_m: f64) -> (Vec<ReachPoint>, ReachSummary) {
    let opts = ReachOptions {
        range_m: 0.03,
        step_m,
        sampling: Sampling::Ideal,
        disturbance: DisturbanceLevel::None,
        disturbance_kind: DisturbanceKind::Random,
        seed: 1,
        start_m: Vec::new(),
        duration_s: Some(RUN_S),
        extra_delay_s: None,
        mismatch: Default::default(),
        known_factors: None,
        known_factor_std: capsule_mpc_sim::closed_loop::KNOWN_FACTOR_STD,
        shooting: None,
    };
    let points = reach_map(&three(), &opts, &|| {}).unwrap();
    let summary = ReachSummary::of(&points);
    (points, summary)
}

/// Targets whose run was refused or did not settle, or settled later than
/// `limit_s` (in the band, held 1 s).
fn late(points: &[ReachPoint], limit_s: f64) -> Vec<String> {
    late_by(points, limit_s, |p| p.settle_time_s)
}

/// As `late`, by the held settle (in the band for 1 s: the arrival).
fn late_arrival(points: &[ReachPoint], limit_s: f64) -> Vec<String> {
    late_by(points, limit_s, |p| p.held_settle_time_s)
}

fn late_by(
    points: &[ReachPoint],
    limit_s: f64,
    settle: impl Fn(&ReachPoint) -> Option<f64>,
) -> Vec<String> {
    points
        .iter()
        .filter(|p| p.refused.is_some() || settle(p).is_none_or(|t| t > limit_s))
        .map(|p| format!("{:?} cm: {:?} {:?}", cm(&p.target_m), settle(p), p.refused))
        .collect()
}

#[test]
fn each_config_runs_on_its_own_compiled_controller() {
    assert_eq!(
        compiled_controller_for(&three()).unwrap(),
        ControllerModule::ThreeCapsules
    );
    assert_eq!(
        compiled_controller_for(&Config::embedded_default()).unwrap(),
        ControllerModule::Controller
    );
    assert_eq!(three_capsules::spec::M, 3);
    assert_eq!(controller::spec::M, 2);
    // The simulation-only sections do not select a controller.
    let mut noisy = three();
    noisy.measurement.position_noise_m = 1e-3;
    noisy.disturbance.seed = 99;
    assert_eq!(
        compiled_controller_for(&noisy).unwrap(),
        ControllerModule::ThreeCapsules
    );
}

/// The three-capsule module has no explicit tier (docs/three-capsules.md):
/// `refine = none` is refused for it with the runtime's `BadSetting`, named
/// in the error; the refinement runs. The `refine` setting does not select
/// the compiled module (it is a runtime setting, not in the solver hash).
#[test]
fn the_three_capsule_module_has_no_explicit_tier() {
    use capsule_mpc_generator::config::RefineMode;
    use capsule_mpc_runtime::solver::PlanSolver;
    use capsule_mpc_runtime::{Controller, RuntimeError};
    type Three = three_capsules::Solver;
    const NX: usize = three_capsules::spec::NX;
    const K: usize = three_capsules::spec::K;
    const { assert!(!<Three as PlanSolver<NX, K>>::HAS_EXPLICIT_TIER) };
    assert_eq!(three_capsules::TABLES.explicit_count, 0);
    const {
        assert!(
            <controller::Solver as PlanSolver<
                { controller::spec::NX },
                { controller::spec::K },
            >>::HAS_EXPLICIT_TIER
        )
    };
    let mut settings = Controller::<Three, NX, K>::default_settings();
    settings.refine = capsule_mpc_runtime::controller::Refine::None;
    assert!(matches!(
        Controller::<Three, NX, K>::new(settings, &[0.0; 3]),
        Err(RuntimeError::BadSetting("refine"))
    ));
    let mut config = three();
    config.controller.refine = RefineMode::None;
    assert_eq!(
        compiled_controller_for(&config).unwrap(),
        ControllerModule::ThreeCapsules
    );
    let target = vec![0.01, 0.0, 0.0, 0.0, -0.01, 0.0];
    let err = run(&config, &RunOptions::new(&config, target, Sampling::Ideal))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("refine = none") && err.contains("three-capsule"),
        "{err}"
    );
}

/// A config nothing was compiled for is refused before the run, with the
/// command that generates its controller.
#[test]
fn a_config_with_no_compiled_controller_says_how_to_generate_one() {
    let mut other = three();
    other.capsule[1].sphere_radius_m = 0.0025;
    let target = vec![0.01, 0.0, 0.0, 0.0, -0.01, 0.0];
    let err = run(&other, &RunOptions::new(&other, target, Sampling::Ideal))
        .unwrap_err()
        .to_string();
    for needle in [
        "no compiled controller",
        "3 capsules",
        "capsule-mpc generate --config FILE --module three-capsules",
        "cargo build --release",
        "`three_capsules` (3 capsules",
    ] {
        assert!(err.contains(needle), "`{needle}` missing from: {err}");
    }
    let mut two = Config::embedded_default();
    two.controller.sample_time_s = 0.025;
    let err = run(
        &two,
        &RunOptions::new(&two, vec![0.01, 0.0, 0.0, 0.0], Sampling::Ideal),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("--module controller"), "{err}");
}

/// Every target of the 1 cm grid over the workspace (342 targets, the plan
/// grid's own points) from rest at the origin, ideal sampling: every one
/// accepted and arrives (in the band, held 1 s); the strict settle (in the
/// band from then to the end of the 8 s run) is what the issue measures.
/// The minimum-time bound itself exceeds 1.5 s for 144 of these targets
/// (three capsules separate only through their drag differences), and the
/// end game loses time to relative drift (docs/known-limits.md, "Three
/// capsules"). The bound of a target no single stored plan reaches is its
/// chain of rest-to-rest legs, which the shot through the waypoints beats
/// (ratios below 1). Measured with the minimum-time shots (on by default
/// for three capsules): every target settles strictly, median 1.20 s,
/// settle / bound median 0.95, worst 1.44 at (0, 0, 1) cm; without them 18
/// targets did not settle strictly, median 2.05 s, worst ratio 18.8.
/// Asserted (issue 26's floors): every target settles strictly, median <=
/// 1.3 s, settle / bound median <= 1.05 (asked: 1.3), no target above 1.4
/// (asked: 1.8; measured 1.25, 1.44 without the shots from the stored
/// tail).
#[test]
fn every_target_of_the_1_cm_grid_settles() {
    let (points, s) = ideal_reach(0.01);
    assert_eq!(s.targets, 342);
    println!(
        "M = 3, 1 cm grid: settle median {:?} s, worst {:?} s; settle / bound median {:?}, worst {:?} at {:?}",
        s.median_settle_time_s,
        s.worst_settle_time_s,
        s.median_settle_over_bound,
        s.worst_settle_over_bound,
        s.worst_ratio_target_m.as_deref().map(cm)
    );
    let bad = late_arrival(&points, RUN_S);
    assert!(
        bad.is_empty(),
        "{} targets never arrive: {bad:?}",
        bad.len()
    );
    let strict = late(&points, RUN_S);
    assert!(
        strict.is_empty(),
        "{} targets not settled strictly: {strict:?}",
        strict.len()
    );
    assert!(s.median_settle_time_s.unwrap() <= 1.3);
    assert!(s.median_settle_over_bound.unwrap() <= 1.05);
    let slow: Vec<_> = points
        .iter()
        .filter(|p| p.settle_over_bound.is_some_and(|r| r > 1.4))
        .map(|p| cm(&p.target_m))
        .collect();
    assert!(
        slow.is_empty(),
        "{} above 1.4 x the bound: {slow:?}",
        slow.len()
    );
}

/// Off the plan grid: a 1.5 cm grid (124 targets, most between plan grid
/// points, reached through chained legs and the fine end game): every one
/// accepted and arrives (held settle) within the 8 s run. Measured strict
/// settle with the shots: every target, median 1.27 s, worst 3.56 s
/// (without the shot through the waypoints: median 1.59 s, worst 3.94 s;
/// without shots: median 2.47 s, two targets unsettled). Asserted: every
/// one settles strictly, strict median <= 1.4 s.
#[test]
fn off_grid_targets_settle() {
    let (points, s) = ideal_reach(0.015);
    assert_eq!(s.targets, 124);
    println!(
        "M = 3, 1.5 cm grid: settle median {:?} s, worst {:?} s",
        s.median_settle_time_s, s.worst_settle_time_s
    );
    assert!(points.iter().all(|p| p.refused.is_none()));
    let bad = late_arrival(&points, RUN_S);
    assert!(
        bad.is_empty(),
        "{} targets never arrive: {bad:?}",
        bad.len()
    );
    let strict = late(&points, RUN_S);
    assert!(
        strict.is_empty(),
        "{} targets not settled strictly: {strict:?}",
        strict.len()
    );
    assert!(s.median_settle_time_s.unwrap() <= 1.4);
}

/// Constant and variable sampling with 0.2 mm noise and the paper's
/// disturbance, seeds 1-8, over targets spread through the workspace
/// (corners, faces, the (1, 1, 1) cm, mixed directions), strict
/// settle (in the band from then to the end of the 8 s run). Issue 26 asks
/// for every run of at least 40 within 2x of its schedule's minimum time
/// (the coasted bound under constant sampling where the tables have it,
/// else the ideal one). Measured, of 80 runs each: constant sampling every
/// run within 2x (the tightest 1.89x), median 1.36 s, worst 5.16 s;
/// variable every run, 1.30 s, 5.54 s (without the shots from the stored
/// tail 80 and 79; without the shot through the waypoints 73 and 76).
/// Asserted: every run settles within 2x.
#[test]
fn scanner_sampling_settles_with_noise_and_disturbance() {
    let mut summaries = Vec::new();
    for sampling in [Sampling::Constant, Sampling::Variable] {
        let mut settled = Vec::new();
        let mut never = Vec::new();
        let mut within_2x = 0;
        for t in SCANNER_TARGETS_CM {
            for seed in 1..=8 {
                let m = run_to(t, sampling, Some(seed));
                let label = format!("{t:?} cm seed {seed}");
                let bound_s = m
                    .schedule_min_time_s
                    .or(m.min_time_bound_s)
                    .unwrap_or(f64::INFINITY);
                match m.settle_time_s {
                    Some(s) => {
                        if s <= 2.0 * bound_s + SETTLE_ROUNDING_S {
                            within_2x += 1;
                        }
                        settled.push((s, label));
                    }
                    None => never.push((label, m.settle_held_s)),
                }
            }
        }
        settled.sort_by(|a, b| a.0.total_cmp(&b.0));
        let median = settled[settled.len() / 2].0;
        println!(
            "M = 3, {} sampling: {} of 80 settle (strict), {within_2x} within 2x of the schedule's bound, median {median:.2} s, worst {:?}; never (held settle): {never:?}",
            sampling.name(),
            settled.len(),
            settled.last()
        );
        summaries.push((sampling, settled.len(), within_2x));
    }
    for (sampling, settled, within_2x) in summaries {
        assert!(
            settled == 80 && within_2x == 80,
            "{}: {settled} of 80 settled, {within_2x} within 2x",
            sampling.name()
        );
    }
}

/// Station keeping long after the arrival: under the paper's random
/// disturbance the third combination (which the hold does not move, see
/// `third_combination` in the runtime) walks a capsule to the band's edge
/// again and again, and each time the hold is left for a shot. 20 s runs
/// to the scanner targets x seeds 1-4, both samplings: from the first
/// entry to the end of the run every run is in the band at least
/// `MIN_IN_BAND` of the time. Measured worst 0.956 (constant sampling) and
/// 0.959 (variable); sitting at the edge instead, 0.889 and 0.886, 24 of
/// 80 runs below (docs/known-limits.md, "Three capsules").
#[test]
fn station_keeping_holds_the_band_over_20_s() {
    const MIN_IN_BAND: f64 = 0.95;
    const STATION_RUN_S: f64 = 20.0;
    let mut low = Vec::new();
    let mut worst = f64::INFINITY;
    for sampling in [Sampling::Constant, Sampling::Variable] {
        for t in SCANNER_TARGETS_CM {
            for seed in 1..=4 {
                let m = run_for(t, sampling, Some(seed), STATION_RUN_S);
                let in_band = m.time_in_band_after_entry.unwrap_or(0.0);
                worst = worst.min(in_band);
                if in_band < MIN_IN_BAND {
                    low.push(format!(
                        "{} {t:?} cm seed {seed}: {in_band:.3}",
                        sampling.name()
                    ));
                }
            }
        }
    }
    println!(
        "M = 3, station keeping over 20 s runs: worst in band {worst:.3} after the first entry"
    );
    assert!(low.is_empty(), "below {MIN_IN_BAND} in band: {low:?}");
}

/// Under variable sampling the first frames choose 1-sample phases and the
/// shot is solved for them; when the switching rule asks for longer ones
/// that the shot does not converge on, the shot flies on with its own
/// phases. Dropped for the refinement, (3, 3, 3) cm, seed 2 swung about
/// the start and settled at 1.74 s (2.0x its 0.86 s bound); kept, 1.16 s.
#[test]
fn a_shot_that_cannot_take_longer_phases_keeps_its_own() {
    let m = run_to([3.0, 3.0, 3.0], Sampling::Variable, Some(2));
    let bound_s = m.min_time_bound_s.unwrap();
    let settle_s = m.settle_time_s.expect("settles");
    assert!(
        settle_s <= 1.5 * bound_s,
        "settled at {settle_s} s against a {bound_s} s bound"
    );
}

/// From rest under variable sampling the first solve models the switching
/// rule's long phases with a coast after each, and for a separation of
/// about 1 s the refined stored plan does not settle within the horizon:
/// the short shot from it never converged, and (2, 0, -1) cm, seed 8,
/// found none until 2.2 s (2.61 s, 2.3x its 1.12 s bound). The shot from
/// the stored plan tail, as long as the tail takes to settle, converges at
/// the first cycle: 1.20 s.
#[test]
fn a_separation_from_rest_shoots_from_the_stored_plan() {
    let m = run_to([2.0, 0.0, -1.0], Sampling::Variable, Some(8));
    let bound_s = m.min_time_bound_s.unwrap();
    let settle_s = m.settle_time_s.expect("settles");
    assert!(
        settle_s <= 1.25 * bound_s,
        "settled at {settle_s} s against a {bound_s} s bound"
    );
}

/// The sparse index keeps a small part of the dense grid for three
/// capsules, and the tables fit the budget.
#[test]
fn the_sparse_index_scales_with_the_plans() {
    let dense = |pos: usize, spd: usize, m: u32| (pos * spd).pow(m);
    let dense3 = dense(
        three_capsules::TABLES.index_position_axis.count,
        three_capsules::TABLES.index_speed_axis.count,
        3,
    );
    let kept3 = three_capsules::TABLES.cell_count;
    let dense2 = dense(
        controller::TABLES.index_position_axis.count,
        controller::TABLES.index_speed_axis.count,
        2,
    );
    let kept2 = controller::TABLES.cell_count;
    let file_bytes = |name: &str| {
        std::fs::metadata(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("generated")
                .join(name),
        )
        .unwrap()
        .len()
    };
    let (bin2, bin3) = (
        file_bytes("controller.tables.bin"),
        file_bytes("three_capsules.tables.bin"),
    );
    println!(
        "index cells kept: M = 2 {kept2} of {dense2}, M = 3 {kept3} of {dense3}; table files M = 2 {bin2} B, M = 3 {bin3} B; section data M = 2 {} B, M = 3 {} B",
        controller::TABLES.data_bytes(),
        three_capsules::TABLES.data_bytes()
    );
    assert!(kept3 * 2 < dense3, "{kept3} of {dense3}");
    // Issue 26's budget: at most 32 MiB of tables per module.
    assert!(bin3 <= 32 << 20, "three capsules' tables: {bin3} B");
    assert!(bin2 <= 32 << 20, "the default module's tables: {bin2} B");
    // Sorted and distinct: the runtime bisects them.
    use capsule_mpc_runtime::solver::format::Section;
    for t in [three_capsules::TABLES, controller::TABLES] {
        let cells: Vec<u64> = (0..t.cell_count)
            .map(|c| t.u64_at(Section::IndexCells, c))
            .collect();
        assert!(cells.windows(2).all(|w| w[0] < w[1]));
    }
}

/// A target off the plan grid that no single stored plan reaches,
/// (0.5, -2, -0.5) cm: the legs stop at rest at two waypoints (1.70 s,
/// against the chain's 1.14 s of rest-to-rest legs); the shot through
/// them, seeded from the shot in flight and the chain's stored plans,
/// does not stop: 1.22 s. Asserted: within 1.15x the chain's time.
#[test]
fn a_move_through_waypoints_does_not_stop_at_them() {
    let m = run_to([0.5, -2.0, -0.5], Sampling::Ideal, None);
    let bound_s = m.min_time_bound_s.unwrap();
    let settle_s = m.settle_time_s.expect("settles");
    assert!(
        settle_s <= 1.15 * bound_s,
        "settled at {settle_s} s against the chain's {bound_s} s"
    );
}

/// Where a chain cuts each leg is stored with the plan
/// (`Section::PlanSettle`, `Section::CoastedPlanSettle`), computed by the
/// generator from its own rollouts: it must be where the runtime's model,
/// played on each set's schedule (constant sampling: a coast after every
/// sample), stays in the settle band, for every plan of both sets.
#[test]
fn stored_settle_samples_match_the_runtime_rollout() {
    use capsule_mpc_runtime::solver::format::{Section, NO_SETTLE, SCALAR_COAST_S};
    use capsule_mpc_runtime::solver::tables::PlanSet;
    use capsule_mpc_runtime::solver::PlanSolver;
    type Three = three_capsules::Solver;
    const NX: usize = three_capsules::spec::NX;
    const K: usize = three_capsules::spec::K;
    let t = &three_capsules::TABLES;
    let coast_s = t.scalar(SCALAR_COAST_S);
    assert!(coast_s > 0.0, "the preset has constant sampling's plans");
    let in_band =
        |e: &[f64; NX]| (0..NX / 2).all(|c| e[2 * c].abs() <= 1e-3 && e[2 * c + 1].abs() <= 5e-3);
    let mut compared = 0;
    for (set, section, coast) in [
        (PlanSet::BackToBack, Section::PlanSettle, 0.0),
        (PlanSet::Coasted, Section::CoastedPlanSettle, coast_s),
    ] {
        for p in 0..t.plan_count {
            // The plan's grid point, the last capsule fastest.
            let mut e = [0.0; NX];
            let mut flat = p;
            for c in (0..NX / 2).rev() {
                e[2 * c] = t.plan_axis.start + (flat % t.plan_axis.count) as f64 * t.plan_axis.step;
                flat /= t.plan_axis.count;
            }
            let mut last_out = None;
            for k in 0..=K {
                if !in_band(&e) {
                    last_out = Some(k);
                }
                if k < K {
                    let mut one = [0.0; K];
                    one[0] = t.plan_u(set, p, k);
                    e = <Three as PlanSolver<NX, K>>::predict_plan(&e, &one, 1);
                    if coast > 0.0 {
                        e = <Three as PlanSolver<NX, K>>::predict_constant(&e, 0.0, coast);
                    }
                }
            }
            let expected = match last_out {
                None => 0,
                Some(K) => NO_SETTLE,
                Some(k) => k as u16 + 1,
            };
            assert_eq!(t.u16_at(section, p), expected, "plan {p} of {set:?}");
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * 343);
}

/// The chain of stored legs played back to back as one plan, the start of
/// the shot through the waypoints (`lookup::chain_plan`): rest-to-rest legs
/// compose, so from rest at every displacement of the 1 cm lattice that
/// no single stored plan reaches, the chain that fits in one plan arrives
/// at the target at rest on the model (within the settle band: 1 mm, 5
/// mm/s).
#[test]
fn chained_legs_played_back_to_back_arrive() {
    use capsule_mpc_runtime::solver::lookup::chain_plan;
    use capsule_mpc_runtime::solver::PlanSolver;
    type Three = three_capsules::Solver;
    const NX: usize = three_capsules::spec::NX;
    const K: usize = three_capsules::spec::K;
    let in_band =
        |e: &[f64; NX]| (0..NX / 2).all(|c| e[2 * c].abs() <= 1e-3 && e[2 * c + 1].abs() <= 5e-3);
    let (mut chains, mut checked) = (0, 0);
    let mut missed = Vec::new();
    for i in 0..343 {
        let d: [f64; NX] = core::array::from_fn(|j| {
            let digit = [i / 49, i / 7 % 7, i % 7][j / 2] as f64;
            if j % 2 == 0 {
                (digit - 3.0) / 100.0
            } else {
                0.0
            }
        });
        let mut plan = [0.0; K];
        let Some(total) = chain_plan::<NX, K>(
            &three_capsules::TABLES,
            true,
            (&[0.0; K], 0),
            &d,
            false,
            &mut plan,
        ) else {
            continue;
        };
        chains += 1;
        if total > K {
            continue;
        }
        checked += 1;
        let end = <Three as PlanSolver<NX, K>>::predict_plan(&d, &plan, total);
        if !in_band(&end) {
            missed.push((cm(&[d[0], d[2], d[4]]), cm(&end)));
        }
    }
    println!("M = 3: {chains} chains of two legs or more, {checked} fit in one plan");
    assert!(checked >= 20, "only {checked} of {chains} chains checked");
    assert!(
        missed.is_empty(),
        "{} chains miss: {missed:?}",
        missed.len()
    );
}
