//! The peers on the warm case of the benchmark states: the generated
//! solver with each QP engine (wrapped in [`Timed`]), and OpEn on the
//! window problem; their statistics.

use crate::bench::clarabel_peer::ClarabelEngine;
use crate::bench::engine::{QpCall, Timed};
use crate::bench::open_peer::OpenPeer;
#[cfg(feature = "peers-osqp")]
use crate::bench::osqp_peer::OsqpEngine;
use crate::bench::reference::RefProblem;
use crate::bench::states::BenchState;
use crate::bench::timing::{fmt_us, timed, Percentiles};
use capsule_mpc_runtime::generated::controller::{spec, Solver, Spec};
use capsule_mpc_runtime::generated::{SolveReport, SolveStatus};
use capsule_mpc_runtime::solver::qp::{ActiveSet, QpEngine};
use capsule_mpc_runtime::solver::PlanSolver;
use serde_json::{json, Value};
use spec::{K, M, N, NX};
use std::hint::black_box;

/// The generated module's solver with the QP engine `E`, timed.
pub type PeerSolver<E> = capsule_mpc_runtime::solver::Solver<Spec, M, NX, N, K, Timed<E>>;

/// The warm case of one state, for the peers: the predicted next state, the
/// plan the warm solve starts from (the cold plan shifted by one; None when
/// the cold solve was out of range) and the generated solver's result.
#[derive(Debug, Clone, Copy)]
pub struct WarmCase {
    pub e1: [f64; NX],
    pub start: Option<[f64; K]>,
    pub plan: [f64; K],
    pub report: SolveReport,
}

impl WarmCase {
    pub fn new(e: &[f64; NX]) -> WarmCase {
        let mut s = Solver::new();
        let cold = s.solve(e);
        let e1 = Solver::predict_plan(e, s.plan(), 1);
        s.shift(1);
        let start = (cold.status != SolveStatus::OutOfRange).then(|| *s.plan());
        let report = s.solve(&e1);
        WarmCase {
            e1,
            start,
            plan: *s.plan(),
            report,
        }
    }
}

/// One engine's warm step: what `Solver::solve` returned, its time and
/// the engine's record of the QPs.
#[derive(Debug, Clone)]
pub struct WarmRun {
    pub e1: [f64; NX],
    pub plan: [f64; K],
    pub report: SolveReport,
    pub step_ns: u64,
    pub calls: Vec<QpCall>,
    /// The first QP's step on the first input (the same QP for every engine).
    pub first_du0: Option<f64>,
}

/// A [`PeerSolver`] behind a name, so that engines of different types run
/// side by side.
pub trait WarmPeer {
    fn name(&self) -> &'static str;
    /// The warm case from `e` as [`WarmCase::new`] builds it, the cold
    /// solve with the active-set method and the timed warm solve with this
    /// peer's engine.
    fn warm_step(&mut self, e: &[f64; NX]) -> WarmRun;
}

/// `E` in the generated solver, one solver reused over the states (reset
/// before each), so that an engine with a workspace (OSQP) keeps it.
pub struct EnginePeer<E> {
    name: &'static str,
    solver: Box<PeerSolver<E>>,
}

impl<E: QpEngine<N>> EnginePeer<E> {
    pub fn new(name: &'static str, engine: E) -> EnginePeer<E> {
        EnginePeer {
            name,
            solver: Box::new(PeerSolver::with_engine(Timed::new(engine))),
        }
    }
}

impl<E: QpEngine<N>> WarmPeer for EnginePeer<E> {
    fn name(&self) -> &'static str {
        self.name
    }

    fn warm_step(&mut self, e: &[f64; NX]) -> WarmRun {
        let s = &mut *self.solver;
        s.reset();
        s.engine().disarm();
        s.solve(e);
        let e1 = Solver::predict_plan(e, s.plan(), 1);
        s.shift(1);
        s.engine().arm();
        let (report, step_ns) = timed(|| black_box(&mut *s).solve(black_box(&e1)));
        s.engine().disarm();
        WarmRun {
            e1,
            plan: *s.plan(),
            report,
            step_ns,
            calls: s.engine().calls().to_vec(),
            first_du0: s.engine().first_step(),
        }
    }
}

