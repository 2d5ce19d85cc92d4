//! Issue 8, runtime faults: one test per fault, each asserting the status
//! code and the safe output, on `DefaultController` driven directly.
//!
//! Settings are always built from `DefaultController::default_settings()`
//! with fields modified, never with a struct literal, so that new settings
//! fields do not break these tests.

use capsule_mpc_generator::config::{Config, DisturbanceConfig};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::{
    braking_gradient, ControllerSettings, Sampling, SwitchingRule, BRAKING_HORIZON_S,
    MAX_ABS_SPEED_M_PER_S, REACQUIRE_AFTER_REJECTIONS,
};
use capsule_mpc_runtime::generated::controller::spec::{self, K, M, N, NX};
use capsule_mpc_runtime::generated::controller::{Solver, Spec, TABLES};
use capsule_mpc_runtime::solver::rollout::rollout_cost;
use capsule_mpc_runtime::solver::shooting::SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S;
use capsule_mpc_runtime::solver::{lookup, PlanSolver, Schedule, SolveStatus};
use capsule_mpc_runtime::{CycleOutput, DefaultController, RuntimeError, RuntimeStatus};
use capsule_mpc_sim::plant::{DisturbanceLevel, Phase, Plant};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// The tests after the in-loop helpers, split off to keep files short.
#[path = "faults/arguments.rs"]
mod arguments;
#[path = "faults/reacquisition.rs"]
mod reacquisition;

/// Scenario A and C targets (both covered from rest at the origin).
const A: [f64; NX] = [0.02, 0.0, 0.03, 0.0];
const C: [f64; NX] = [0.02, 0.0, -0.01, 0.0];
const U_MAX: f64 = spec::U_MAX_T_PER_M;

fn settings(sampling: Sampling) -> ControllerSettings {
    let mut s = DefaultController::default_settings();
    s.sampling = sampling;
    s
}

/// A controller at rest at the origin with `target` set.
fn controller(sampling: Sampling, target: &[f64; NX]) -> DefaultController {
    let mut c = DefaultController::new(settings(sampling), &[0.0; M]).unwrap();
    c.set_target(target).unwrap();
    c
}

/// The safe-output invariant every cycle must meet, whatever the status:
/// every gradient (played or not) finite and within |u| <= u_max, a play
/// length in 1..=N, a finite estimate.
fn assert_safe(out: &CycleOutput<K>, what: &str) {
    for (k, u) in out.gradients_t_per_m.iter().enumerate() {
        assert!(
            u.is_finite() && u.abs() <= U_MAX,
            "{what}: gradient[{k}] = {u} T/m violates |u| <= {U_MAX} ({out:?})"
        );
    }
    assert!(
        (1..=N).contains(&out.actuation_samples),
        "{what}: actuation_samples = {} not in 1..={N}",
        out.actuation_samples
    );
    assert!(
        out.estimate[..NX].iter().all(|v| v.is_finite()),
        "{what}: estimate {:?} not finite",
        &out.estimate[..NX]
    );
}

/// Per-capsule (mean, covariance) of the filters.
fn filters(c: &DefaultController) -> [([f64; 2], [f64; 4]); M] {
    core::array::from_fn(|i| {
        let f = c.filter(i).unwrap();
        (f.mean, f.cov)
    })
}

/// The estimate `x` predicted over `duration_s` at gradient `u` with the
/// solver's model (what the estimator's time update computes).
fn predicted(x: &[f64; NX], u: f64, duration_s: f64) -> [f64; NX] {
    <Solver as PlanSolver<NX, K>>::predict_constant(x, u, duration_s)
}

/// The positions the estimate expects at the next tracking start (a
/// consistent, noise-free frame).
fn expected_frame(c: &DefaultController) -> [f64; M] {
    let x = c.estimate();
    core::array::from_fn(|i| x[2 * i])
}

