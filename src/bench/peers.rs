//! The peers on the warm case of the benchmark states: the reference loop
//! with each QP engine, and OpEn on the window problem; their statistics.

use crate::bench::clarabel_peer::ClarabelEngine;
use crate::bench::open_peer::OpenPeer;
#[cfg(feature = "peers-osqp")]
use crate::bench::osqp_peer::OsqpEngine;
use crate::bench::reference::{ActiveSetEngine, QpEngine, RefProblem, RefSolver};
use crate::bench::states::BenchState;
use crate::bench::timing::{fmt_us, timed, Percentiles};
use capsule_mpc_runtime::generated::controller::{spec, Solver};
use capsule_mpc_runtime::generated::{SolveReport, SolveStatus};
use capsule_mpc_runtime::solver::PlanSolver;
use serde_json::{json, Value};
use spec::{K, NX};

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
}

/// Runs every peer on `count` of the states (evenly spread); prints their
/// table and returns their JSON.
pub(crate) fn run_peers(states: &[BenchState], problem: &RefProblem, count: usize) -> Value {
    if count == 0 {
        return json!({});
    }
    let picks: Vec<usize> = (0..count).map(|i| i * states.len() / count).collect();
    let mut engines: Vec<Box<dyn QpEngine>> = vec![
        Box::new(ActiveSetEngine::default()),
        Box::new(ClarabelEngine),
    ];
    #[cfg(feature = "peers-osqp")]
    engines.push(Box::new(OsqpEngine::default()));
    let mut stats: Vec<PeerStats> = engines.iter().map(|_| PeerStats::default()).collect();
    let mut open_stats = PeerStats::default();
    let mut open = OpenPeer::new();
    let mut rs = RefSolver::new();
    let mut ref_vs_generated_u0: f64 = 0.0;
    let mut ref_vs_generated_cost: f64 = 0.0;
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
        let e1 = &t.e1;
        let start = t.start.as_ref();
        let mut first_du0_ref = 0.0;
        for (k, engine) in engines.iter_mut().enumerate() {
            let (out, ns) = timed(|| rs.refine(problem, engine.as_mut(), e1, start));
            let Some(out) = out else { continue };
            if n < warmup {
                continue;
            }
            let st = &mut stats[k];
            st.step_ns.push(ns);
            st.qp_ns.extend_from_slice(&out.qp_ns);
            st.max_iterations = st.max_iterations.max(out.max_qp_iterations);
            st.failures += out.qp_failures as u64;
            if k == 0 {
                first_du0_ref = out.first_du0;
                ref_vs_generated_u0 = ref_vs_generated_u0.max((out.plan[0] - t.plan[0]).abs());
                let c = t.report.cost;
                ref_vs_generated_cost =
                    ref_vs_generated_cost.max((out.cost - c).abs() / c.abs().max(1e-12));
            }
            st.max_abs_du = st.max_abs_du.max((out.first_du0 - first_du0_ref).abs());
            st.max_abs_u0 = st.max_abs_u0.max((out.plan[0] - t.plan[0]).abs());
            st.cost_gap
                .push((out.cost - t.report.cost) / t.report.cost.abs().max(1e-12));
        }
        let (out, ns) = timed(|| open.refine(problem, e1, start));
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
                open_stats
                    .cost_gap
                    .push((cost - t.report.cost) / t.report.cost.abs().max(1e-12));
            }
            None => open_stats.failures += 1,
        }
    }
    let ours_step = Percentiles::of(&stats[0].step_ns).median;
    let ours_qp = Percentiles::of(&stats[0].qp_ns).median;
    let mut out = serde_json::Map::new();
    println!(
        "peers on {} states (warm step, same state and start plan; times per refinement step = table check + {} SQP iterations; ratios vs the active-set engine in the same reference loop):",
        stats[0].step_ns.len(),
        spec::SQP_ITERATIONS
    );
    println!(
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
    );
    for (engine, st) in engines.iter().zip(&stats) {
        let j = st.json(ours_step, ours_qp);
        print_peer(engine.name(), &j);
        out.insert(engine.name().to_string(), j);
    }
    let j = open_stats.json(ours_step, ours_qp);
    print_peer("open", &j);
    out.insert("open".to_string(), j);
    #[cfg(not(feature = "peers-osqp"))]
    out.insert(
        "osqp".to_string(),
        json!({"skipped": "build with --features peers-osqp (needs cmake)"}),
    );
    println!(
        "reference loop (active-set) vs the generated solver: max |u0| difference {ref_vs_generated_u0:.3e} T/m, max relative cost difference {ref_vs_generated_cost:.3e}"
    );
    println!(
        "|du0|: first QP's step on u0 vs the active-set engine's (identical QP data); |u0|: first input after the step vs the generated solver's; open: no QP, |du0| = |u0|"
    );
    out.insert(
        "reference_check".to_string(),
        json!({"max_abs_u0_vs_generated": ref_vs_generated_u0, "max_rel_cost_vs_generated": ref_vs_generated_cost}),
    );
    Value::Object(out)
}

fn print_peer(name: &str, j: &Value) {
    let ns = |k: &str| j[k].as_u64().map_or("-".to_string(), fmt_us);
    let ratio = |k: &str| {
        j[k].as_f64()
            .map_or("-".to_string(), |r| format!("{r:.1}x"))
    };
    println!(
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
    );
}