/// The engines timed in the generated solver: the active-set method first
/// (the reference of the ratios), then clarabel and, with feature
/// `peers-osqp`, OSQP.
pub fn engine_peers() -> Vec<Box<dyn WarmPeer>> {
    vec![
        Box::new(EnginePeer::new("active-set", ActiveSet)),
        Box::new(EnginePeer::new("clarabel", ClarabelEngine)),
        #[cfg(feature = "peers-osqp")]
        Box::new(EnginePeer::new("osqp", OsqpEngine::default())),
    ]
}

/// Whether a run reproduces the plain solver's warm case bit for bit
/// (predicted state, plan, cost and status).
pub fn same_bits(run: &WarmRun, case: &WarmCase) -> bool {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    bits(&run.e1) == bits(&case.e1)
        && bits(&run.plan) == bits(&case.plan)
        && run.report.cost.to_bits() == case.report.cost.to_bits()
        && run.report.status == case.report.status
}

/// Figures of one peer over the peer states.
#[derive(Debug, Default)]
struct PeerStats {
    step_ns: Vec<u64>,
    qp_ns: Vec<u64>,
    max_iterations: u32,
    failures: u64,
    max_abs_du: f64,
    max_abs_u0: f64,
    /// (peer cost - generated cost) / generated cost, per state.
    cost_gap: Vec<f64>,
    not_converged: u64,
}

impl PeerStats {
    fn json(&self, ours_step_median: u64, ours_qp_median: u64) -> Value {
        let s = Percentiles::of(&self.step_ns);
        let q = Percentiles::of(&self.qp_ns);
        let mut gaps = self.cost_gap.clone();
        gaps.sort_by(f64::total_cmp);
        let gap_median = gaps.get(gaps.len() / 2).copied().unwrap_or(0.0);
        let lower = self.cost_gap.iter().filter(|&&g| g < -1e-9).count();
        json!({
            "median_ns": s.median,
            "p99_ns": s.p99,
            "max_ns": s.max,
            "ratio_median": s.median as f64 / ours_step_median.max(1) as f64,
            "qp_median_ns": (!self.qp_ns.is_empty()).then_some(q.median),
            "qp_max_ns": (!self.qp_ns.is_empty()).then_some(q.max),
            "qp_ratio_median": (!self.qp_ns.is_empty()).then(|| q.median as f64 / ours_qp_median.max(1) as f64),
            "max_iterations": self.max_iterations,
            "failures": self.failures,
            "not_converged": self.not_converged,
            "max_abs_du": self.max_abs_du,
            "max_abs_u0": self.max_abs_u0,
            "cost_gap_median": gap_median,
            "states_with_lower_cost": lower,
            "states": self.step_ns.len(),
        })
    }

    fn cost_gap(&mut self, cost: f64, case: &WarmCase) {
        let c = case.report.cost;
        self.cost_gap.push((cost - c) / c.abs().max(1e-12));
    }
}

/// The active-set row against the plain generated solver.
#[derive(Debug, Default)]
struct Check {
    compared: u64,
    differing: u64,
    max_abs_u0: f64,
    max_rel_cost: f64,
}

