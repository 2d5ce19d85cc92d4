//! The two solver tiers timed separately on the benchmark states, the
//! explicit tier's QP against the peers on the same QP data, and its
//! measured QP iterations against the certified operation bound.
//!
//! Per state `e`: a first explicit step from `e` (untimed) whose plan is
//! adopted and applied for one sample, then, from the predicted next state
//! `e1`, the timed calls the closed loop makes: **explicit** =
//! `Solver::solve_explicit(e1)` (look-up, deviation, gradient, warm-started
//! box QP, clamp); **refined** = the same explicit step followed by the
//! refinement `Solver::solve(e1)` (the SQP weighing the explicit plan by
//! its true cost), i.e. what a cycle with `refine = once` costs in the
//! solver. Min of `REPEATS` passes per state, one pinned thread. Each pass
//! sweeps every state, so these are cold-cache times (5.9 MB of explicit
//! data); **explicit in the loop** times the same step right after its
//! untimed predecessor, as the closed loop runs it.

use crate::bench::clarabel_peer::ClarabelEngine;
#[cfg(feature = "peers-osqp")]
use crate::bench::osqp_peer::OsqpEngine;
use crate::bench::states::BenchState;
use crate::bench::timing::{fmt_us, timed, Percentiles};
use capsule_mpc_runtime::generated::controller::{spec, Solver, TABLES};
use capsule_mpc_runtime::generated::SolveStatus;
use capsule_mpc_runtime::solver::explicit::{self, explicit_step_ops, ExplicitSample};
use capsule_mpc_runtime::solver::format::Section;
use capsule_mpc_runtime::solver::qp::{BoxQp, QpEngine};
use capsule_mpc_runtime::solver::PlanSolver;
use serde_json::{json, Value};
use spec::{K, N, NX};
use std::hint::black_box;

/// Passes over the states; the per-state minimum is reported.
pub const REPEATS: usize = 3;

/// A timed step's start: the solver after its first explicit step, and
/// the state one sample later.
type Start = (Solver, [f64; NX]);

/// The state after one explicit sample from `e`, and the solver that
/// played it (its last slot set as in the closed loop); None out of range.
fn after_one_explicit_sample(e: &[f64; NX]) -> Option<Start> {
    after_one_explicit_sample_on(e, &[[1.0, 1.0]; NX / 2], false)
}

/// As `after_one_explicit_sample`, with the solver told the capsules'
/// gain and drag factors `scales` and answering from the similar model
/// state when `similar` (the law alone's step off the model).
fn after_one_explicit_sample_on(
    e: &[f64; NX],
    scales: &[[f64; 2]; NX / 2],
    similar: bool,
) -> Option<Start> {
    let mut s = Solver::new();
    PlanSolver::set_model_scales(&mut s, scales);
    s.set_explicit_similarity(similar);
    if s.solve_explicit(e).status == SolveStatus::OutOfRange {
        return None;
    }
    s.adopt_explicit();
    let e1 = Solver::predict_plan(e, s.plan(), 1);
    s.shift(1);
    Some((s, e1))
}