/// A few normal cycles with consistent frames (the controller starts to
/// push towards the target; the estimate moves off its start).
fn warm_up(c: &mut DefaultController) {
    for _ in 0..3 {
        let out = c.cycle(Some(&expected_frame(c))).unwrap();
        assert_eq!(out.status, RuntimeStatus::Ok);
        assert_safe(&out, "warm-up");
    }
}

fn wait_s(c: &DefaultController) -> f64 {
    c.settings().tracking_time_s + c.settings().extra_delay_s
}

// ---------------------------------------------------------------------------
// NaN / inf / out-of-range measurements.

/// Each bad frame is rejected (status MeasurementRejected), the estimate is
/// not pulled by it: the cycle is exactly the lost-frame cycle (same
/// prediction from the unchanged estimate, same plan), and the plan is
/// finite and within u_max. A good frame afterwards is fused again.
#[test]
fn bad_measurements_are_rejected_and_the_estimate_kept() {
    let bad_frames: [(&str, [f64; M]); 9] = [
        ("NaN capsule 1", [f64::NAN, 0.0]),
        ("NaN capsule 2", [0.0, f64::NAN]),
        ("+inf", [f64::INFINITY, 0.0]),
        ("-inf", [0.0, f64::NEG_INFINITY]),
        ("both NaN", [f64::NAN, f64::NAN]),
        ("out of range (> 1 m)", [2.0, 0.0]),
        ("out of range (< -1 m)", [0.0, -1.5]),
        ("huge", [1e300, -1e300]),
        // Inside 1 m but ~1000 sigma from the estimate: a gross outlier.
        ("gross outlier", [0.3, 0.0]),
    ];
    for sampling in [Sampling::Constant, Sampling::Variable, Sampling::Ideal] {
        for (what, z) in bad_frames {
            let what = format!("{sampling:?}, {what}");
            let mut c = controller(sampling, &A);
            warm_up(&mut c);
            let before = c.estimate();
            let mut twin = c.clone();

            let out = c.cycle(Some(&z)).unwrap();
            assert_eq!(out.status, RuntimeStatus::MeasurementRejected, "{what}");
            assert_safe(&out, &what);
            // Estimate kept: the actuation start is the prediction of the
            // estimate before the frame, not a fusion with it.
            let expected = predicted(&before, 0.0, wait_s(&c));
            assert_eq!(&out.estimate[..NX], &expected[..], "{what}");
            // The same as a lost frame, bit for bit (plan and filters).
            let lost = twin.cycle(None).unwrap();
            assert_eq!(lost.status, RuntimeStatus::MeasurementLost);
            assert_eq!(out.gradients_t_per_m, lost.gradients_t_per_m, "{what}");
            assert_eq!(out.actuation_samples, lost.actuation_samples, "{what}");
            assert_eq!(filters(&c), filters(&twin), "{what}");

            // The next good frame is accepted again.
            let out = c.cycle(Some(&expected_frame(&c))).unwrap();
            assert_eq!(out.status, RuntimeStatus::Ok, "{what}: recovery");
            assert_safe(&out, &what);
        }
    }
}

// ---------------------------------------------------------------------------
// Lost tracking frame.

