//! The second move of a session against the first (docs/known-limits.md,
//! "Capsules that are not quite the model"): what the controller learns of
//! capsules off the model in one move, it keeps for the next.
//!
//! On a plant with drag and gain factors DRAG, GAIN (the controller keeps
//! the model and is told nothing), seeds 1-4, the paper's disturbance, from
//! rest at (2, -1) cm to every target of the 1 cm grid around it (+-4 cm,
//! within the +-5 cm workspace): the first move of a session starts there
//! at rest; the second arrives there from the origin first (3 s) and is
//! then given the same target. Prints the strict settle's median, 90th
//! percentile and worst of each (9 s: never), from the move's start, and
//! how many never settled.
//!
//!     cargo run --release -p capsule-mpc-sim --example second_move -- DRAG GAIN constant|variable
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::Model;
use capsule_mpc_sim::closed_loop::{run, Retarget, RunOptions, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::DisturbanceLevel;

const USAGE: &str = "usage: second_move DRAG GAIN constant|variable (DRAG, GAIN: the plant's factors, e.g. 1.2 1.0)";

/// The plant's factors and the sampling, or a one-line error naming the
/// argument.
fn parse_args(args: &[String]) -> Result<(f64, f64, Sampling), String> {
    let [drag, gain, sampling] = args else {
        return Err(USAGE.to_string());
    };
    let factor = |name: &str, v: &str| match v.parse::<f64>() {
        Ok(f) if f.is_finite() && f > 0.0 => Ok(f),
        _ => Err(format!("{name} {v:?} is not a positive factor; {USAGE}")),
    };
    let sampling = match sampling.as_str() {
        "constant" => Sampling::Constant,
        "variable" => Sampling::Variable,
        other => {
            return Err(format!(
                "sampling {other:?} is not constant or variable; {USAGE}"
            ))
        }
    };
    Ok((factor("DRAG", drag)?, factor("GAIN", gain)?, sampling))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (drag, gain, sampling) = parse_args(&args).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let first = [0.02, -0.01];
    let mut firsts = Vec::new();
    let mut seconds = Vec::new();
    for seed in 1..=4u64 {
        for a in -4..=4 {
            for b in -4..=4 {
                if a == 0 && b == 0 {
                    continue;
                }
                let (da, db) = (a as f64 / 100.0, b as f64 / 100.0);
                // First move of a session: from rest at `first` to first + d.
                let target2 = vec![first[0] + da, 0.0, first[1] + db, 0.0];
                if target2.iter().step_by(2).any(|p: &f64| p.abs() > 0.05) {
                    continue;
                }
                let mk = || {
                    let mut o = RunOptions::new(&config, target2.clone(), sampling);
                    o.seed = seed;
                    o.disturbance = DisturbanceLevel::Paper.config(&model, seed);
                    o.mismatch = PlantMismatch::uniform(drag, gain);
                    o
                };
                let mut o1 = mk();
                o1.start_m = first.to_vec();
                o1.duration_s = 4.0;
                let r1 = run(&config, &o1).unwrap();
                firsts.push(r1.metrics.settle_time_s.unwrap_or(9.0));
                // Second move: origin -> first (3 s), then -> first + d.
                let mut o2 = mk();
                o2.target = vec![first[0], 0.0, first[1], 0.0];
                o2.retarget = Some(Retarget {
                    at_s: 3.0,
                    target: target2.clone(),
                });
                o2.duration_s = 7.0;
                let r2 = run(&config, &o2).unwrap();
                seconds.push(r2.metrics.settle_time_s.map_or(9.0, |t| t - 3.0));
            }
        }
    }
    let never = |v: &[f64]| v.iter().filter(|&&t| t >= 9.0).count();
    let (never_first, never_second) = (never(&firsts), never(&seconds));
    let stat = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[v.len() * 9 / 10], v[v.len() - 1], v.len())
    };
    println!(
        "drag {drag} gain {gain} {:?}: first move (median, p90, worst, n) {:?}",
        sampling,
        stat(&mut firsts)
    );
    println!(
        "drag {drag} gain {gain} {:?}: second move                        {:?}",
        sampling,
        stat(&mut seconds)
    );
    println!(
        "drag {drag} gain {gain} {sampling:?}: never settled: first move {never_first}, second move {never_second}"
    );
}