/// Times both tiers; returns the `tiers` JSON and prints the table.
pub fn measure_tiers(states: &[BenchState], peer_count: usize) -> std::io::Result<Value> {
    let (origins, starts): (Vec<[f64; NX]>, Vec<Start>) = states
        .iter()
        .filter_map(|s| after_one_explicit_sample(&s.e).map(|start| (s.e, start)))
        .unzip();
    let mut explicit_ns = vec![u64::MAX; starts.len()];
    let mut refined_ns = vec![u64::MAX; starts.len()];
    let mut iterations = vec![0u32; starts.len()];
    for _ in 0..REPEATS {
        for (i, (proto, e1)) in starts.iter().enumerate() {
            let mut s = proto.clone();
            let (r, t) = timed(|| black_box(&mut s).solve_explicit(black_box(e1)));
            explicit_ns[i] = explicit_ns[i].min(t);
            iterations[i] = r.max_qp_iterations;
            let mut s = proto.clone();
            let (_, t) = timed(|| {
                let s = black_box(&mut s);
                s.solve_explicit(black_box(e1));
                s.solve(black_box(e1))
            });
            refined_ns[i] = refined_ns[i].min(t);
        }
    }
    // In the loop: each state's step timed right after the step before it
    // (from `e`, untimed), as the closed loop calls it; the data that step
    // touched is in cache. The sweep above times every state cold instead
    // (100 000 states cycle through 5.9 MB of explicit data).
    let mut in_loop_ns = vec![u64::MAX; starts.len()];
    for _ in 0..REPEATS {
        for (i, e) in origins.iter().enumerate() {
            let Some((mut solver, e1)) = after_one_explicit_sample(e) else {
                continue;
            };
            let (_, t) = timed(|| black_box(&mut solver).solve_explicit(black_box(&e1)));
            in_loop_ns[i] = in_loop_ns[i].min(t);
        }
    }
    // The law alone's step on capsules off the model (gain x0.9, drag
    // x1.2 learned): the similar state and the rescaled plan on top.
    let mut similar_ns = vec![u64::MAX; starts.len()];
    for _ in 0..REPEATS {
        for (i, e) in origins.iter().enumerate() {
            let Some((mut solver, e1)) =
                after_one_explicit_sample_on(e, &[[0.9, 1.2]; NX / 2], true)
            else {
                continue;
            };
            let (_, t) = timed(|| black_box(&mut solver).solve_explicit(black_box(&e1)));
            similar_ns[i] = similar_ns[i].min(t);
        }
    }
    let similar_ns: Vec<u64> = similar_ns.into_iter().filter(|&t| t != u64::MAX).collect();
    let ex = Percentiles::of(&explicit_ns);
    let in_loop = Percentiles::of(&in_loop_ns);
    let similar = Percentiles::of(&similar_ns);
    let re = Percentiles::of(&refined_ns);
    let max_iterations = iterations.iter().copied().max().unwrap_or(0);
    let mut histogram = std::collections::BTreeMap::<u32, u64>::new();
    for &it in &iterations {
        *histogram.entry(it).or_default() += 1;
    }
    let measured_max_ops = explicit_step_ops(N, NX, K, max_iterations as usize);
    let certified = <Solver as PlanSolver<NX, K>>::EXPLICIT_CERTIFIED_OPS;
    crate::out!(
        "tiers ({} states in range, min of {REPEATS}): {:<10} {:>9} {:>9} {:>9}",
        starts.len(),
        "",
        "median",
        "p99",
        "max"
    )?;
    for (name, p) in [
        ("explicit (cold: one sweep over all states)", ex),
        ("explicit in the loop (after the step before)", in_loop),
        ("the same off the model (similar state)", similar),
        ("refined", re),
    ] {
        crate::out!(
            "  {name:<46} {:>9} {:>9} {:>9}",
            fmt_us(p.median),
            fmt_us(p.p99),
            fmt_us(p.max)
        )?;
    }
    crate::out!(
        "explicit QP iterations: max {max_iterations} (cap {}), histogram {histogram:?}; operations at that count {measured_max_ops}, certified bound {certified}",
        spec::QP_MAX_ITERATIONS
    )?;
    let peers = explicit_qp_peers(&starts, peer_count)?;
    Ok(json!({
        "explicit": {
            "median_ns": ex.median, "p99_ns": ex.p99, "max_ns": ex.max,
            "max_qp_iterations": max_iterations,
            "qp_iteration_histogram": histogram.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "ops_at_max_iterations": measured_max_ops,
            "certified_ops": certified,
            "what": "Solver::solve_explicit from the state one explicit sample later (look-up, deviation, gradient, warm-started box QP, clamp)",
        },
        "explicit_in_loop": {
            "median_ns": in_loop.median, "p99_ns": in_loop.p99, "max_ns": in_loop.max,
            "what": "Solver::solve_explicit from the state one explicit sample later, timed right after the untimed step before it (its data in cache, as in the closed loop)",
        },
        "explicit_in_loop_similar": {
            "median_ns": similar.median, "p99_ns": similar.p99, "max_ns": similar.max,
            "states": similar_ns.len(),
            "what": "as explicit_in_loop, the law alone told gain x0.9 and drag x1.2: the similar model state's step and the rescaled plan",
        },
        "refined": {
            "median_ns": re.median, "p99_ns": re.p99, "max_ns": re.max,
            "what": "the explicit step followed by the SQP refinement Solver::solve (refine = once)",
        },
        "states": starts.len(),
        "repeats": REPEATS,
        "explicit_table_bytes": explicit_table_bytes(),
        "peers_on_explicit_qp": peers,
    }))
}