/// A lost frame reports MeasurementLost; the estimate is predicted only (the
/// actuation start is the model prediction of the previous estimate through
/// tracking + delay, then it follows the played gradients), and the
/// position uncertainty grows with every lost frame until a frame arrives.
#[test]
fn lost_frames_predict_the_estimate_and_grow_its_covariance() {
    for sampling in [Sampling::Constant, Sampling::Variable] {
        let mut c = controller(sampling, &A);
        warm_up(&mut c);
        let mut last_cov = filters(&c).map(|(_, cov)| cov);
        for frame in 0..6 {
            let what = format!("{sampling:?}, lost frame {frame}");
            let before = c.estimate();
            let out = c.cycle(None).unwrap();
            assert_eq!(out.status, RuntimeStatus::MeasurementLost, "{what}");
            assert_safe(&out, &what);
            let start = predicted(&before, 0.0, wait_s(&c));
            assert_eq!(&out.estimate[..NX], &start[..], "{what}");
            // Then the estimator follows the actuation that will be played.
            let mut x = start;
            for &u in &out.gradients_t_per_m[..out.actuation_samples] {
                x = predicted(&x, u, spec::DT_S);
            }
            assert_eq!(c.estimate(), x, "{what}");
            let cov = filters(&c).map(|(_, cov)| cov);
            // Position uncertainty grows (the speed variance may shrink:
            // drag damps speed errors of a moving capsule).
            for i in 0..M {
                assert!(
                    cov[i][0] > last_cov[i][0],
                    "{what}: capsule {i} position variance did not grow: {:?} -> {:?}",
                    last_cov[i],
                    cov[i]
                );
            }
            last_cov = cov;
        }
        // A frame arrives: the position uncertainty shrinks again.
        let out = c.cycle(Some(&expected_frame(&c))).unwrap();
        assert_eq!(out.status, RuntimeStatus::Ok);
        assert_safe(&out, "frame after losses");
        for (i, (_, cov)) in filters(&c).iter().enumerate() {
            assert!(cov[0] < last_cov[i][0], "capsule {i}: {cov:?}");
        }
    }
}

// ---------------------------------------------------------------------------
// State outside the tables' range.

/// Distance every capsule coasts (u = 0) over `BRAKING_HORIZON_S` from
/// `x` after one sample at `u`, summed, with the solver's model.
fn coasting_after(x: &[f64; NX], u: f64) -> f64 {
    let braked = predicted(x, u, spec::DT_S);
    let coasted = predicted(&braked, 0.0, BRAKING_HORIZON_S);
    (0..M).map(|i| (coasted[2 * i] - braked[2 * i]).abs()).sum()
}