/// Runs every peer on `count` of the states (evenly spread); prints their
/// table and returns their JSON. `problem` (the config's constants) only
/// enters the check's report.
pub(crate) fn run_peers(
    states: &[BenchState],
    problem: &RefProblem,
    count: usize,
) -> std::io::Result<Value> {
    if count == 0 {
        return Ok(json!({}));
    }
    let picks: Vec<usize> = (0..count).map(|i| i * states.len() / count).collect();
    let mut engines = engine_peers();
    let mut stats: Vec<PeerStats> = engines.iter().map(|_| PeerStats::default()).collect();
    let mut open_stats = PeerStats::default();
    let mut open = OpenPeer::new();
    let mut check = Check::default();
    eprintln!(
        "bench: peers ({}, open) on {count} of the states",
        engines
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let warmup = 20.min(count);
    for (n, &i) in picks.iter().enumerate() {
        let t = WarmCase::new(&states[i].e);
        let mut first_du0_ref = 0.0;
        for (k, engine) in engines.iter_mut().enumerate() {
            let run = engine.warm_step(&states[i].e);
            if k == 0 {
                check.compared += 1;
                if !same_bits(&run, &t) {
                    check.differing += 1;
                }
                check.max_abs_u0 = check.max_abs_u0.max((run.plan[0] - t.plan[0]).abs());
                let c = t.report.cost;
                if run.report.cost != c {
                    check.max_rel_cost = check
                        .max_rel_cost
                        .max((run.report.cost - c).abs() / c.abs().max(1e-12));
                }
                first_du0_ref = run.first_du0.unwrap_or(0.0);
            }
            if n < warmup || run.report.status == SolveStatus::OutOfRange {
                continue;
            }
            let st = &mut stats[k];
            st.step_ns.push(run.step_ns);
            st.qp_ns.extend(run.calls.iter().map(|c| c.ns));
            for c in &run.calls {
                st.max_iterations = st.max_iterations.max(c.iterations);
                if !c.converged {
                    st.failures += 1;
                }
            }
            let du0 = run.first_du0.unwrap_or(0.0);
            st.max_abs_du = st.max_abs_du.max((du0 - first_du0_ref).abs());
            st.max_abs_u0 = st.max_abs_u0.max((run.plan[0] - t.plan[0]).abs());
            st.cost_gap(run.report.cost, &t);
        }
        let (out, ns) = timed(|| open.refine(&t.e1, t.start.as_ref()));
        if n < warmup {
            continue;
        }
        match out {
            Some((plan, cost, iters, converged)) => {
                open_stats.step_ns.push(ns);
                open_stats.max_iterations = open_stats.max_iterations.max(iters as u32);
                if !converged {
                    open_stats.not_converged += 1;
                }
                open_stats.max_abs_u0 = open_stats.max_abs_u0.max((plan[0] - t.plan[0]).abs());
                open_stats.max_abs_du = open_stats.max_abs_u0;
                open_stats.cost_gap(cost, &t);
            }
            None => open_stats.failures += 1,
        }
    }
    let ours_step = Percentiles::of(&stats[0].step_ns).median;
    let ours_qp = Percentiles::of(&stats[0].qp_ns).median;
    let mut out = serde_json::Map::new();
    crate::out!(
        "peers on {} states (warm step, same state and start plan; times per Solver::solve = table check + {} SQP iterations of the generated solver, each engine wrapped alike; ratios vs the active-set engine):",
        stats[0].step_ns.len(),
        spec::SQP_ITERATIONS
    )?;
    crate::out!(
        "{:<12} {:>11} {:>11} {:>11} {:>7} {:>11} {:>11} {:>7} {:>11} {:>11} {:>6}",
        "",
        "step med",
        "step p99",
        "step max",
        "ratio",
        "QP med",
        "QP max",
        "ratio",
        "|du0| max",
        "|u0| max",
        "iters"
    )?;
    for (engine, st) in engines.iter().zip(&stats) {
        let j = st.json(ours_step, ours_qp);
        print_peer(engine.name(), &j)?;
        out.insert(engine.name().to_string(), j);
    }
    let j = open_stats.json(ours_step, ours_qp);
    print_peer("open", &j)?;
    out.insert("open".to_string(), j);
    #[cfg(not(feature = "peers-osqp"))]
    out.insert(
        "osqp".to_string(),
        json!({"skipped": "build with --features peers-osqp (needs cmake)"}),
    );
    let identical = check.differing == 0;
    crate::out!(
        "active-set engine (wrapped) vs the plain generated solver: {} of {} warm steps bit for bit identical (max |u0| difference {:.3e} T/m, max relative cost difference {:.3e})",
        check.compared - check.differing,
        check.compared,
        check.max_abs_u0,
        check.max_rel_cost
    )?;
    crate::out!(
        "|du0|: first QP's step on u0 vs the active-set engine's (identical QP data); |u0|: first input after the step vs the generated solver's; open: no QP, |du0| = |u0|"
    )?;
    out.insert(
        "reference_check".to_string(),
        json!({
            "plans_bit_identical": identical,
            "states_compared": check.compared,
            "states_differing": check.differing,
            "max_abs_u0_vs_generated": check.max_abs_u0,
            "max_rel_cost_vs_generated": check.max_rel_cost,
            "config_vs_spec_max_rel": problem.spec_mismatch(),
            "what": "the generated solver with the wrapped active-set engine (the peers' reference row) against the plain Solver on the same warm cases: predicted state, plan, cost and status compared bit for bit",
        }),
    );
    Ok(Value::Object(out))
}

fn print_peer(name: &str, j: &Value) -> std::io::Result<()> {
    let ns = |k: &str| j[k].as_u64().map_or("-".to_string(), fmt_us);
    let ratio = |k: &str| {
        j[k].as_f64()
            .map_or("-".to_string(), |r| format!("{r:.1}x"))
    };
    crate::out!(
        "{name:<12} {:>11} {:>11} {:>11} {:>7} {:>11} {:>11} {:>7} {:>11.2e} {:>11.2e} {:>6}",
        ns("median_ns"),
        ns("p99_ns"),
        ns("max_ns"),
        ratio("ratio_median"),
        ns("qp_median_ns"),
        ns("qp_max_ns"),
        ratio("qp_ratio_median"),
        j["max_abs_du"].as_f64().unwrap_or(0.0),
        j["max_abs_u0"].as_f64().unwrap_or(0.0),
        j["max_iterations"]
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// States at rest, moving, near the target and out of range.
    const STATES: [[f64; NX]; 6] = [
        [0.02, 0.0, -0.01, 0.0],
        [-0.03, 0.1, 0.02, -0.2],
        [-0.012, 0.12, 0.006, 0.05],
        [0.031, -0.21, -0.044, 0.17],
        [0.0005, 0.0, -0.0003, 0.0],
        [0.5, 0.0, -0.5, 0.0],
    ];

    #[test]
    fn wrapped_active_set_reproduces_the_plain_solver_bit_for_bit() {
        let mut peer = EnginePeer::new("active-set", ActiveSet);
        // Twice over: the reused, reset solver is a fresh one.
        for e in STATES.iter().chain(&STATES) {
            let case = WarmCase::new(e);
            let run = peer.warm_step(e);
            assert!(same_bits(&run, &case), "{e:?}: {run:?} vs {case:?}");
            if run.report.status != SolveStatus::OutOfRange {
                assert_eq!(run.calls.len(), spec::SQP_ITERATIONS, "{e:?}");
                assert!(run.first_du0.is_some());
            }
        }
    }

    #[test]
    fn clarabel_in_the_solver_starts_from_the_same_qp() {
        let mut ours = EnginePeer::new("active-set", ActiveSet);
        let mut clarabel = EnginePeer::new("clarabel", ClarabelEngine);
        for e in &STATES[..4] {
            let (a, c) = (ours.warm_step(e), clarabel.warm_step(e));
            assert_eq!(a.e1, c.e1);
            assert_eq!(c.calls.len(), spec::SQP_ITERATIONS);
            let (da, dc) = (a.first_du0.unwrap(), c.first_du0.unwrap());
            assert!((da - dc).abs() < 1e-2, "{e:?}: {da} vs {dc}");
            assert!((a.plan[0] - c.plan[0]).abs() < 1e-2, "{e:?}");
        }
    }
}
