//! The controller step of any compiled module (`bench --config FILE`):
//! the worst-case cycle of a config other than the embedded default (three
//! capsules), timed the way the default's controller-step rows are.
//!
//! States: the closed-loop states of ideal-sampling runs from rest to
//! [`CLOSED_LOOP_TARGETS`] targets of the module's capsule count, the rest
//! uniform over the kept cells of the module's own warm-start index (states
//! outside them go to the fallback, not to the solver). Each state is timed
//! cold (a fresh controller, target set, no plan) and warm (the step after,
//! from the state its first sample predicts), [`REPEATS`] passes, the
//! per-state minimum reported beside the single shots. The peers and the
//! two tiers' rows exist for the default module only.

use crate::bench::harness::{prototype, REPEATS};
use crate::bench::states::{sample_instants, uniform_in_kept_cells};
use crate::bench::timing::{
    fmt_us, pin_to_one_core, print_rows, timed, timer_overhead_ns, Percentiles,
};
use anyhow::{Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_runtime::controller::Sampling as RtSampling;
use capsule_mpc_runtime::solver::{PlanSolver, Tables};
use capsule_mpc_runtime::Controller;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use serde_json::{json, Value};
use std::hint::black_box;

/// Closed-loop runs that contribute states (ideal sampling, from rest).
pub const CLOSED_LOOP_TARGETS: usize = 4;
/// Each closed-loop run, s.
pub const CLOSED_LOOP_SECONDS: f64 = 3.0;
/// Target offsets of the closed-loop runs, m: capsule `i` of run `j` goes
/// to `TARGET_OFFSETS_M[(i + j) % 3]` (a spread, a shift and a mix).
const TARGET_OFFSETS_M: [f64; 3] = [0.02, -0.01, 0.0];
/// Untimed warm-up: states stepped before timing.
const WARM_UP_STATES: usize = 2000;

/// `n` relative states of the module (see the module docs).
fn sample_states<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    config: &Config,
    tables: &Tables,
    n: usize,
    seed: u64,
) -> Result<Vec<[f64; NX]>> {
    let m = NX / 2;
    let mut states = Vec::new();
    for j in 0..CLOSED_LOOP_TARGETS {
        let target: Vec<f64> = (0..m)
            .flat_map(|i| [TARGET_OFFSETS_M[(i + j) % TARGET_OFFSETS_M.len()], 0.0])
            .collect();
        let mut opts = RunOptions::new(config, target.clone(), Sampling::Ideal);
        opts.duration_s = CLOSED_LOOP_SECONDS;
        let report =
            run(config, &opts).with_context(|| format!("closed-loop run to {target:?} m"))?;
        states.extend(sample_instants::<NX>(
            &report.t,
            &report.x,
            &target,
            S::DT_S,
        ));
    }
    states.truncate(n);
    let rest = n - states.len();
    states.extend(uniform_in_kept_cells::<NX>(tables, rest, seed));
    Ok(states)
}

/// Cold and warm controller step from `e`, ns.
fn time_state<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    proto: &Controller<S, NX, K>,
    e: &[f64; NX],
) -> (u64, u64)
where
    Controller<S, NX, K>: Clone,
{
    let mut c = proto.clone();
    let (out, cold) = timed(|| black_box(&mut c).cycle_full_state(black_box(e)));
    let e1 = match out {
        Ok(out) => S::predict_plan(e, &out.gradients_t_per_m, 1),
        Err(_) => *e,
    };
    let (_, warm) = timed(|| black_box(&mut c).cycle_full_state(black_box(&e1)));
    (cold, warm)
}

/// Times module `S`'s controller step over `n` states under `sampling`,
/// prints the table and returns the JSON report.
pub fn measure<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    config: &Config,
    tables: &Tables,
    sampling: RtSampling,
    n: usize,
    seed: u64,
) -> Result<Value>
where
    Controller<S, NX, K>: Clone,
{
    let proto = prototype::<S, NX, K>(sampling)?;
    let states = sample_states::<S, NX, K>(config, tables, n, seed)?;
    let core = pin_to_one_core();
    let overhead = timer_overhead_ns();
    // Untimed warm-up pass over the first states.
    for e in states.iter().take(WARM_UP_STATES) {
        black_box(time_state(&proto, e));
    }
    let first: Vec<(u64, u64)> = states.iter().map(|e| time_state(&proto, e)).collect();
    let (mut cold_min, mut warm_min): (Vec<u64>, Vec<u64>) = first.iter().copied().unzip();
    for _ in 1..REPEATS {
        for (i, e) in states.iter().enumerate() {
            let (cold, warm) = time_state(&proto, e);
            cold_min[i] = cold_min[i].min(cold);
            warm_min[i] = warm_min[i].min(warm);
        }
    }
    let single =
        |f: fn(&(u64, u64)) -> u64| Percentiles::of(&first.iter().map(f).collect::<Vec<_>>());
    let rows = [
        ("controller step (warm)".to_string(), single(|t| t.1)),
        ("controller step (cold)".to_string(), single(|t| t.0)),
        (
            format!("controller step (warm), min of {REPEATS}"),
            Percentiles::of(&warm_min),
        ),
        (
            format!("controller step (cold), min of {REPEATS}"),
            Percentiles::of(&cold_min),
        ),
    ];
    crate::out!(
        "capsule-mpc bench: {} capsules, {} states, core {core:?}, timer overhead {overhead} ns (peers and tiers: the default module only)",
        NX / 2,
        states.len()
    )?;
    let json_rows: serde_json::Map<String, Value> = rows
        .iter()
        .map(|(name, p)| (name.clone(), p.json()))
        .collect();
    print_rows(rows)?;
    let worst = (0..states.len())
        .max_by_key(|&i| cold_min[i].max(warm_min[i]))
        .unwrap_or(0);
    crate::out!(
        "slowest state (min of {REPEATS}): e = {:?}: cold {}, warm {}",
        states[worst],
        fmt_us(cold_min[worst]),
        fmt_us(warm_min[worst])
    )?;
    Ok(json!({
        "capsules": NX / 2,
        "timer_overhead_ns": overhead,
        "controller_step_ns": Value::Object(json_rows),
    }))
}
