//! The timed runs of the generated controller step and solver over the
//! benchmark states, and the tables `capsule-mpc bench` prints.

use crate::bench::peers::run_peers;
use crate::bench::reference::RefProblem;
use crate::bench::states::BenchState;
use crate::bench::tiers::measure_tiers;
use crate::bench::timing::{pin_to_one_core, print_rows, timed, timer_overhead_ns, Percentiles};
use anyhow::Result;
use capsule_mpc_runtime::controller::Sampling as RtSampling;
use capsule_mpc_runtime::generated::controller::{spec, Solver};
use capsule_mpc_runtime::generated::{qp_iteration_map, SolveReport, SolveStatus};
use capsule_mpc_runtime::solver::PlanSolver;
use capsule_mpc_runtime::{Controller, DefaultController};
use serde_json::{json, Value};
use spec::NX;
use std::collections::BTreeMap;
use std::hint::black_box;
use std::time::Instant;

/// Timing passes over all states; the per-state minimum is reported beside
/// the single-shot (first pass) distribution.
pub const REPEATS: usize = 3;

/// Timings and figures of one state (ns).
#[derive(Debug, Clone, Copy)]
pub struct StateTiming {
    pub step_cold: u64,
    pub step_warm: u64,
    pub solver_cold: u64,
    pub solver_warm: u64,
    pub cold: SolveReport,
    pub warm: SolveReport,
    /// The QP iteration map's entries for the cold and the warm state.
    pub cold_map: u32,
    pub warm_map: u32,
}

/// A controller with the zero target set (states are then relative states),
/// ideal sampling.
pub fn prototype_controller() -> Result<DefaultController> {
    prototype_controller_with(RtSampling::Ideal)
}

/// A controller with the zero target set and the given sampling mode.
pub fn prototype_controller_with(sampling: RtSampling) -> Result<DefaultController> {
    prototype(sampling)
}

/// A controller of any compiled module `S` with the zero target set and
/// the given sampling mode.
pub fn prototype<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    sampling: RtSampling,
) -> Result<Controller<S, NX, K>> {
    let mut settings = Controller::<S, NX, K>::default_settings();
    settings.sampling = sampling;
    let mut c = Controller::<S, NX, K>::new(settings, &[0.0; NX][..NX / 2])
        .map_err(|e| anyhow::anyhow!("controller: {e:?}"))?;
    c.set_target(&[0.0; NX])
        .map_err(|e| anyhow::anyhow!("set_target: {e:?}"))?;
    Ok(c)
}

/// Times the cold and warm controller step and solver solve from `e`.
pub fn time_state(proto: &DefaultController, e: &[f64; NX]) -> StateTiming {
    // Solver only.
    let mut s = Solver::new();
    let settings = proto.settings();
    let (samples, coast_s) = settings.schedule(settings.max_actuation_samples);
    s.set_schedule(samples, coast_s);
    let (cold, solver_cold) = timed(|| black_box(&mut s).solve(black_box(e)));
    let e1 = Solver::predict_plan(e, s.plan(), 1);
    s.shift(1);
    let (warm, solver_warm) = timed(|| black_box(&mut s).solve(black_box(&e1)));
    // Controller step.
    let mut c = proto.clone();
    let (_, step_cold) = timed(|| black_box(&mut c).cycle_full_state(black_box(e)));
    let (_, step_warm) = timed(|| black_box(&mut c).cycle_full_state(black_box(&e1)));
    StateTiming {
        step_cold,
        step_warm,
        solver_cold,
        solver_warm,
        cold,
        warm,
        cold_map: Solver::qp_iterations_measured(e),
        warm_map: Solver::qp_iterations_measured(&e1),
    }
}