/// Outside the warm-start index with no current plan, the status is
/// Fallback and the output is one braking sample (every later sample zero),
/// never a (extrapolated) table plan. The braking law leaves the capsules
/// the least distance to coast: no more than no braking or braking the
/// mean speed (which can leave them moving apart, one coasting far). At
/// rest it is zero, and the next cycle starts a recovery leg (status
/// Recovering, a stored plan) when the tables reach a point nearer the
/// target; while moving the next cycle brakes again.
#[test]
fn state_outside_the_tables_falls_back_to_braking() {
    let g_mean = spec::G.iter().sum::<f64>() / M as f64;
    let cases: [(&str, [f64; NX], Option<f64>); 6] = [
        // Speeds far outside the index (|v| <= 0.45 m/s), still physical
        // (<= MAX_ABS_SPEED_M_PER_S): saturated braking.
        ("+0.9 m/s", [A[0], 0.9, A[2], 0.9], Some(-U_MAX)),
        ("-1 m/s", [A[0], -1.0, A[2], -1.0], Some(U_MAX)),
        // One capsule just outside the index, moving apart.
        ("0.46 / -0.44 m/s", [A[0], 0.46, A[2], -0.44], None),
        // The case: 86 and 231 mm/s braked on the mean would leave
        // -72 and +73 mm/s, the large capsule coasting 12 cm.
        (
            "86 / 231 mm/s, 10 cm off",
            [-0.08, 0.086, -0.07, 0.231],
            None,
        ),
        // Positions far outside, at rest: nothing to brake.
        ("30 cm off, at rest", [0.3, 0.0, -0.3, 0.0], Some(0.0)),
        ("90 cm off, moving", [0.9, 0.1, -0.9, 0.2], None),
    ];
    for (what, x, exact) in cases {
        let mut c = controller(Sampling::Ideal, &A);
        let out = c.cycle_full_state(&x).unwrap();
        assert_eq!(out.status, RuntimeStatus::Fallback, "{what}");
        assert_safe(&out, what);
        assert_eq!(
            out.solve.map(|r| r.status),
            Some(SolveStatus::OutOfRange),
            "{what}"
        );
        assert_eq!(out.actuation_samples, 1, "{what}");
        let u = out.gradients_t_per_m[0];
        assert_eq!(u, braking_gradient::<Solver, NX, K>(&x), "{what}");
        if let Some(expected) = exact {
            assert_eq!(u, expected, "{what}");
        }
        assert!(
            out.gradients_t_per_m[1..].iter().all(|&v| v == 0.0),
            "{what}: only the braking sample may be non-zero: {:?}",
            out.gradients_t_per_m
        );
        let mean_law = (-(x[1] + x[3]) / 2.0 / (g_mean * spec::DT_S)).clamp(-U_MAX, U_MAX);
        let (ours, none, mean) = (
            coasting_after(&x, u),
            coasting_after(&x, 0.0),
            coasting_after(&x, mean_law),
        );
        assert!(
            ours <= none + 1e-9 && ours <= mean + 1e-9,
            "{what}: coasts {ours} m after braking, {none} m without, {mean} m after mean braking"
        );
        // The next cycle from the same state.
        let again = c.cycle_full_state(&x).unwrap();
        assert_safe(&again, what);
        if u == 0.0 {
            assert_eq!(again.status, RuntimeStatus::Recovering, "{what}");
            assert!(again.solve.is_some_and(|r| r.took_table_plan), "{what}");
        } else {
            assert_eq!(again.status, RuntimeStatus::Fallback, "{what}");
        }
    }
    // Moving apart, braking the mean does next to nothing (and leaves
    // 14.5 cm to coast); the law stops the large capsule: 12.7 cm.
    let x = [A[0], 0.46, A[2], -0.44];
    let mean_law = (-(x[1] + x[3]) / 2.0 / (g_mean * spec::DT_S)).clamp(-U_MAX, U_MAX);
    let ours = coasting_after(&x, braking_gradient::<Solver, NX, K>(&x));
    assert!(coasting_after(&x, mean_law) > ours + 0.01, "{ours}");

    // The same through the scanner cycle: the estimate restarted at the
    // workspace's edge, outside the tables from A (beyond the workspace a
    // restart is refused).
    let mut c = controller(Sampling::Constant, &A);
    assert!(c.reset(&[0.5, -0.5]).is_err());
    c.reset(&[0.06, -0.06]).unwrap();
    let out = c.cycle(Some(&[0.06, -0.06])).unwrap();
    assert_eq!(out.status, RuntimeStatus::Fallback);
    assert_safe(&out, "cycle, at the workspace's edge");
    assert_eq!(
        out.gradients_t_per_m[0],
        braking_gradient::<Solver, NX, K>(out.estimate[..NX].try_into().unwrap())
    );
    assert!(out.gradients_t_per_m[1..].iter().all(|&v| v == 0.0));
}

/// At rest outside the tables' range (8-10 cm off, no stored plan reaches
/// the target from there), the controller does not stay in Fallback: it
/// moves the capsules along stored plans to intermediate points (status
/// Recovering, one leg after another) until the tables reach the target,
/// and then settles there within 5 s (ideal sampling on the solver's
/// model; 6 s runs).
#[test]
fn recovery_legs_bring_a_state_at_rest_outside_the_tables_back() {
    for start in [[0.10, 0.0, 0.11, 0.0], [-0.06, 0.0, 0.08, 0.0]] {
        let mut c = controller(Sampling::Ideal, &A);
        let mut x = start;
        let mut statuses = Vec::new();
        for _ in 0..300 {
            let out = c.cycle_full_state(&x).unwrap();
            assert_safe(&out, "recovery");
            statuses.push(out.status);
            x = predicted(&x, out.gradients_t_per_m[0], spec::DT_S);
        }
        let what = format!("from {start:?}: final {x:?}");
        assert_eq!(statuses[0], RuntimeStatus::Fallback, "{what}");
        let legs = statuses
            .iter()
            .filter(|s| **s == RuntimeStatus::Recovering)
            .count();
        assert!(legs > 0, "{what}");
        let last_non_ok = statuses
            .iter()
            .rposition(|s| *s != RuntimeStatus::Ok)
            .unwrap();
        assert!(last_non_ok < 250, "{what}: {statuses:?}");
        for i in 0..M {
            assert!((x[2 * i] - A[2 * i]).abs() <= 1e-3, "{what}");
            assert!(x[2 * i + 1].abs() <= 5e-3, "{what}");
        }
    }
}

