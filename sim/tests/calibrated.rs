//! Capsules calibrated before the run: the plant off the model and the
//! controller told its factors (`Controller::set_model_factors`, 3 %
//! deviation, the simulator's default for told factors), against the nominal
//! plant on the same targets and seeds (the paper's disturbance, both
//! scanner-cycle samplings, 6 s).
//!
//! Asserted: every run settles, and the median is at most 1.3 x the
//! nominal plant's (issue 26's floor, which the uncalibrated loop misses
//! under variable sampling: `mismatch.rs`). Measured on the 24-target
//! grid, seeds 1-8: variable medians 1.05-1.22 s against 1.00 s, constant
//! 1.16-1.37 s against 1.18 s (docs/calibrate.md).
//!
//! And the short moves of the 1 cm reach grid with a 1 % calibration, on
//! the model and on a plant 3 % off it (three of its deviations): see
//! `a_sharp_calibration_keeps_short_moves_near_their_minimum_time`.

use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::config::DisturbanceKind;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::reach::{reach_map, ReachOptions};

const TARGETS_CM: [(f64, f64); 4] = [(2.0, 3.0), (2.0, -1.0), (-1.0, 2.0), (3.0, 1.0)];
const SEEDS: std::ops::RangeInclusive<u64> = 1..=8;

fn settle_times(
    config: &Config,
    sampling: Sampling,
    plant: &PlantMismatch,
    told: Option<f64>,
) -> Vec<f64> {
    let model = capsule_mpc_generator::model::Model::from_config(config);
    let mut out = Vec::new();
    for &(a, b) in &TARGETS_CM {
        for seed in SEEDS {
            let mut opts = RunOptions::new(config, vec![a / 100.0, 0.0, b / 100.0, 0.0], sampling);
            opts.duration_s = 6.0;
            opts.seed = seed;
            opts.disturbance = DisturbanceLevel::Paper.config(&model, seed);
            opts.mismatch = plant.clone();
            if let Some(std) = told {
                opts.known_factors = Some(plant.clone());
                opts.known_factor_std = std;
            }
            let r = run(config, &opts).expect("closed-loop run");
            let s = r.metrics.settle_time_s.unwrap_or_else(|| {
                panic!("{sampling:?} {plant:?} ({a}, {b}) cm seed {seed}: never settled")
            });
            if told.is_some() {
                assert!(
                    r.calibrated.is_some(),
                    "the report records the told factors"
                );
            }
            out.push(s);
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

/// Issue 26's mismatch floors for calibrated capsules, told with a 3 % and
/// a 1 % deviation: every run settles, the median within 1.3x the nominal
/// plant's. The floor's worst within 2x the nominal worst is not asserted:
/// here the nominal worst is short (0.99 s variable) and one run of gain
/// x0.9 told at 1 % takes 3.40 s (drag x0.8 told at 3 %: 5.39 s); on the
/// 24-target grid the 1 % worst is 2.04 s against 2.00 s (docs/calibrate.md).
#[test]
fn calibrated_capsules_settle_near_the_nominal_times() {
    let config = Config::embedded_default();
    let plants = [
        PlantMismatch::uniform(0.8, 1.0),
        PlantMismatch::uniform(1.2, 1.0),
        PlantMismatch {
            drag_scale: vec![1.2, 0.8],
            gain_scale: vec![],
        },
        PlantMismatch::uniform(1.0, 0.9),
        PlantMismatch::uniform(1.0, 1.1),
    ];
    for sampling in [Sampling::Constant, Sampling::Variable] {
        let nominal = settle_times(&config, sampling, &PlantMismatch::default(), None);
        let nominal_median = nominal[nominal.len() / 2];
        let nominal_worst = nominal[nominal.len() - 1];
        for plant in &plants {
            for std in [0.03, 0.01] {
                let t = settle_times(&config, sampling, plant, Some(std));
                let (median, worst) = (t[t.len() / 2], t[t.len() - 1]);
                eprintln!(
                    "{sampling:?} {plant:?} told at {std}: median {median:.2} s (nominal {nominal_median:.2} s), worst {worst:.2} s (nominal {nominal_worst:.2} s)"
                );
                assert!(
                    median <= 1.3 * nominal_median,
                    "{sampling:?} {plant:?} told at {std}: median {median} s against the nominal {nominal_median} s"
                );
            }
        }
    }
}

/// Settle over the ideal minimum time of every target of the 1 cm grid
/// (+-4 cm), variable sampling, the paper's disturbance, seeds 1-4, the
/// controller told the model's factors (1.0) with deviation `std`.
fn short_move_ratios(config: &Config, plant: &PlantMismatch, std: f64) -> Vec<f64> {
    let mut ratios = Vec::new();
    for seed in 1..=4 {
        let opts = ReachOptions {
            range_m: 0.04,
            step_m: 0.01,
            sampling: Sampling::Variable,
            disturbance: DisturbanceLevel::Paper,
            disturbance_kind: DisturbanceKind::Random,
            seed,
            start_m: Vec::new(),
            duration_s: None,
            extra_delay_s: None,
            mismatch: plant.clone(),
            known_factors: Some(PlantMismatch::default()),
            known_factor_std: std,
            shooting: None,
        };
        for p in reach_map(config, &opts, &|| {}).expect("reach grid") {
            // Never settled: counted as far beyond any bound.
            ratios.push(p.settle_over_bound.unwrap_or(f64::INFINITY));
        }
    }
    ratios.sort_by(f64::total_cmp);
    ratios
}

/// A calibration good to 1 % also tells the estimator how sure it may be of
/// the capsules' speeds from the start (`Controller::set_model_factors`
/// before the first cycle): the first frames then no longer put about
/// 1 mm/s of relative speed into the first arrival, which the hold cannot
/// remove. On the model every short move settles within 2x its ideal
/// minimum time (seeds 1-8: worst 1.69, against 6.38 with the speeds as
/// uncertain as the model's prior makes them). On a plant 3 % off the told
/// factors (three deviations) the loop still beats the 3 % calibration
/// (seeds 1-8: 5 against 135 of 640 runs above 2x).
#[test]
fn a_sharp_calibration_keeps_short_moves_near_their_minimum_time() {
    let config = Config::embedded_default();
    let model = short_move_ratios(&config, &PlantMismatch::default(), 0.01);
    let worst = model[model.len() - 1];
    eprintln!("model, told at 1 %: worst ratio {worst:.2}");
    assert!(
        worst <= 2.0,
        "a short move took {worst:.2}x its minimum time"
    );
    let off = PlantMismatch {
        drag_scale: vec![1.03],
        gain_scale: vec![0.97],
    };
    let above = |r: &[f64]| r.iter().filter(|&&x| x > 2.0).count();
    let sharp = short_move_ratios(&config, &off, 0.01);
    let loose = short_move_ratios(&config, &off, 0.03);
    eprintln!(
        "plant 3 % off: above 2x told at 1 %: {} of {}, at 3 %: {}",
        above(&sharp),
        sharp.len(),
        above(&loose)
    );
    assert!(
        above(&sharp) * 20 <= sharp.len() && 2 * above(&sharp) < above(&loose),
        "plant 3 % off: {} runs above 2x told at 1 %, {} at 3 %",
        above(&sharp),
        above(&loose)
    );
}