/// Times every state (after a warm-up), prints the tables and runs the
/// peers on `peer_count` of the states; returns the JSON report.
pub fn measure(
    states: &[BenchState],
    proto: &DefaultController,
    problem: &RefProblem,
    peer_count: usize,
) -> Result<Value> {
    let core = pin_to_one_core();
    let overhead = timer_overhead_ns();
    // Warm-up: at least 2000 states or 0.5 s, untimed.
    let t0 = Instant::now();
    let mut i = 0;
    while i < 2000 || t0.elapsed().as_secs_f64() < 0.5 {
        black_box(time_state(proto, &states[i % states.len()].e));
        i += 1;
        if t0.elapsed().as_secs_f64() > 3.0 {
            break;
        }
    }
    eprintln!("bench: timing {} states on core {core:?}", states.len());
    let timings: Vec<StateTiming> = states.iter().map(|s| time_state(proto, &s.e)).collect();
    let col = |f: fn(&StateTiming) -> u64| timings.iter().map(f).collect::<Vec<u64>>();
    let step_warm = Percentiles::of(&col(|t| t.step_warm));
    let step_cold = Percentiles::of(&col(|t| t.step_cold));
    let solver_warm = Percentiles::of(&col(|t| t.solver_warm));
    let solver_cold = Percentiles::of(&col(|t| t.solver_cold));
    // Per-state minimum over REPEATS passes: the state's own cost, without
    // preemption by the OS (which the single-shot tail includes).
    let mut min_of = [
        col(|t| t.step_warm),
        col(|t| t.step_cold),
        col(|t| t.solver_warm),
        col(|t| t.solver_cold),
    ];
    for _ in 1..REPEATS {
        for (i, s) in states.iter().enumerate() {
            let t = time_state(proto, &s.e);
            for (m, v) in
                min_of
                    .iter_mut()
                    .zip([t.step_warm, t.step_cold, t.solver_warm, t.solver_cold])
            {
                m[i] = m[i].min(v);
            }
        }
    }
    let min_p = min_of.each_ref().map(|v| Percentiles::of(v));
    // Iterations over every timed solve (cold and warm, solver only).
    let mut hist: BTreeMap<u32, u64> = BTreeMap::new();
    let mut max_iter = 0;
    let mut statuses: BTreeMap<&'static str, u64> = BTreeMap::new();
    // Solves above their cell's offline-measured count (the runtime flags
    // these), and solves in cells the map has no count for.
    let (mut above_map, mut unmapped) = (0u64, 0u64);
    for t in &timings {
        for (r, map) in [(t.cold, t.cold_map), (t.warm, t.warm_map)] {
            if map == 0 {
                unmapped += 1;
            } else if r.max_qp_iterations > map {
                above_map += 1;
            }
            *hist.entry(r.max_qp_iterations).or_default() += 1;
            max_iter = max_iter.max(r.max_qp_iterations);
            let name = match r.status {
                SolveStatus::Refined => "refined",
                SolveStatus::OutOfRange => "out_of_range",
                SolveStatus::IterationLimit => "iteration_limit",
            };
            *statuses.entry(name).or_default() += 1;
        }
    }
    // Five worst states by the warm controller step, re-timed 101 times.
    let mut order: Vec<usize> = (0..timings.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(timings[i].step_warm.max(timings[i].step_cold)));
    let worst: Vec<Value> = order
        .iter()
        .take(5)
        .map(|&i| {
            let t = &timings[i];
            let retimed: Vec<u64> = (0..101)
                .map(|_| time_state(proto, &states[i].e).step_warm)
                .collect();
            let retimed_cold: Vec<u64> = (0..101)
                .map(|_| time_state(proto, &states[i].e).step_cold)
                .collect();
            json!({
                "index": i,
                "origin": states[i].origin.name(),
                "e": states[i].e,
                "step_cold_ns": t.step_cold,
                "step_warm_ns": t.step_warm,
                "solver_cold_ns": t.solver_cold,
                "solver_warm_ns": t.solver_warm,
                "retimed_step_warm_median_ns": Percentiles::of(&retimed).median,
                "retimed_step_cold_median_ns": Percentiles::of(&retimed_cold).median,
                "max_qp_iterations": t.cold.max_qp_iterations.max(t.warm.max_qp_iterations),
                "status_warm": format!("{:?}", t.warm.status),
            })
        })
        .collect();
    let mut origins: BTreeMap<&'static str, u64> = BTreeMap::new();
    for s in states {
        *origins.entry(s.origin.name()).or_default() += 1;
    }

    crate::out!(
        "capsule-mpc bench: {} states ({origins:?}), core {core:?}, timer overhead {overhead} ns",
        states.len()
    )?;
    let names = [
        "controller step (warm)",
        "controller step (cold)",
        "solver only (warm)",
        "solver only (cold)",
    ];
    let rows = names
        .iter()
        .map(|n| n.to_string())
        .zip([step_warm, step_cold, solver_warm, solver_cold])
        .chain(
            names
                .iter()
                .map(|n| format!("{n}, min of {REPEATS}"))
                .zip(min_p),
        );
    print_rows(rows)?;
    crate::out!("QP iterations (max per QP, per solve): max {max_iter}, histogram {hist:?}; statuses {statuses:?}")?;
    crate::out!(
        "QP iteration map (offline, per index cell; largest entry {}): {above_map} of {} solves above their cell's count, {unmapped} in cells without one",
        qp_iteration_map::CONTROLLER_MAX,
        2 * timings.len()
    )?;
    crate::out!("worst states (by max of cold/warm controller step; re-timed medians show whether the max was noise):")?;
    for w in &worst {
        crate::out!(
            "  #{} {} e = {:?}: cold {} ns, warm {} ns, re-timed median cold {} ns, warm {} ns, {} QP iterations",
            w["index"],
            w["origin"].as_str().unwrap_or(""),
            states[w["index"].as_u64().unwrap_or(0) as usize].e,
            w["step_cold_ns"],
            w["step_warm_ns"],
            w["retimed_step_cold_median_ns"],
            w["retimed_step_warm_median_ns"],
            w["max_qp_iterations"]
        )?;
    }

    let peers = run_peers(states, problem, peer_count)?;
    let tiers = measure_tiers(states, peer_count.max(1000))?;

    Ok(json!({
        "step_ns": step_warm.json(),
        "step_cold_ns": step_cold.json(),
        "solver_ns": solver_warm.json(),
        "solver_cold_ns": solver_cold.json(),
        "min_of_repeats": {
            "repeats": REPEATS,
            "step_ns": min_p[0].json(),
            "step_cold_ns": min_p[1].json(),
            "solver_ns": min_p[2].json(),
            "solver_cold_ns": min_p[3].json(),
        },
        "iterations": {
            "max": max_iter,
            "histogram": hist.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "qp_max_iterations_bound": spec::QP_MAX_ITERATIONS,
            "offline_map": {
                "measured": qp_iteration_map::MEASURED,
                "largest_cell_count": qp_iteration_map::CONTROLLER_MAX,
                "solves_above_cell_count": above_map,
                "solves_in_unmapped_cells": unmapped,
            },
            "statuses": statuses,
        },
        "worst_states": worst,
        "peers": peers,
        "tiers": tiers,
        "allocations_per_step": 0,
        "allocations_source": "tests/alloc_free.rs (counting global allocator over set_target, cycle_full_state and cycle along closed-loop runs)",
        "workspace_bytes": std::mem::size_of::<DefaultController>(),
        "solver_bytes": std::mem::size_of::<Solver>(),
        "table_bytes": spec::TABLE_FILE.len(),
        "timer_overhead_ns": overhead,
        "pinned_core": core,
        "origins": origins,
        "what_is_timed": "step_ns/solver_ns: the warm step (solve from the predicted next state after shift(1) of the plan of a first solve); *_cold_ns: that first solve of a fresh controller/solver. Per-call Instant timing, one pinned thread, after warm-up.",
    }))
}
