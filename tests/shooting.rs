//! The minimum-time shooting law (`ControllerSettings::shooting`, on by
//! default under ideal sampling) off the 1 cm lattice the tables were
//! solved on, and on capsules off the model: two capsules, ideal sampling,
//! strict settle over the min-time bound. Measured (docs/results.md):
//! 1.1 cm grid median 1.08, worst 1.16 (1.17 / 2.78 without shots);
//! 0.75 cm grid 1.03 / 1.39 (1.10 / 1.73). Issue 26 asks for 1.15 at the
//! median and 1.4 at worst.

use capsule_mpc_generator::config::Config;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;

/// Settle / bound over every target of a `step_m` grid within `range_m`
/// (both capsules, the start excluded), with or without shots (None: the
/// default), on the model.
fn ratios(step_m: f64, range_m: f64, shooting: Option<bool>) -> Vec<f64> {
    grid_runs(step_m, range_m, shooting, &PlantMismatch::uniform(1.0, 1.0))
        .into_iter()
        .map(|(ratio, _)| ratio)
        .collect()
}

/// (settle / bound, settle time s) over a grid as in `ratios`, sorted by
/// the ratio, on `plant` (never settled: infinite), 3 s runs.
fn grid_runs(
    step_m: f64,
    range_m: f64,
    shooting: Option<bool>,
    plant: &PlantMismatch,
) -> Vec<(f64, f64)> {
    let config = Config::embedded_default();
    let n = (range_m / step_m).round() as i64;
    let mut out = Vec::new();
    for i in -n..=n {
        for j in -n..=n {
            if i == 0 && j == 0 {
                continue;
            }
            let target = [i as f64 * step_m, 0.0, j as f64 * step_m, 0.0];
            let mut opts = RunOptions::new(&config, target.to_vec(), Sampling::Ideal);
            opts.duration_s = 3.0;
            opts.shooting = shooting;
            opts.mismatch = plant.clone();
            let m = run(&config, &opts).unwrap().metrics;
            out.push((
                m.settle_over_bound.unwrap_or(f64::INFINITY),
                m.settle_time_s.unwrap_or(f64::INFINITY),
            ));
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

fn median(v: &[f64]) -> f64 {
    v[v.len() / 2]
}

/// Runs the 1 cm grid over +-3 cm under ideal sampling on each plant
/// (drag factors, gain factors) and asserts its median ratio to the
/// model's minimum time and its worst settle.
fn plants_settle_on_the_grid(
    plants: impl IntoIterator<Item = (Vec<f64>, Vec<f64>)>,
    max_median_ratio: f64,
    max_worst_s: f64,
) {
    for (drag_scale, gain_scale) in plants {
        let plant = PlantMismatch {
            drag_scale,
            gain_scale,
        };
        let runs = grid_runs(0.01, 0.03, None, &plant);
        let m = runs[runs.len() / 2].0;
        let worst_s = runs.iter().map(|r| r.1).fold(0.0, f64::max);
        println!("{plant:?}: median ratio {m:.3}, worst settle {worst_s:.3} s");
        assert!(m <= max_median_ratio, "{plant:?}: median ratio {m}");
        assert!(
            worst_s <= max_worst_s,
            "{plant:?}: worst settle {worst_s} s"
        );
    }
}

#[test]
fn shots_settle_off_lattice_targets_near_minimum_time() {
    for (step_m, range_m) in [(0.011, 0.033), (0.0075, 0.0375)] {
        let with = ratios(step_m, range_m, None);
        let (m, worst) = (median(&with), *with.last().unwrap());
        println!("{step_m} m grid, default (shots): median {m:.3}, worst {worst:.3}");
        assert!(m <= 1.15, "{step_m} m grid: median {m}");
        assert!(worst <= 1.4, "{step_m} m grid: worst {worst}");
    }
}

/// Switched off: the refinement alone, whose worst case off the lattice
/// the shots remove (this is what the test above would catch if the
/// default were not the shots).
#[test]
fn without_shots_the_off_lattice_worst_case_is_the_refinements() {
    let without = ratios(0.011, 0.033, Some(false));
    let worst = *without.last().unwrap();
    assert!(worst > 2.0, "1.1 cm grid without shots: worst {worst}");
}

/// Capsules off the model under ideal sampling: the factors are learned
/// from the full state and the shots aim on them. Every target of the 1 cm
/// grid over +-3 cm on seven plants settles within 2.2 s, at a median
/// within 1.2x the model's minimum time (measured over +-4 cm: medians
/// 0.97-1.19, worst settle 2.00 s; docs/results.md). Without the learning
/// drag x0.8's median is 1.24.
#[test]
fn capsules_off_the_model_settle_near_minimum_time_under_ideal_sampling() {
    let plants = [
        (vec![0.8], vec![1.0]),
        (vec![1.2], vec![1.0]),
        (vec![1.2, 0.8], vec![1.0]),
        (vec![0.8, 1.2], vec![1.0]),
        (vec![1.0], vec![0.9]),
        (vec![1.0], vec![1.1]),
        (vec![1.0], vec![0.9, 1.1]),
    ];
    plants_settle_on_the_grid(plants, 1.2, 2.2);
}

/// Capsules farther off than the controller is told (gain 10 %, drag 20 %
/// at one deviation) under ideal sampling: every full state still teaches
/// the factors, and the hold's station keeping takes its coordinate
/// across gains that differ, so every target of the 1 cm grid over +-3 cm
/// settles within 2 s (measured: worst 1.66 s, medians 0.86-1.27 of the
/// model's minimum time; when such steps were rejected, 54 of the first
/// four plants' 192 targets never settled, and with the drag direction
/// alone the last plant's worst was 4.43 s: docs/decisions.md).
#[test]
fn capsules_beyond_their_told_uncertainty_settle_under_ideal_sampling() {
    let plants = [
        (vec![1.04, 0.95], vec![1.0, 0.81]),
        (vec![0.7], vec![1.2]),
        (vec![1.3], vec![0.85, 1.15]),
        (vec![1.3, 0.7], vec![0.8]),
        (vec![0.7], vec![1.15, 0.85]),
    ];
    plants_settle_on_the_grid(plants, 1.35, 2.0);
}
