//! The controller's mode machine (`Mode`, issue 26 item 4): which mode a
//! cycle is in, on the exact model under ideal sampling.

use capsule_mpc_runtime::controller::{Mode, Sampling};
use capsule_mpc_runtime::generated::controller::spec::{K, M, NX};
use capsule_mpc_runtime::generated::controller::Solver;
use capsule_mpc_runtime::solver::PlanSolver;
use capsule_mpc_runtime::{DefaultController, RuntimeStatus};

const A: [f64; NX] = [0.02, 0.0, 0.03, 0.0];
const C: [f64; NX] = [0.02, 0.0, -0.01, 0.0];
const DT_S: f64 = <Solver as PlanSolver<NX, K>>::DT_S;

fn controller() -> DefaultController {
    let mut s = DefaultController::default_settings();
    s.sampling = Sampling::Ideal;
    DefaultController::new(s, &[0.0; M]).unwrap()
}

/// The modes of `steps` ideal cycles from rest at the origin, the plant
/// being the solver's own model.
fn modes_to(c: &mut DefaultController, target: &[f64; NX], steps: usize) -> (Vec<Mode>, [f64; NX]) {
    c.set_target(target).unwrap();
    let mut x = c.estimate();
    let mut modes = Vec::new();
    for _ in 0..steps {
        let out = c.cycle_full_state(&x).unwrap();
        modes.push(c.mode());
        x = <Solver as PlanSolver<NX, K>>::predict_constant(&x, out.gradients_t_per_m[0], DT_S);
    }
    (modes, x)
}

#[test]
fn without_a_target_the_mode_is_no_target() {
    let mut c = controller();
    let out = c.cycle_full_state(&[0.0; NX]).unwrap();
    assert_eq!(out.status, RuntimeStatus::NoTarget);
    assert_eq!(c.mode(), Mode::NoTarget);
    assert_eq!(out.gradients_t_per_m[0], 0.0);
}

/// A reached target: plan, then hold for good (no fallback, no hold
/// before arrival), and the hold is where the capsules are at the target.
#[test]
fn a_reached_target_ends_in_the_hold_and_a_new_target_leaves_it() {
    let mut c = controller();
    for target in [A, C] {
        let (modes, x) = modes_to(&mut c, &target, 100);
        assert!(!modes.contains(&Mode::Fallback), "{target:?}: {modes:?}");
        let first_hold = modes.iter().position(|&m| m == Mode::Hold).expect("holds");
        assert!(
            modes[..first_hold]
                .iter()
                .all(|&m| m == Mode::Plan || m == Mode::Brake),
            "{target:?}: {modes:?}"
        );
        assert!(
            modes[first_hold..].iter().all(|&m| m == Mode::Hold),
            "{target:?}: {modes:?}"
        );
        assert!(c.holding());
        for i in 0..M {
            assert!(
                (x[2 * i] - target[2 * i]).abs() <= 1e-3,
                "{target:?}: {x:?}"
            );
        }
        c.reset(&[0.0; M]).unwrap();
        assert_eq!(c.mode(), Mode::Plan, "a reset leaves the hold");
        assert!(!c.holding());
    }
}

#[test]
fn a_state_no_plan_covers_falls_back() {
    let mut c = controller();
    c.set_target(&A).unwrap();
    let out = c.cycle_full_state(&[A[0], 0.9, A[2], 0.9]).unwrap();
    assert_eq!(out.status, RuntimeStatus::Fallback);
    assert_eq!(c.mode(), Mode::Fallback);
}

/// Outside the tables with the capsules moving apart slowly (15 mm/s each
/// way): one gradient cannot stop both, and near rest only drag, falling
/// as v^2, removes their relative speed (three capsules once braked for
/// 4.4 s so). The fallback re-plans the legs from there once every speed
/// is below `REPLAN_SPEED_M_PER_S` instead of waiting for rest; faster, it
/// keeps braking.
#[test]
fn a_fallback_replans_once_slow_without_waiting_for_rest() {
    use capsule_mpc_runtime::controller::REPLAN_SPEED_M_PER_S;
    for (speed, replans) in [
        (0.75 * REPLAN_SPEED_M_PER_S, true),
        (2.0 * REPLAN_SPEED_M_PER_S, false),
    ] {
        let mut c = controller();
        c.set_target(&A).unwrap();
        // 8 cm short of the target on both capsules: beyond the warm-start
        // index, within the chained legs.
        let x = [A[0] - 0.08, speed, A[2] - 0.08, -speed];
        let out = c.cycle_full_state(&x).unwrap();
        assert_eq!(out.status, RuntimeStatus::Fallback, "{speed} m/s");
        let out = c.cycle_full_state(&x).unwrap();
        assert_eq!(
            out.status != RuntimeStatus::Fallback,
            replans,
            "{speed} m/s: {:?}, mode {:?}",
            out.status,
            c.mode()
        );
        if replans {
            assert_eq!(out.status, RuntimeStatus::Recovering);
            assert_ne!(c.leg_target(), Some(&A), "a waypoint first");
        }
    }
}

/// The simulator's report carries the mode timeline: it starts planning,
/// ends in the hold shortly after the strict settle, and each entry is a
/// change of mode at a later time.
#[test]
fn the_run_report_carries_the_mode_timeline() {
    use capsule_mpc_generator::config::Config;
    use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling as SimSampling};
    let config = Config::embedded_default();
    for target in [A, C] {
        let mut opts = RunOptions::new(&config, target.to_vec(), SimSampling::Ideal);
        opts.duration_s = 2.0;
        let report = run(&config, &opts).unwrap();
        let modes = report.modes.expect("timeline");
        assert_eq!(modes.first().unwrap().mode, Mode::Plan.name());
        let last = modes.last().unwrap();
        assert_eq!(last.mode, Mode::Hold.name(), "{target:?}: {modes:?}");
        assert!(
            modes
                .windows(2)
                .all(|w| w[0].t_s < w[1].t_s && w[0].mode != w[1].mode),
            "{modes:?}"
        );
        let settle = report.metrics.settle_time_s.expect("settles");
        assert!(
            (last.t_s - settle).abs() <= 0.1,
            "{target:?}: hold at {} s, settle {settle} s",
            last.t_s
        );
    }
}
