//! Long gaps between actuation phases (tracking plus an extra compute or
//! transfer delay of up to 60 ms): the controller must still act.
//!
//! With 60 ms gaps under constant sampling, the refined plan for a 5 cm
//! move from rest started with an idle (zero) sample. Played, it left the
//! capsules at rest; re-planned from the same state, it started idle
//! again: the loop played zero gradient for as long as it ran. From rest an
//! idle sample only waits, so the runtime now starts such a plan at its
//! first acting sample.
//!
//! Run with `--nocapture` to see the reach summaries.

use capsule_mpc_generator::config::{Config, DisturbanceKind};
use capsule_mpc_runtime::controller::{Sampling, IDLE_GRADIENT_FRACTION};
use capsule_mpc_runtime::generated::controller::spec::{NX, U_MAX_T_PER_M};
use capsule_mpc_runtime::DefaultController;
use capsule_mpc_sim::closed_loop::{check_extra_delay, Sampling as SimSampling};
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::reach::{reach_map, ReachOptions, ReachSummary};

/// Extra delays after tracking, s (tracking itself is 20 ms).
const EXTRA_DELAYS_S: [f64; 4] = [0.0, 0.02, 0.04, 0.06];

/// From rest, away from the target, the first cycle's gradient is not
/// idle: for every target of a 1 cm grid over +-5 cm, both scanner-cycle
/// samplings and every gap above.
#[test]
fn from_rest_the_first_cycle_acts_whatever_the_gap() {
    let idle_t_per_m = IDLE_GRADIENT_FRACTION * U_MAX_T_PER_M;
    let mut checked = 0;
    let mut idle = Vec::new();
    for sampling in [Sampling::Constant, Sampling::Variable] {
        for extra_delay_s in EXTRA_DELAYS_S {
            for i in -5..=5 {
                for j in -5..=5 {
                    if i == 0 && j == 0 {
                        continue;
                    }
                    let mut settings = DefaultController::default_settings();
                    settings.sampling = sampling;
                    settings.extra_delay_s = extra_delay_s;
                    let mut ctl = DefaultController::new(settings, &[0.0, 0.0]).unwrap();
                    let target: [f64; NX] = [i as f64 * 0.01, 0.0, j as f64 * 0.01, 0.0];
                    ctl.set_target(&target).unwrap();
                    let out = ctl.cycle(Some(&[0.0, 0.0])).unwrap();
                    checked += 1;
                    if out.gradients_t_per_m[0].abs() <= idle_t_per_m {
                        idle.push(format!(
                            "{sampling:?}, extra {extra_delay_s} s, target ({i}, {j}) cm: u = {:e} T/m, {:?}",
                            out.gradients_t_per_m[0], out.status
                        ));
                    }
                }
            }
        }
    }
    assert_eq!(checked, 2 * EXTRA_DELAYS_S.len() * 120);
    assert!(idle.is_empty(), "idle first cycles:\n{}", idle.join("\n"));
}

/// Closed loop (true plant, no disturbance) to every target of the 1 cm
/// grid under constant sampling with 60 ms gaps: every run leaves its
/// start, and no capsule ends farther from its target than half its start
/// distance. Before the fix, (1, -3) cm never moved (30 mm off at the end).
#[test]
fn every_target_is_approached_with_60_ms_gaps() {
    let config = Config::embedded_default();
    let opts = ReachOptions {
        range_m: 0.04,
        step_m: 0.01,
        sampling: SimSampling::Constant,
        disturbance: DisturbanceLevel::None,
        disturbance_kind: DisturbanceKind::Random,
        seed: 1,
        start_m: Vec::new(),
        duration_s: None,
        extra_delay_s: Some(0.04),
        mismatch: Default::default(),
        shooting: false,
    };
    let points = reach_map(&config, &opts, &|| {}).unwrap();
    let summary = ReachSummary::of(&points);
    println!(
        "constant sampling, 60 ms gaps: {} targets, {} never settled, median settle {:?} s, worst {:?} s",
        summary.targets, summary.never_settled, summary.median_settle_time_s, summary.worst_settle_time_s
    );
    assert_eq!(summary.refused, 0);
    let mut far = Vec::new();
    for p in &points {
        let start_m = p.target_m.iter().map(|t| t.abs()).fold(0.0, f64::max);
        let final_m = p.final_position_error_m.unwrap();
        if final_m > 0.5 * start_m {
            far.push(format!("{:?}: {final_m:e} m off at the end", p.target_m));
        }
    }
    assert!(
        far.is_empty(),
        "targets not approached:\n{}",
        far.join("\n")
    );
}

/// An extra delay outside [0, 1] s is refused with the value and the range.
#[test]
fn a_bad_extra_delay_names_the_value_and_the_range() {
    for bad in [-0.01, 1.5, f64::NAN] {
        let message = check_extra_delay(bad).unwrap_err().to_string();
        assert!(
            message.contains("extra delay") && message.contains("[0, 1]"),
            "{message}"
        );
    }
    check_extra_delay(0.06).unwrap();
}