/// The explicit tier's box QP (the same H, gradient and box it solves,
/// as `explicit::explicit_plan` loads it) through clarabel (and OSQP with
/// `peers-osqp`) as `QpEngine`s, timed against the generated active-set QP
/// warm-started from the stored active set; the ratio is peer / ours at
/// the median, with the largest input difference.
fn explicit_qp_peers(starts: &[Start], peer_count: usize) -> std::io::Result<Value> {
    let count = peer_count.min(starts.len());
    let stride = (starts.len() / count.max(1)).max(1);
    let mut cases: Vec<(BoxQp<N>, usize)> = Vec::new();
    let mut qp = BoxQp::<{ spec::N }>::new(spec::QP_MAX_ITERATIONS, spec::QP_MULTIPLIER_TOLERANCE);
    let mut plan = [0.0; K];
    for (_, e1) in starts.iter().step_by(stride).take(count) {
        let Some(slot) = explicit::explicit_slot(&TABLES, e1, false, usize::MAX) else {
            continue;
        };
        if explicit::explicit_plan(
            &TABLES,
            spec::U_MAX_T_PER_M,
            e1,
            false,
            usize::MAX,
            None,
            &mut qp,
            &mut plan,
        )
        .is_none()
        {
            continue;
        }
        cases.push((qp.clone(), slot));
    }
    let mut ours_ns = Vec::new();
    let mut ours_x = Vec::new();
    for (case, slot) in &cases {
        let mut best = u64::MAX;
        let mut x = [0.0; N];
        let active = ExplicitSample::get(&TABLES, *slot).map_or([0; N], |s| s.active::<N>());
        for _ in 0..REPEATS {
            let mut q = case.clone();
            let (_, t) = timed(|| black_box(&mut q).solve_from(black_box(&active)));
            best = best.min(t);
            x = q.x;
        }
        ours_ns.push(best);
        ours_x.push(x);
    }
    let ours = Percentiles::of(&ours_ns);
    let engines: Vec<(&str, Box<dyn QpEngine<N>>)> = vec![
        ("clarabel", Box::new(ClarabelEngine)),
        #[cfg(feature = "peers-osqp")]
        ("osqp", Box::new(OsqpEngine::default())),
    ];
    let mut out = serde_json::Map::new();
    out.insert(
        "explicit_qp_ns".into(),
        json!({"median": ours.median, "p99": ours.p99, "max": ours.max, "qps": cases.len()}),
    );
    for (name, mut engine) in engines {
        let mut ns = Vec::new();
        let mut max_dx: f64 = 0.0;
        for ((case, _), x_ours) in cases.iter().zip(&ours_x) {
            let mut q = case.clone();
            q.x = [0.0; N];
            let (_, t) = timed(|| engine.solve(black_box(&mut q)));
            ns.push(t);
            for j in 0..N {
                max_dx = max_dx.max((q.x[j] - x_ours[j]).abs());
            }
        }
        let p = Percentiles::of(&ns);
        let ratio = p.median as f64 / ours.median.max(1) as f64;
        crate::out!(
            "  explicit QP: ours {} median, {name} {} median ({ratio:.1}x), largest input difference {max_dx:.1e} T/m",
            fmt_us(ours.median),
            fmt_us(p.median)
        )?;
        out.insert(
            name.into(),
            json!({"median_ns": p.median, "max_ns": p.max, "ratio_to_ours": ratio, "max_abs_du_t_per_m": max_dx}),
        );
    }
    Ok(Value::Object(out))
}

/// Bytes of the explicit tier's sections of the table file.
fn explicit_table_bytes() -> usize {
    Section::EXPLICIT
        .iter()
        .map(|&s| TABLES.section_bytes(s).len())
        .sum()
}
