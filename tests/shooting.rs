//! The opt-in minimum-time shooting law (`ControllerSettings::shooting`)
//! off the 1 cm lattice the tables were solved on: two capsules, ideal
//! sampling, no disturbance, strict settle over the min-time bound.
//! Measured (docs/decisions.md): 1.1 cm grid median 1.07, worst 1.16
//! (1.17 / 2.78 without shots); 0.75 cm grid 1.02 / 1.39 (1.10 / 1.73).
//! Issue 26 asks for 1.15 at the median and 1.4 at worst.

use capsule_mpc_generator::config::Config;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};

/// Settle / bound over every target of a `step_m` grid within `range_m`
/// (both capsules, the start excluded), with or without shots.
fn ratios(step_m: f64, range_m: f64, shooting: bool) -> Vec<f64> {
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
            opts.shooting = Some(shooting);
            let m = run(&config, &opts).unwrap().metrics;
            out.push(m.settle_over_bound.unwrap_or(f64::INFINITY));
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

fn median(v: &[f64]) -> f64 {
    v[v.len() / 2]
}

#[test]
fn shots_settle_off_lattice_targets_near_minimum_time() {
    for (step_m, range_m) in [(0.011, 0.033), (0.0075, 0.0375)] {
        let with = ratios(step_m, range_m, true);
        let (m, worst) = (median(&with), *with.last().unwrap());
        println!("{step_m} m grid with shots: median {m:.3}, worst {worst:.3}");
        assert!(m <= 1.15, "{step_m} m grid: median {m}");
        assert!(worst <= 1.4, "{step_m} m grid: worst {worst}");
    }
}

/// Off by default: the refinement alone, whose worst case off the lattice
/// the shots remove (this is what the test above would catch if the
/// switch were ignored).
#[test]
fn without_shots_the_off_lattice_worst_case_is_the_refinements() {
    let without = ratios(0.011, 0.033, false);
    let worst = *without.last().unwrap();
    assert!(worst > 2.0, "1.1 cm grid without shots: worst {worst}");
}
