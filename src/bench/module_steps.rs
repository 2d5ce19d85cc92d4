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

use crate::bench::harness::REPEATS;
use crate::bench::timing::{fmt_us, pin_to_one_core, timed, timer_overhead_ns, Percentiles};
use anyhow::{Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_runtime::controller::Sampling as RtSampling;
use capsule_mpc_runtime::solver::lookup;
use capsule_mpc_runtime::solver::{PlanSolver, Tables};
use capsule_mpc_runtime::Controller;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};
use std::hint::black_box;

/// Closed-loop runs that contribute states (ideal sampling, from rest).
pub const CLOSED_LOOP_TARGETS: usize = 4;
/// Each closed-loop run, s.
pub const CLOSED_LOOP_SECONDS: f64 = 3.0;
/// Target offsets of the closed-loop runs, m: capsule `i` of run `j` goes
/// to `TARGET_OFFSETS_M[(i + j) % 3]` (a spread, a shift and a mix).
const TARGET_OFFSETS_M: [f64; 3] = [0.02, -0.01, 0.0];
/// Speed range of the uniformly drawn states, m/s (as the default's).
const SAMPLED_SPEED_M_PER_S: f64 = 0.3;

/// A controller of module `S` with the zero target set.
fn prototype<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    sampling: RtSampling,
) -> Result<Controller<S, NX, K>> {
    let mut settings = Controller::<S, NX, K>::default_settings();
    settings.sampling = sampling;
    let mut c = Controller::<S, NX, K>::new(settings, &vec![0.0; NX / 2])
        .map_err(|e| anyhow::anyhow!("controller: {e:?}"))?;
    c.set_target(&[0.0; NX])
        .map_err(|e| anyhow::anyhow!("set_target: {e:?}"))?;
    Ok(c)
}

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
        let mut last = None;
        for (t, x) in report.t.iter().zip(&report.x) {
            let dt_s = S::DT_S;
            let k = (t / dt_s).round();
            if (t - k * dt_s).abs() > 1e-9 || last == Some(k) {
                continue;
            }
            last = Some(k);
            let mut e = [0.0; NX];
            for (ej, (xj, tj)) in e.iter_mut().zip(x.iter().zip(&target)) {
                *ej = xj - tj;
            }
            states.push(e);
        }
    }
    states.truncate(n);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = tables.index_position_axis;
    let (p_lo, p_hi) = (axis.start, axis.start + (axis.count - 1) as f64 * axis.step);
    while states.len() < n {
        let mut e = [0.0; NX];
        for (j, ej) in e.iter_mut().enumerate() {
            *ej = if j % 2 == 0 {
                rng.gen_range(p_lo..=p_hi)
            } else {
                rng.gen_range(-SAMPLED_SPEED_M_PER_S..=SAMPLED_SPEED_M_PER_S)
            };
        }
        if lookup::index_cell(tables, &e).is_some() {
            states.push(e);
        }
    }
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
    for e in states.iter().take(2000) {
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
    let rows = [
        (
            "controller step (warm)",
            Percentiles::of(&first.iter().map(|t| t.1).collect::<Vec<_>>()),
        ),
        (
            "controller step (cold)",
            Percentiles::of(&first.iter().map(|t| t.0).collect::<Vec<_>>()),
        ),
        (
            "controller step (warm), min of 3",
            Percentiles::of(&warm_min),
        ),
        (
            "controller step (cold), min of 3",
            Percentiles::of(&cold_min),
        ),
    ];
    println!(
        "capsule-mpc bench: {} capsules, {} states, core {core:?}, timer overhead {overhead} ns (peers and tiers: the default module only)",
        NX / 2,
        states.len()
    );
    println!(
        "{:<36}{:>12}{:>12}{:>12}{:>12}",
        "single shot", "median", "p99", "p99.9", "max"
    );
    let mut json_rows = serde_json::Map::new();
    for (name, p) in &rows {
        println!(
            "{name:<36}{:>12}{:>12}{:>12}{:>12}",
            fmt_us(p.median),
            fmt_us(p.p99),
            fmt_us(p.p999),
            fmt_us(p.max)
        );
        json_rows.insert(name.to_string(), p.json());
    }
    let worst = (0..states.len())
        .max_by_key(|&i| cold_min[i].max(warm_min[i]))
        .unwrap_or(0);
    println!(
        "slowest state (min of 3): e = {:?}: cold {}, warm {}",
        states[worst],
        fmt_us(cold_min[worst]),
        fmt_us(warm_min[worst])
    );
    Ok(json!({
        "capsules": NX / 2,
        "timer_overhead_ns": overhead,
        "controller_step_ns": Value::Object(json_rows),
    }))
}
