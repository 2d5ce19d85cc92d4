//! The closed loop on capsules that are not quite the model: the plant's
//! drag and gain off by the amounts nobody can rule out (drag x0.8, x1.2
//! and split x1.2 / x0.8, gain x0.9 and x1.1), the paper's disturbance,
//! both scanner-cycle samplings, four targets and eight seeds, against the
//! nominal plant on the same targets and seeds.
//!
//! Asserted: the frame gate takes a capsule off the model for what it is,
//! not for a tracking glitch (at most 1 % of the true frames rejected on
//! every plant); every run settles within 6 s, on the model and off it;
//! the nominal plant within 2.0 s (measured worst 1.19 s constant, 0.99 s
//! variable); off the model the median is at most 1.3 x the nominal one
//! under constant sampling (measured at most 1.08 x) and, for a gain off
//! both capsules alike, under variable sampling too (measured 1.14 x and
//! 1.06 x), and 1.6 x for the drag rows under variable sampling (measured
//! at most 1.49 x: 1.18 s against 0.79 s), and at most `MAX_SLOW_RUNS`
//! of a plant's 32 runs take longer than twice the nominal worst (measured
//! at most 1,
//! constant gain x1.1; variants of the end game that this bound rejects:
//! docs/decisions.md). Issue 26 asks for 1.3 x everywhere: the drag rows
//! under variable sampling not met yet.
//! Printed: settled
//! runs and settle times per plant (docs/known-limits.md quotes them).

use capsule_mpc_generator::config::{Config, RefineMode};
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::DisturbanceLevel;

const TARGETS_CM: [(f64, f64); 4] = [(2.0, 3.0), (2.0, -1.0), (-1.0, 2.0), (3.0, 1.0)];
const DURATION_S: f64 = 6.0;
/// Twice the nominal plant's worst settle (1.19 s constant, 0.99 s
/// variable), s, and how many of a plant's 32 runs may exceed it.
const SLOW_S: f64 = 2.4;
const MAX_SLOW_RUNS: usize = 2;

struct Outcome {
    settle_s: Option<f64>,
    received: usize,
    rejected: usize,
}

