//! Three capsules off the model: each run draws its own plant (drag
//! x0.8-1.2 and gain x0.9-1.1, one factor per capsule), a target at rest
//! anywhere in the preset's +-3 cm, constant or variable sampling and a
//! random or drifting disturbance of the paper's size; 8 s runs from rest
//! at the origin, strict settle. The draw is seeded, so the runs are the
//! same on every machine.
//!
//! What such runs lose their time to is the hold's third combination (the
//! one neither the gradient nor the dither moves, `third_combination` in
//! the runtime): an arrival that leaves a walk in it drifts out of the
//! band seconds later. Asserted: at most `MAX_UNSETTLED` runs unsettled
//! and the 90th percentile of the settle times (unsettled runs counted as
//! never) within `P90_BOUND_S`. Measured on these 240 runs: 3 unsettled,
//! median 2.06 s, 90th percentile 6.28 s (2, 2.08 s and 6.52 s before the
//! pooled gain; 4 unsettled and 6.36 s before the station keeping's
//! coordinate was taken across differing gains). Earlier: without leaving the hold once the walk has reached the band's
//! edge 6 unsettled, 90th percentile 6.96 s; without leaving it for the
//! walk at all 9 unsettled, median 1.98 s, 90th percentile 7.48 s. Printed: every run's conditions and
//! settle time.

use capsule_mpc_generator::config::{Config, DisturbanceKind};
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::DisturbanceLevel;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const RUNS: usize = 240;
const DRAW_SEED: u64 = 326;
const DURATION_S: f64 = 8.0;
const REACH_M: f64 = 0.03;
/// Most runs left unsettled at `DURATION_S`.
const MAX_UNSETTLED: usize = 5;
/// Bound on the 90th percentile of the settle times, s.
const P90_BOUND_S: f64 = 6.75;

/// One drawn run: what differs from the default options.
#[derive(Debug)]
struct Drawn {
    target_m: Vec<f64>,
    drag: Vec<f64>,
    gain: Vec<f64>,
    sampling: Sampling,
    drift: bool,
    seed: u64,
}

fn draw(rng: &mut ChaCha8Rng) -> Drawn {
    Drawn {
        target_m: (0..3).map(|_| rng.gen_range(-REACH_M..=REACH_M)).collect(),
        drag: (0..3).map(|_| rng.gen_range(0.8..=1.2)).collect(),
        gain: (0..3).map(|_| rng.gen_range(0.9..=1.1)).collect(),
        sampling: [Sampling::Constant, Sampling::Variable][rng.gen_range(0..2)],
        drift: rng.gen_bool(0.5),
        seed: rng.gen_range(1..=1000),
    }
}

fn settle_s(config: &Config, r: &Drawn) -> Option<f64> {
    let model = capsule_mpc_generator::model::Model::from_config(config);
    let target = r.target_m.iter().flat_map(|&p| [p, 0.0]).collect();
    let mut opts = RunOptions::new(config, target, r.sampling);
    opts.duration_s = DURATION_S;
    opts.seed = r.seed;
    let kind = if r.drift {
        DisturbanceKind::Drift
    } else {
        DisturbanceKind::Random
    };
    opts.disturbance = DisturbanceLevel::Paper.config_of_kind(&model, r.seed, kind);
    opts.mismatch = PlantMismatch {
        drag_scale: r.drag.clone(),
        gain_scale: r.gain.clone(),
    };
    run(config, &opts).unwrap().metrics.settle_time_s
}

#[test]
fn three_capsules_off_the_model_settle() {
    let config = Config::embedded_three_capsules();
    let mut rng = ChaCha8Rng::seed_from_u64(DRAW_SEED);
    let runs: Vec<Drawn> = (0..RUNS).map(|_| draw(&mut rng)).collect();
    let settles: Vec<Option<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = runs
            .chunks(RUNS / 2)
            .map(|chunk| {
                let config = &config;
                s.spawn(move || {
                    chunk
                        .iter()
                        .map(|r| settle_s(config, r))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    for (r, s) in runs.iter().zip(&settles) {
        println!(
            "{:?}: {}",
            r,
            s.map_or("never".to_string(), |t| format!("{t:.2} s"))
        );
    }
    let unsettled = settles.iter().filter(|s| s.is_none()).count();
    let mut times: Vec<f64> = settles.iter().map(|s| s.unwrap_or(f64::INFINITY)).collect();
    times.sort_by(f64::total_cmp);
    let median = times[RUNS / 2];
    let p90 = times[RUNS * 9 / 10];
    println!("{unsettled} of {RUNS} unsettled; median {median:.2} s, 90th percentile {p90:.2} s");
    assert!(
        unsettled <= MAX_UNSETTLED,
        "{unsettled} of {RUNS} unsettled"
    );
    assert!(p90 <= P90_BOUND_S, "90th percentile {p90:.2} s");
}
