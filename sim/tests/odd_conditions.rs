//! Capsules off the model under odd conditions, all at once: each run draws
//! its own plant (drag x0.8-1.2 and gain x0.9-1.1, one factor per capsule),
//! a start and a target at rest anywhere in +-5 cm, ideal, constant or
//! variable sampling, a random or drifting disturbance of the paper's size,
//! 0, 5 or 10 ms of extra delay per cycle (the end of the proven range) and
//! no, every 7th or every 4th tracking frame lost; 8 s runs, strict settle.
//! The draw is seeded, so the runs are the same on every machine.
//!
//! Asserted: every run settles (measured on `docs/scripts/random_plants.py
//! --odd`'s 550 such runs: every one, worst 7.82 s; here 120 runs, median
//! 1.88 s, worst 7.74 s: gains x1.04 / x0.97, held from 2.05 s while the
//! capsules drift apart to the band's edge, left at 7.54 s) and the median
//! settle stays within `MEDIAN_BOUND_S` (measured 1.44-1.69 s over those
//! 550). A constant bias is left out: the hold
//! cannot keep two capsules inside the band against its relative part
//! (docs/known-limits.md, "Station keeping under a constant bias").
//! Printed: every run's conditions and settle time.

use capsule_mpc_generator::config::{Config, DisturbanceKind};
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::DisturbanceLevel;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const RUNS: usize = 120;
const DRAW_SEED: u64 = 26;
const DURATION_S: f64 = 8.0;
const REACH_M: f64 = 0.05;
/// Bound on the median settle of the draw, s.
const MEDIAN_BOUND_S: f64 = 2.5;

/// One drawn run: what differs from the default options.
#[derive(Debug)]
struct OddRun {
    start_m: Vec<f64>,
    target_m: Vec<f64>,
    drag: Vec<f64>,
    gain: Vec<f64>,
    sampling: Sampling,
    drift: bool,
    extra_delay_s: f64,
    lose_every: Option<usize>,
    seed: u64,
}

fn draw(rng: &mut ChaCha8Rng) -> OddRun {
    let mut positions =
        || -> Vec<f64> { (0..2).map(|_| rng.gen_range(-REACH_M..=REACH_M)).collect() };
    let start_m = positions();
    let target_m = positions();
    let drag = (0..2).map(|_| rng.gen_range(0.8..=1.2)).collect();
    let gain = (0..2).map(|_| rng.gen_range(0.9..=1.1)).collect();
    let sampling = [Sampling::Ideal, Sampling::Constant, Sampling::Variable][rng.gen_range(0..3)];
    OddRun {
        start_m,
        target_m,
        drag,
        gain,
        sampling,
        drift: rng.gen_bool(0.5),
        extra_delay_s: [0.0, 0.005, 0.01][rng.gen_range(0..3)],
        lose_every: [None, Some(7), Some(4)][rng.gen_range(0..3)],
        seed: rng.gen_range(1..=1000),
    }
}

fn settle_s(config: &Config, r: &OddRun) -> Option<f64> {
    let model = capsule_mpc_generator::model::Model::from_config(config);
    let target = vec![r.target_m[0], 0.0, r.target_m[1], 0.0];
    let mut opts = RunOptions::new(config, target, r.sampling);
    opts.start_m = r.start_m.clone();
    opts.duration_s = DURATION_S;
    opts.seed = r.seed;
    opts.disturbance = DisturbanceLevel::Paper.config(&model, r.seed);
    if r.drift {
        opts.disturbance.kind = DisturbanceKind::Drift;
    }
    if r.sampling != Sampling::Ideal {
        opts.extra_delay_s += r.extra_delay_s;
        opts.lose_every = r.lose_every;
    }
    opts.mismatch = PlantMismatch {
        drag_scale: r.drag.clone(),
        gain_scale: r.gain.clone(),
    };
    run(config, &opts)
        .expect("closed-loop run")
        .metrics
        .settle_time_s
}

#[test]
fn capsules_off_the_model_settle_from_anywhere_under_odd_timing_and_lost_frames() {
    let config = Config::embedded_default();
    let mut rng = ChaCha8Rng::seed_from_u64(DRAW_SEED);
    let runs: Vec<OddRun> = (0..RUNS).map(|_| draw(&mut rng)).collect();
    let mut settles = Vec::new();
    let mut unsettled = Vec::new();
    for r in &runs {
        let s = settle_s(&config, r);
        println!("{:?}: settle {s:?}", r);
        match s {
            Some(t) => settles.push(t),
            None => unsettled.push(r),
        }
    }
    assert!(
        unsettled.is_empty(),
        "unsettled within {DURATION_S} s: {unsettled:?}"
    );
    settles.sort_by(f64::total_cmp);
    let median = settles[settles.len() / 2];
    println!(
        "{RUNS} runs: median {median:.2} s, worst {:.2} s",
        settles[settles.len() - 1]
    );
    assert!(median <= MEDIAN_BOUND_S, "median settle {median} s");
}