fn one(
    config: &Config,
    target_cm: (f64, f64),
    sampling: Sampling,
    seed: u64,
    plant: &PlantMismatch,
) -> Outcome {
    let model = capsule_mpc_generator::model::Model::from_config(config);
    let target = vec![target_cm.0 / 100.0, 0.0, target_cm.1 / 100.0, 0.0];
    let mut opts = RunOptions::new(config, target, sampling);
    opts.duration_s = DURATION_S;
    opts.seed = seed;
    opts.disturbance = DisturbanceLevel::Paper.config(&model, seed);
    opts.mismatch = plant.clone();
    let r = run(config, &opts).expect("closed-loop run");
    let frames = r.frames.expect("frame counts");
    Outcome {
        settle_s: r.metrics.settle_time_s,
        received: frames.received,
        rejected: frames.rejected,
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

#[test]
fn off_model_capsules_settle_near_the_nominal_times() {
    let config = Config::embedded_default();
    let plants = [
        ("nominal", PlantMismatch::default()),
        ("drag x0.8", PlantMismatch::uniform(0.8, 1.0)),
        ("drag x1.2", PlantMismatch::uniform(1.2, 1.0)),
        ("drag x1.2/x0.8", split_drag()),
        ("gain x0.9", PlantMismatch::uniform(1.0, 0.9)),
        ("gain x1.1", PlantMismatch::uniform(1.0, 1.1)),
    ];
    let mut failures = Vec::new();
    for sampling in [Sampling::Constant, Sampling::Variable] {
        let mut nominal = (0.0, 0.0);
        for (name, plant) in &plants {
            let mut settles = Vec::new();
            let (mut unsettled, mut received, mut rejected) = (0, 0, 0);
            for &t in &TARGETS_CM {
                for seed in 1..=8 {
                    let o = one(&config, t, sampling, seed, plant);
                    match o.settle_s {
                        Some(s) => settles.push(s),
                        None => unsettled += 1,
                    }
                    received += o.received;
                    rejected += o.rejected;
                }
            }
            let worst = settles.iter().copied().fold(0.0, f64::max);
            let slow = settles.iter().filter(|&&s| s > SLOW_S).count();
            let med = if settles.is_empty() {
                f64::NAN
            } else {
                median(&mut settles)
            };
            let mut check = |ok: bool, what: String| {
                if !ok {
                    failures.push(format!("{sampling:?} {name}: {what}"));
                }
            };
            if *name == "nominal" {
                nominal = (med, worst);
                check(worst <= 2.0, format!("nominal worst {worst} s"));
            } else {
                let ratio = match (sampling, name.starts_with("gain")) {
                    (Sampling::Constant, _) | (_, true) => 1.3,
                    _ => 1.6,
                };
                check(
                    med <= ratio * nominal.0,
                    format!("median {med} s against the nominal {} s", nominal.0),
                );
                check(
                    slow <= MAX_SLOW_RUNS,
                    format!("{slow} of 32 runs slower than {SLOW_S} s"),
                );
            }
            check(unsettled == 0, format!("{unsettled} of 32 runs unsettled"));
            check(
                rejected as f64 <= 0.01 * received as f64,
                format!("{rejected} of {received} true frames rejected"),
            );
            eprintln!(
                "{:?} {name:<15} settled {}/{} median {med:.2} s worst {worst:.2} s, {slow} above {SLOW_S} s; rejected {rejected}/{received} frames ({:.1} %)",
                sampling,
                32 - unsettled,
                32,
                100.0 * rejected as f64 / received as f64
            );
        }
        eprintln!(
            "{sampling:?} nominal: median {:.2} s, worst {:.2} s",
            nominal.0, nominal.1
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A relative drift the hold's first look (0.8 s of frames) keeps only on
/// its rate's uncertainty is judged again at 1.3 s in the hold
/// (`HOLD_DRIFT_RECHECK_S`): the four targets' two slowest drag x0.8 runs,
/// (-1, 2) cm, whose line at 0.8 s (-0.66 +- 0.27 mm/s) stopped inside
/// within two deviations while the capsules stopped 1.9 mm apart at the
/// band's edge, settled at 4.20 s (constant, seed 7) and 4.38 s (variable,
/// seed 4) without the second look, 2.24 / 2.26 s with it.
#[test]
fn a_drift_the_first_look_cannot_tell_from_noise_is_judged_again() {
    let config = Config::embedded_default();
    let plant = PlantMismatch::uniform(0.8, 1.0);
    for (sampling, seed) in [(Sampling::Constant, 7), (Sampling::Variable, 4)] {
        let settle_s = one(&config, (-1.0, 2.0), sampling, seed, &plant).settle_s;
        assert!(
            settle_s.is_some_and(|s| s <= SLOW_S),
            "{sampling:?}, seed {seed}: settle {settle_s:?} s, allowed {SLOW_S} s"
        );
    }
}

/// The explicit law alone under variable sampling, its phases up to 10
/// samples long on the back-to-back plans (once the learned products
/// differ), swings the capsules at 100-400 mm/s with frames 0.22 s apart:
/// off the model the prediction over such a phase can leave even the
/// widened gate. Frames that agree with one another and whose run starts
/// within the model's drift bound are followed at the third instead of
/// rejected 20 at a time as a glitch. Asserted over the 24-target mismatch
/// grid (+-4 cm, 2 cm steps), seeds 1-2, the paper's disturbance: at most
/// 1 % of the true frames rejected on the two plants that rejected most
/// (1.6 % and 2.8 % when every phase was that long and the gate did not
/// follow; measured 0.03 % and 0 % now that phases are one sample while
/// the products agree).
#[test]
fn the_law_alone_follows_capsules_off_the_model_instead_of_rejecting_them() {
    let config = law_alone_config();
    let targets = grid_targets_cm();
    let plants = [
        ("drag x0.8", PlantMismatch::uniform(0.8, 1.0)),
        ("drag x1.2/x0.8", split_drag()),
    ];
    let mut failures = Vec::new();
    for (name, plant) in &plants {
        let (mut received, mut rejected) = (0, 0);
        for &t in &targets {
            for seed in 1..=2 {
                let o = one(&config, t, Sampling::Variable, seed, plant);
                received += o.received;
                rejected += o.rejected;
            }
        }
        let percent = 100.0 * rejected as f64 / received as f64;
        eprintln!("law alone, variable, {name}: rejected {rejected}/{received} true frames ({percent:.2} %)");
        if rejected as f64 > 0.01 * received as f64 {
            failures.push(format!(
                "{name}: {rejected} of {received} true frames rejected"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The explicit law alone answers capsules off the model with the model's
/// answer for a similar state: their errors and speeds scaled by the ratio
/// of gain-drag products, the gradient by its inverse (`solver::refine`).
/// Without it a drag x1.2 plant left 63 of 192 constant-sampling runs of
/// the mismatch grid unsettled (median 4.18 s) and gain x0.9 9 (2.33 s).
/// While the learned products agree, variable sampling plays one sample
/// per phase on the coasted plans (with the back-to-back plans the
/// medians were 2.20 x the nominal); once they differ (the drag split:
/// no state is similar) each plan is played to its end (re-solved every
/// cycle, the split left 84 of 192 constant-sampling runs unsettled).
/// Asserted over the 24-target grid (+-4 cm, 2 cm steps), seeds 1-2, the
/// paper's disturbance: on each plant at most one run of 48 unsettled;
/// the median within 1.3 x the nominal plant's under constant sampling
/// and 1.5 x under variable (measured 1.02-1.22 x and 1.06-1.43 x; issue
/// 26 asks 1.3 x), the split's within 2.0 x (measured 1.66 x and 1.86 x).
#[test]
fn the_law_alone_answers_capsules_off_the_model_with_a_similar_state() {
    let config = law_alone_config();
    let targets = grid_targets_cm();
    // (name, plant, its median bound against the nominal's when not the
    // sampling's: the split's products no similar state makes agree).
    let plants = [
        ("nominal", PlantMismatch::default(), None),
        ("drag x0.8", PlantMismatch::uniform(0.8, 1.0), None),
        ("drag x1.2", PlantMismatch::uniform(1.2, 1.0), None),
        ("gain x0.9", PlantMismatch::uniform(1.0, 0.9), None),
        ("gain x1.1", PlantMismatch::uniform(1.0, 1.1), None),
        ("drag x1.2/x0.8", split_drag(), Some(2.0)),
    ];
    let mut failures = Vec::new();
    for (sampling, median_ratio, max_unsettled) in
        [(Sampling::Constant, 1.3, 1), (Sampling::Variable, 1.5, 1)]
    {
        let mut nominal_median_s = f64::NAN;
        for (name, plant, own_ratio) in &plants {
            let mut settles = Vec::new();
            for &t in &targets {
                for seed in 1..=2 {
                    let o = one(&config, t, sampling, seed, plant);
                    settles.extend(o.settle_s);
                }
            }
            let runs = 2 * targets.len();
            let unsettled = runs - settles.len();
            let worst = settles.iter().copied().fold(0.0, f64::max);
            let med = median(&mut settles);
            eprintln!(
                "law alone, {sampling:?}, {name:<10} settled {}/{runs} median {med:.2} s worst {worst:.2} s",
                settles.len()
            );
            if *name == "nominal" {
                nominal_median_s = med;
            } else if med > own_ratio.unwrap_or(median_ratio) * nominal_median_s {
                failures.push(format!(
                    "{sampling:?} {name}: median {med} s against the nominal {nominal_median_s} s"
                ));
            }
            if unsettled > max_unsettled {
                failures.push(format!(
                    "{sampling:?} {name}: {unsettled} of {runs} runs unsettled"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The explicit law alone's config (`refine = none`).
fn law_alone_config() -> Config {
    let mut config = Config::embedded_default();
    config.controller.refine = RefineMode::None;
    config
}

/// The law alone's mismatch grid: +-4 cm in 2 cm steps per capsule, the
/// start excluded (24 targets), cm.
fn grid_targets_cm() -> Vec<(f64, f64)> {
    let steps_cm = [-4.0, -2.0, 0.0, 2.0, 4.0];
    steps_cm
        .iter()
        .flat_map(|&a| steps_cm.map(|b| (a, b)))
        .filter(|&(a, b)| (a, b) != (0.0, 0.0))
        .collect()
}

/// The drag split: the first capsule's drag x1.2, the second's x0.8.
fn split_drag() -> PlantMismatch {
    PlantMismatch {
        drag_scale: vec![1.2, 0.8],
        gain_scale: vec![],
    }
}

/// Capsules farther off than the controller is told (gain 15-20 %, drag
/// 30 %): after a long phase at full gradient the first frames leave the
/// gate the told uncertainty widens, and the frames' speed tells the
/// capsule from a glitch (`MODEL_ERROR_SPEED_SIGMAS`). Variable sampling,
/// the paper's disturbance, seeds 1-8: every run settles within 6 s and no
/// run rejects more than 6 true frames (measured at most 4 and a worst
/// settle of 4.90 s; judged on the first frame alone, seed 3 rejected 43,
/// 42 and 20: docs/decisions.md).
#[test]
fn capsules_beyond_their_told_uncertainty_are_followed_not_rejected() {
    const MAX_REJECTED: usize = 6;
    let config = Config::embedded_default();
    let cases = [
        (vec![1.3], vec![0.85, 1.15], (-3.01, -2.21)),
        (vec![1.3, 0.7], vec![0.85, 1.15], (-3.44, -3.27)),
        (vec![1.0], vec![1.0, 1.2], (-3.01, -2.21)),
    ];
    let mut failures = Vec::new();
    for (drag_scale, gain_scale, target_cm) in cases {
        let plant = PlantMismatch {
            drag_scale,
            gain_scale,
        };
        for seed in 1..=8 {
            let o = one(&config, target_cm, Sampling::Variable, seed, &plant);
            println!(
                "{plant:?} {target_cm:?} seed {seed}: settle {:?} s, rejected {} of {}",
                o.settle_s, o.rejected, o.received
            );
            if o.settle_s.is_none() || o.rejected > MAX_REJECTED {
                failures.push(format!(
                    "{plant:?} {target_cm:?} seed {seed}: settle {:?}, rejected {}",
                    o.settle_s, o.rejected
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