/// A full state beyond the physical range (|x| > 1 m or |v| > 1 m/s) is
/// rejected like an implausible frame: status MeasurementRejected, the
/// estimate kept (and planned from), a safe plan. Before the fix, such a
/// state was stored in the estimator, whose next prediction overflowed to
/// NaN: every later frame was rejected and the estimate stayed NaN
/// (found by the `runtime` fuzz target, fuzz/regressions/runtime/).
#[test]
fn implausible_full_state_is_rejected_and_the_estimate_kept() {
    let implausible: [(&str, [f64; NX]); 4] = [
        ("5 m/s", [A[0], 5.0, A[2], 5.0]),
        ("1e300 m/s", [0.0, 1e300, 0.0, 0.0]),
        ("2 m away", [2.0, 0.0, 0.0, 0.0]),
        ("1e300 m away", [0.0, 0.0, -1e300, 0.0]),
    ];
    for (what, bad) in implausible {
        let mut c = controller(Sampling::Ideal, &A);
        let good = [0.001, 0.05, 0.002, 0.06];
        assert_eq!(c.cycle_full_state(&good).unwrap().status, RuntimeStatus::Ok);
        let mut twin = c.clone();
        let out = c.cycle_full_state(&bad).unwrap();
        assert_eq!(out.status, RuntimeStatus::MeasurementRejected, "{what}");
        assert_safe(&out, what);
        assert_eq!(c.estimate(), good, "{what}: estimate kept");
        assert_eq!(&out.estimate[..NX], &good[..], "{what}: planned from it");
        // The same plan as the kept state fed again would give.
        let again = twin.cycle_full_state(&good).unwrap();
        assert_eq!(out.gradients_t_per_m, again.gradients_t_per_m, "{what}");
        // Measured cycles afterwards keep a finite estimate and accept frames.
        for _ in 0..5 {
            let out = c.cycle(Some(&expected_frame(&c))).unwrap();
            assert_eq!(out.status, RuntimeStatus::Ok, "{what}");
            assert_safe(&out, what);
        }
    }
}

// ---------------------------------------------------------------------------
// Iteration bound of the online QP.

/// Relative states (as f64 bits) where the cold solve of the embedded
/// solver hits the QP iteration bound, found by a seeded search over the
/// bench's uniform distribution (ChaCha8 seed 1, positions +-5 cm, speeds
/// +-0.3 m/s): 31 of the first 200 000 states hit it on the cold or warm
/// step. If the generated solver changes, `iteration_limit_state` searches
/// again from the same seed.
const ITERATION_LIMIT_STATES: [[u64; NX]; 3] = [
    [
        13795011086203902120,
        13806845838492767504,
        13802347986011122784,
        13820410128511608174,
    ],
    [
        4585677177486125834,
        13821614934766026848,
        4581082874382596260,
        4599012167785343563,
    ],
    [
        4572262082091137040,
        13820007645318783946,
        4578193483166375564,
        4596168946699583286,
    ],
];

/// The first state on which a fresh `cycle_full_state` (target 0, so the
/// state is the relative state) reports IterationLimit.
fn iteration_limit_state(proto: &DefaultController) -> Option<[f64; NX]> {
    // Inside a kept index cell too, so that a fresh solver starting from the
    // stored tail hits the bound as well (the controller's explicit tier
    // also starts from samples of neighbouring cells).
    let hits = |e: &[f64; NX]| {
        let mut c = proto.clone();
        c.cycle_full_state(e).unwrap().status == RuntimeStatus::IterationLimit
            && Solver::new().solve(e).status == SolveStatus::IterationLimit
    };
    let known = ITERATION_LIMIT_STATES
        .iter()
        .map(|bits| bits.map(f64::from_bits))
        .find(|e| hits(e));
    if known.is_some() {
        return known;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    (0..200_000)
        .map(|_| {
            core::array::from_fn(|j| {
                if j % 2 == 0 {
                    rng.gen_range(-0.05..=0.05)
                } else {
                    rng.gen_range(-0.3..=0.3)
                }
            })
        })
        .find(|e| hits(e))
}

/// A solve whose QP needs more active-set iterations than the offline map
/// measured in its index cell is flagged AboveIterationMap (never silent);
/// the plan is the solver's converged plan, within u_max. Cells are
/// measured at their centres and neighbours, so such states exist (about
/// 1 in 2000 bench solves) but are rare.
#[test]
fn solve_above_the_offline_iteration_map_is_flagged() {
    use capsule_mpc_runtime::generated::qp_iteration_map;
    assert!(
        !qp_iteration_map::CONTROLLER.is_empty(),
        "map not measured: run `capsule-mpc generate`"
    );
    let mut proto = DefaultController::new(settings(Sampling::Ideal), &[0.0; M]).unwrap();
    proto.set_target(&[0.0; NX]).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut found = None;
    for _ in 0..200_000 {
        let e: [f64; NX] = core::array::from_fn(|j| {
            if j % 2 == 0 {
                rng.gen_range(-0.05..=0.05)
            } else {
                rng.gen_range(-0.3..=0.3)
            }
        });
        let mut c = proto.clone();
        let out = c.cycle_full_state(&e).unwrap();
        let report = out.solve.expect("a solve report");
        let measured = Solver::qp_iterations_measured(&e);
        let above = measured > 0 && report.max_qp_iterations > measured;
        // The flag is exactly "above the map" (when nothing else is wrong).
        if report.status == SolveStatus::Refined {
            assert_eq!(
                out.status == RuntimeStatus::AboveIterationMap,
                above,
                "{e:?}"
            );
        }
        if above && report.status == SolveStatus::Refined {
            found = Some((e, out));
            break;
        }
    }
    let (e, out) = found.expect("no state above the map in 200 000 seeded states");
    assert_safe(&out, "above the iteration map");
    // The controller under ideal sampling shoots, at the full state's
    // speed tolerance: the same solver, set up alike.
    let mut s = Solver::new();
    s.set_shooting(true);
    s.set_shot_speed_tolerance(SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S);
    s.set_tail_shots(true);
    s.solve(&e);
    assert_eq!(&out.gradients_t_per_m, s.plan());
}

/// A QP that hits its iteration bound is flagged IterationLimit through the
/// controller, and the plan played is finite, within u_max, no worse than
/// the solver's best feasible plan nor the stored plan it started from.
#[test]
fn iteration_limit_is_flagged_with_a_finite_bounded_plan() {
    let mut proto = DefaultController::new(settings(Sampling::Ideal), &[0.0; M]).unwrap();
    proto.set_target(&[0.0; NX]).unwrap();
    let e = iteration_limit_state(&proto)
        .expect("no state hits the QP iteration bound in 200 000 seeded states");

    let mut c = proto.clone();
    let out = c.cycle_full_state(&e).unwrap();
    assert_eq!(out.status, RuntimeStatus::IterationLimit);
    assert_safe(&out, "iteration limit");
    let report = out.solve.expect("a solve report");
    assert_eq!(report.status, SolveStatus::IterationLimit);
    assert_eq!(
        report.max_qp_iterations as usize,
        <Solver as PlanSolver<NX, K>>::QP_MAX_ITERATIONS
    );
    assert!(report.cost.is_finite());

    // The plan played is the cheaper of the two tiers' (issue 15): no worse
    // than the best feasible plan a fresh solver refines from the stored
    // tail...
    let mut s = Solver::new();
    let direct = s.solve(&e);
    assert_eq!(direct.status, SolveStatus::IterationLimit);
    let played_cost =
        rollout_cost::<Spec, M, NX, K>(&e, &out.gradients_t_per_m, &Schedule::BACK_TO_BACK);
    assert!(
        played_cost <= direct.cost * (1.0 + 1e-12),
        "played {played_cost} > refined {}",
        direct.cost
    );
    assert!(out.gradients_t_per_m.iter().any(|&u| u != 0.0));
    // ... and it is no worse than the stored plan the solve started from.
    let mut table = [0.0; K];
    lookup::lookup_tail(&TABLES, &e, &mut table).expect("state inside the index");
    let table_cost = rollout_cost::<Spec, M, NX, K>(&e, &table, &Schedule::BACK_TO_BACK);
    assert!(report.cost <= table_cost, "{} > {table_cost}", report.cost);

    // The loop goes on: the next cycle from the predicted state is usable.
    let e1 = Solver::predict_plan(&e, &out.gradients_t_per_m, 1);
    let next = c.cycle_full_state(&e1).unwrap();
    assert_safe(&next, "after the iteration limit");
    assert_ne!(next.status, RuntimeStatus::Fallback);
}

// ---------------------------------------------------------------------------
// Target change mid-run, in the plant simulator.

/// The closed loop of `closed_loop.rs`, cycle by cycle, so the test can act
/// between cycles.
/// What the tracking phase delivers.
#[derive(Debug, Clone, Copy)]
enum Frame {
    Measured,
    Lost,
    /// A wrong frame instead of the measured one.
    Replaced([f64; M]),
}

struct Loop {
    plant: Plant,
    ctl: DefaultController,
    sampling: Sampling,
    max_abs_u: f64,
}

impl Loop {
    fn new(
        sampling: Sampling,
        target: &[f64; NX],
        disturbance: DisturbanceLevel,
        seed: u64,
    ) -> Loop {
        let config = Config::embedded_default();
        let model = Model::from_config(&config);
        let (noise, dist) = if sampling == Sampling::Ideal {
            (0.0, DisturbanceConfig::default())
        } else {
            (
                config.measurement.position_noise_m,
                disturbance.config(&model, seed),
            )
        };
        let plant = Plant::new(model, vec![0.0; NX], dist.clone(), noise, seed).unwrap();
        let mut s = settings(sampling);
        s.disturbance_bound = dist.bound_si();
        s.position_noise_m = noise;
        let mut ctl = DefaultController::new(s, &[0.0; M]).unwrap();
        ctl.set_target(target).unwrap();
        Loop {
            plant,
            ctl,
            sampling,
            max_abs_u: 0.0,
        }
    }

    /// One scanner cycle on the plant's timeline; `frame` says what the
    /// tracking delivers (ignored under ideal sampling, which reads the
    /// true state).
    fn cycle_with(&mut self, frame: Frame) -> CycleOutput<K> {
        let out = if self.sampling == Sampling::Ideal {
            let x: [f64; NX] = self.plant.state().try_into().unwrap();
            self.ctl.cycle_full_state(&x).unwrap()
        } else {
            let z = self.plant.measure_positions();
            let s = *self.ctl.settings();
            self.plant
                .advance(s.tracking_time_s + s.extra_delay_s, 0.0, Phase::Track)
                .unwrap();
            match frame {
                Frame::Measured => self.ctl.cycle(Some(&z)),
                Frame::Lost => self.ctl.cycle(None),
                Frame::Replaced(bad) => self.ctl.cycle(Some(&bad)),
            }
            .unwrap()
        };
        assert_safe(&out, "closed loop");
        for &u in &out.gradients_t_per_m[..out.actuation_samples] {
            self.max_abs_u = self.max_abs_u.max(u.abs());
            self.plant.advance(spec::DT_S, u, Phase::Actuate).unwrap();
        }
        out
    }

    fn cycle(&mut self) -> CycleOutput<K> {
        self.cycle_with(Frame::Measured)
    }

    fn run_until(&mut self, t_s: f64) {
        while self.plant.time_s() < t_s {
            self.cycle();
        }
    }

    fn position_error(&self, target: &[f64; NX]) -> f64 {
        let x = self.plant.state();
        (0..M)
            .map(|i| (x[2 * i] - target[2 * i]).abs())
            .fold(0.0, f64::max)
    }
}
