//! `capsule-mpc bench`: timing of the online step, and peers on the same states.
//!
//! # What is timed
//!
//! For every benchmark state `e` (relative to the target, SI):
//!
//! * **cold** — a fresh controller (resp. solver) with no plan solves from
//!   `e`: the table lookup picks a stored plan tail, then the SQP iterations
//!   refine it. This is what the first step after `set_target` costs.
//! * **warm** — the step that follows, the way the closed loop does it with
//!   ideal sampling: the plan of the cold solve has its first input applied
//!   (`shift(1)`), and the solve runs from the *predicted* next state
//!   `e1 = predict(e, plan, 1)`. Only this second call is timed. It still
//!   compares the shifted plan with the table's plan from `e1` and runs the
//!   full `SQP_ITERATIONS` (there is no early exit), so warm and cold differ
//!   mostly in how good the starting plan is.
//!
//! "controller step" is `DefaultController::cycle_full_state(&x)` (estimate
//! overwrite, relative state, shift, solve, clamp and copy of the plan into
//! the output; `set_target` is done once on a prototype that is cloned per
//! state, not timed). "solver only" is `Solver::solve(&e)` of the generated
//! crate. Each call is timed alone with `std::time::Instant` (its own overhead,
//! about 20-40 ns, is reported as `timer_overhead_ns` and not subtracted),
//! inputs and outputs pass through `std::hint::black_box`, on one thread
//! pinned to one core, after an untimed warm-up pass.
//!
//! # States
//!
//! The states visited by closed-loop runs of scenarios A and C (ideal
//! sampling, 3 s, one row per 20 ms sample), plus states drawn uniformly over
//! the admissible region: each relative position over the warm-start index
//! range (`tables::INDEX_POSITION_AXIS`), each speed in +-0.3 m/s.
//!
//! # Peers
//!
//! The generated solver's window QP lives in private fields, so the peers run
//! inside [`RefSolver`], a plain-Rust re-implementation of the template's
//! refinement step (same table selection, same model through
//! `capsule_mpc_generator::model::rk4_capsule` with the config's parameters,
//! same weights through `OcpWeights::from_config`, same tail cost-to-go,
//! condensing and line search) whose QP engine is pluggable: the generated
//! active-set [`solver::BoxQp`] (the reference: it reproduces the generated
//! solver's plan, which is checked), clarabel, and OSQP (feature
//! `peers-osqp`). OpEn (PANOC) solves the nonlinear window problem itself:
//! the N window inputs in the box, the nonlinear cost over the whole plan with
//! the tail fixed, the exact gradient by the adjoint of the RK4 Jacobians.
//! All peers start from the same state and plan as the warm step above.

// Index loops mirror the math (S[k][j], H[a][b]), as in the template.
#![allow(clippy::needless_range_loop)]

use crate::cli::{BenchArgs, Sampling, Scenario};
use crate::closed_loop::{run, RunOptions};
use anyhow::{bail, Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::{rk4_capsule, CapsuleParams, Model};
use capsule_mpc_generator::ocp::OcpWeights;
use capsule_mpc_runtime::controller::Sampling as RtSampling;
use capsule_mpc_runtime::generated::controller::{solver, spec, tables};
use capsule_mpc_runtime::generated::{qp_iteration_map, SolveReport, SolveStatus};
use capsule_mpc_runtime::DefaultController;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};
use spec::{K, M, N, NX};
use std::collections::BTreeMap;
use std::hint::black_box;
use std::time::Instant;

/// Speed range of the uniformly drawn states, m/s.
pub const SAMPLED_SPEED_M_PER_S: f64 = 0.3;
/// Timing passes over all states; the per-state minimum is reported beside
/// the single-shot (first pass) distribution.
pub const REPEATS: usize = 3;
/// Closed-loop runs that contribute states (ideal sampling).
pub const CLOSED_LOOP_SECONDS: f64 = 3.0;

/// Where a benchmark state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    Uniform,
    ClosedLoopA,
    ClosedLoopC,
}

impl Origin {
    pub fn name(self) -> &'static str {
        match self {
            Origin::Uniform => "uniform",
            Origin::ClosedLoopA => "closed-loop-A",
            Origin::ClosedLoopC => "closed-loop-C",
        }
    }
}

/// One benchmark state, relative to the target (SI).
#[derive(Debug, Clone, Copy)]
pub struct BenchState {
    pub e: [f64; NX],
    pub origin: Origin,
}

/// `n` states: every closed-loop state of scenarios A and C (at most `n`),
/// the rest uniform over the admissible region.
pub fn sample_states(config: &Config, n: usize, seed: u64) -> Result<Vec<BenchState>> {
    let mut closed = Vec::new();
    for (scenario, origin) in [
        (Scenario::A, Origin::ClosedLoopA),
        (Scenario::C, Origin::ClosedLoopC),
    ] {
        let target = scenario.target_state();
        let mut opts = RunOptions::new(config, target.clone(), Sampling::Ideal);
        opts.duration_s = CLOSED_LOOP_SECONDS;
        let report = run(config, &opts)
            .with_context(|| format!("closed-loop run of scenario {}", scenario.name()))?;
        let mut last = None;
        for (t, x) in report.t.iter().zip(&report.x) {
            let k = (t / spec::DT_S).round();
            if (t - k * spec::DT_S).abs() > 1e-9 || last == Some(k) {
                continue;
            }
            last = Some(k);
            let mut e = [0.0; NX];
            for j in 0..NX {
                e[j] = x[j] - target[j];
            }
            closed.push(BenchState { e, origin });
        }
    }
    let mut states: Vec<BenchState> = if closed.len() > n {
        (0..n).map(|i| closed[i * closed.len() / n]).collect()
    } else {
        closed
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = tables::INDEX_POSITION_AXIS;
    let (p_lo, p_hi) = (axis.start, axis.start + (axis.count - 1) as f64 * axis.step);
    while states.len() < n {
        let mut e = [0.0; NX];
        for j in 0..NX {
            e[j] = if j % 2 == 0 {
                rng.gen_range(p_lo..=p_hi)
            } else {
                rng.gen_range(-SAMPLED_SPEED_M_PER_S..=SAMPLED_SPEED_M_PER_S)
            };
        }
        states.push(BenchState {
            e,
            origin: Origin::Uniform,
        });
    }
    Ok(states)
}

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
        let mut s = solver::Solver::new();
        let cold = s.solve(e);
        let e1 = solver::predict(e, s.plan(), 1);
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

/// A controller with the zero target set (states are then relative states),
/// ideal sampling.
pub fn prototype_controller() -> Result<DefaultController> {
    prototype_controller_with(RtSampling::Ideal)
}

/// A controller with the zero target set and the given sampling mode.
pub fn prototype_controller_with(sampling: RtSampling) -> Result<DefaultController> {
    let mut settings = DefaultController::default_settings();
    settings.sampling = sampling;
    let mut c = DefaultController::new(settings, &[0.0; M])
        .map_err(|e| anyhow::anyhow!("controller: {e:?}"))?;
    c.set_target(&[0.0; NX])
        .map_err(|e| anyhow::anyhow!("set_target: {e:?}"))?;
    Ok(c)
}

#[inline(always)]
fn timed<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let t0 = Instant::now();
    let r = black_box(f());
    let ns = t0.elapsed().as_nanos() as u64;
    (r, ns)
}

/// Times the cold and warm controller step and solver solve from `e`.
pub fn time_state(proto: &DefaultController, e: &[f64; NX]) -> StateTiming {
    // Solver only.
    let mut s = solver::Solver::new();
    let settings = proto.settings();
    let (samples, coast_s) = settings.schedule(settings.max_actuation_samples);
    s.set_schedule(samples, coast_s);
    let (cold, solver_cold) = timed(|| black_box(&mut s).solve(black_box(e)));
    let e1 = solver::predict(e, s.plan(), 1);
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
        cold_map: solver::qp_iterations_measured(e),
        warm_map: solver::qp_iterations_measured(&e1),
    }
}

/// Median, p99, p99.9 and max of `v` (nearest rank), ns.
#[derive(Debug, Clone, Copy, Default)]
pub struct Percentiles {
    pub median: u64,
    pub p99: u64,
    pub p999: u64,
    pub max: u64,
}

impl Percentiles {
    pub fn of(values: &[u64]) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        let mut v = values.to_vec();
        v.sort_unstable();
        let rank = |q: f64| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
        Percentiles {
            median: rank(0.5),
            p99: rank(0.99),
            p999: rank(0.999),
            max: v[v.len() - 1],
        }
    }

    pub fn json(&self) -> Value {
        json!({"median": self.median, "p99": self.p99, "p999": self.p999, "max": self.max})
    }
}

fn fmt_us(ns: u64) -> String {
    format!("{:.2} us", ns as f64 / 1e3)
}

/// Pins the calling thread to the last core (best effort); returns its id.
fn pin_to_one_core() -> Option<usize> {
    let ids = core_affinity::get_core_ids()?;
    let id = *ids.last()?;
    core_affinity::set_for_current(id).then_some(id.id)
}

/// Median cost of an empty `Instant` measurement, ns.
fn timer_overhead_ns() -> u64 {
    let v: Vec<u64> = (0..10_000).map(|_| timed(|| ()).1).collect();
    Percentiles::of(&v).median
}

// ---------------------------------------------------------------------------
// Reference refinement loop with a pluggable QP engine.
// ---------------------------------------------------------------------------

/// Model and weights of the reference loop, from the config (not from the
/// generated spec, so that agreement is a check of both).
#[derive(Debug, Clone)]
pub struct RefProblem {
    pub capsules: Vec<CapsuleParams>,
    pub q: [f64; NX],
    pub r: f64,
    pub p: [f64; NX],
    pub dt_s: f64,
    pub substeps: usize,
    pub u_max: f64,
}

impl RefProblem {
    pub fn from_config(config: &Config) -> Result<RefProblem> {
        let model = Model::from_config(config);
        let w = OcpWeights::from_config(config);
        if model.capsules.len() != M || w.q.len() != NX || w.p.len() != NX {
            bail!(
                "the config has {} capsules but the generated solver was built for {M}",
                model.capsules.len()
            );
        }
        let mut q = [0.0; NX];
        let mut p = [0.0; NX];
        q.copy_from_slice(&w.q);
        p.copy_from_slice(&w.p);
        Ok(RefProblem {
            capsules: model.capsules,
            q,
            r: w.r,
            p,
            dt_s: config.controller.sample_time_s,
            substeps: config.controller.rk4_substeps,
            u_max: model.u_max_t_per_m,
        })
    }

    /// Largest relative difference to the generated spec's constants.
    pub fn spec_mismatch(&self) -> f64 {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-300);
        let mut worst = rel(self.r, spec::R).max(rel(self.dt_s, spec::DT_S));
        worst = worst.max(rel(self.u_max, spec::U_MAX_T_PER_M));
        worst = worst.max(if self.substeps == spec::RK4_SUBSTEPS {
            0.0
        } else {
            1.0
        });
        for j in 0..NX {
            worst = worst
                .max(rel(self.q[j], spec::Q[j]))
                .max(rel(self.p[j], spec::P[j]));
        }
        for i in 0..M {
            worst = worst.max(rel(self.capsules[i].g, spec::G[i]));
            let (a_ref, _) = self.capsules[i].drag.accel_and_slope(0.1);
            worst = worst.max(rel(a_ref, spec::drag(i, 0.1).0));
        }
        worst
    }

    fn clamp(&self, u: f64) -> f64 {
        u.clamp(-self.u_max, self.u_max)
    }

    /// Nonlinear cost of `plan` from `e0` over K samples.
    pub fn cost(&self, e0: &[f64; NX], plan: &[f64; K]) -> f64 {
        let mut e = *e0;
        let mut cost = 0.0;
        for &u in plan.iter() {
            cost += self.r * u * u;
            for j in 0..NX {
                cost += self.q[j] * e[j] * e[j];
            }
            for (i, c) in self.capsules.iter().enumerate() {
                let s = rk4_capsule(c, [e[2 * i], e[2 * i + 1]], u, self.dt_s, self.substeps);
                e[2 * i] = s.next[0];
                e[2 * i + 1] = s.next[1];
            }
        }
        for j in 0..NX {
            cost += self.p[j] * e[j] * e[j];
        }
        if cost.is_nan() {
            f64::INFINITY
        } else {
            cost
        }
    }

    /// Rollout with per-capsule Jacobians a (row major 2x2) and b.
    fn rollout(&self, e0: &[f64; NX], plan: &[f64; K], w: &mut Trajectory) {
        w.states[0] = *e0;
        for k in 0..K {
            for (i, c) in self.capsules.iter().enumerate() {
                let xv = [w.states[k][2 * i], w.states[k][2 * i + 1]];
                let s = rk4_capsule(c, xv, plan[k], self.dt_s, self.substeps);
                w.states[k + 1][2 * i] = s.next[0];
                w.states[k + 1][2 * i + 1] = s.next[1];
                w.a[k][i] = [s.a[0][0], s.a[0][1], s.a[1][0], s.a[1][1]];
                w.b[k][i] = s.b;
            }
        }
    }

    /// Cost and its gradient with respect to `plan[..N]` (tail fixed), by
    /// the adjoint of the RK4 Jacobians.
    pub fn window_cost_gradient(&self, e0: &[f64; NX], plan: &[f64; K], grad: &mut [f64]) -> f64 {
        let mut w = Trajectory::new();
        self.rollout(e0, plan, &mut w);
        let mut cost = 0.0;
        let mut lam = [0.0; NX];
        for j in 0..NX {
            cost += self.p[j] * w.states[K][j] * w.states[K][j];
            lam[j] = 2.0 * self.p[j] * w.states[K][j];
        }
        for k in (0..K).rev() {
            let e = &w.states[k];
            cost += self.r * plan[k] * plan[k];
            let mut gu = 2.0 * self.r * plan[k];
            let mut next = [0.0; NX];
            for i in 0..M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                let (a, b) = (&w.a[k][i], &w.b[k][i]);
                gu += lam[xi] * b[0] + lam[vi] * b[1];
                next[xi] = 2.0 * self.q[xi] * e[xi] + a[0] * lam[xi] + a[2] * lam[vi];
                next[vi] = 2.0 * self.q[vi] * e[vi] + a[1] * lam[xi] + a[3] * lam[vi];
            }
            for j in 0..NX {
                cost += self.q[j] * e[j] * e[j];
            }
            if k < grad.len() {
                grad[k] = gu;
            }
            lam = next;
        }
        cost
    }
}

/// Rollout memory of the reference loop.
#[derive(Debug, Clone)]
struct Trajectory {
    states: [[f64; NX]; K + 1],
    a: [[[f64; 4]; M]; K],
    b: [[[f64; 2]; M]; K],
}

impl Trajectory {
    fn new() -> Trajectory {
        Trajectory {
            states: [[0.0; NX]; K + 1],
            a: [[[0.0; 4]; M]; K],
            b: [[[0.0; 2]; M]; K],
        }
    }
}

/// The window QP `min 1/2 x'Hx + g'x, lo <= x <= hi` (x = step on plan[..N]).
#[derive(Debug, Clone, Copy)]
pub struct DenseQp {
    pub h: [[f64; N]; N],
    pub g: [f64; N],
    pub lo: [f64; N],
    pub hi: [f64; N],
}

/// A box-QP engine for the reference loop.
pub trait QpEngine {
    fn name(&self) -> &'static str;
    /// Solves `qp` into `x`; returns (iterations, success). On failure `x`
    /// must still be in the box (zero is).
    fn solve(&mut self, qp: &DenseQp, x: &mut [f64; N]) -> (u32, bool);
}

/// The generated solver's primal active-set method.
#[derive(Debug, Clone, Default)]
pub struct ActiveSetEngine {
    pub qp: solver::BoxQp,
}

impl QpEngine for ActiveSetEngine {
    fn name(&self) -> &'static str {
        "active-set"
    }
    fn solve(&mut self, qp: &DenseQp, x: &mut [f64; N]) -> (u32, bool) {
        self.qp.h = qp.h;
        self.qp.g = qp.g;
        self.qp.lo = qp.lo;
        self.qp.hi = qp.hi;
        let r = self.qp.solve();
        *x = self.qp.x;
        r
    }
}

/// H's upper triangle in compressed sparse columns (column pointers, row
/// indices, values), dense: the form both clarabel and OSQP take.
fn upper_triangle_csc(qp: &DenseQp) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let mut colptr = Vec::with_capacity(N + 1);
    let mut rowval = Vec::with_capacity(N * (N + 1) / 2);
    let mut nzval = Vec::with_capacity(N * (N + 1) / 2);
    colptr.push(0);
    for c in 0..N {
        for r in 0..=c {
            rowval.push(r);
            nzval.push(qp.h[r][c]);
        }
        colptr.push(rowval.len());
    }
    (colptr, rowval, nzval)
}

/// clarabel 0.11 (interior point; no warm start): a new solver per QP.
#[derive(Debug, Clone, Default)]
pub struct ClarabelEngine;

impl QpEngine for ClarabelEngine {
    fn name(&self) -> &'static str {
        "clarabel"
    }
    fn solve(&mut self, qp: &DenseQp, x: &mut [f64; N]) -> (u32, bool) {
        use clarabel::algebra::CscMatrix;
        use clarabel::solver::{
            DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
        };
        // Dense upper triangle of H; A = [I; -I], b = [hi; -lo].
        let (colptr, rowval, nzval) = upper_triangle_csc(qp);
        let p = CscMatrix::new(N, N, colptr, rowval, nzval);
        let a = CscMatrix::new(
            2 * N,
            N,
            (0..=N).map(|c| 2 * c).collect(),
            (0..N).flat_map(|c| [c, N + c]).collect(),
            (0..N).flat_map(|_| [1.0, -1.0]).collect(),
        );
        let b: Vec<f64> = qp
            .hi
            .iter()
            .copied()
            .chain(qp.lo.iter().map(|v| -v))
            .collect();
        let cones = [NonnegativeConeT(2 * N)];
        let settings = DefaultSettings {
            verbose: false,
            ..DefaultSettings::default()
        };
        let Ok(mut s) = DefaultSolver::new(&p, &qp.g, &a, &b, &cones, settings) else {
            *x = [0.0; N];
            return (0, false);
        };
        s.solve();
        let ok = matches!(
            s.solution.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        );
        for j in 0..N {
            x[j] = if ok {
                s.solution.x[j].clamp(qp.lo[j], qp.hi[j])
            } else {
                0.0
            };
        }
        (s.solution.iterations, ok)
    }
}

/// OSQP 0.6 (ADMM): one workspace, `P`, `q` and the bounds updated per QP;
/// OSQP's default warm start (from the previous QP's solution) is kept.
#[cfg(feature = "peers-osqp")]
#[derive(Default)]
pub struct OsqpEngine {
    problem: Option<osqp::Problem>,
}

#[cfg(feature = "peers-osqp")]
impl OsqpEngine {
    /// Tolerances: tight enough to agree with the exact active-set solution
    /// to about 1e-6 T/m on steps of up to 0.08 T/m; polishing on.
    pub fn settings() -> osqp::Settings {
        osqp::Settings::default()
            .verbose(false)
            .eps_abs(1e-7)
            .eps_rel(1e-7)
            .max_iter(20_000)
            .polish(true)
    }

    fn upper(qp: &DenseQp) -> osqp::CscMatrix<'static> {
        let (indptr, indices, data) = upper_triangle_csc(qp);
        osqp::CscMatrix {
            nrows: N,
            ncols: N,
            indptr: indptr.into(),
            indices: indices.into(),
            data: data.into(),
        }
    }
}

#[cfg(feature = "peers-osqp")]
impl QpEngine for OsqpEngine {
    fn name(&self) -> &'static str {
        "osqp"
    }
    fn solve(&mut self, qp: &DenseQp, x: &mut [f64; N]) -> (u32, bool) {
        let p = Self::upper(qp);
        let problem = match &mut self.problem {
            Some(pr) => {
                pr.update_P(p);
                pr.update_lin_cost(&qp.g);
                pr.update_bounds(&qp.lo, &qp.hi);
                pr
            }
            None => {
                let mut eye = [[0.0; N]; N];
                for j in 0..N {
                    eye[j][j] = 1.0;
                }
                let a = osqp::CscMatrix::from(&eye[..]);
                match osqp::Problem::new(p, &qp.g, a, &qp.lo, &qp.hi, &Self::settings()) {
                    Ok(pr) => self.problem.insert(pr),
                    Err(_) => {
                        *x = [0.0; N];
                        return (0, false);
                    }
                }
            }
        };
        let status = problem.solve();
        let iters = status.iter();
        match status {
            osqp::Status::Solved(s) | osqp::Status::SolvedInaccurate(s) => {
                for j in 0..N {
                    x[j] = s.x()[j].clamp(qp.lo[j], qp.hi[j]);
                }
                (iters, true)
            }
            _ => {
                *x = [0.0; N];
                (iters, false)
            }
        }
    }
}

/// What one reference refinement step returns.
#[derive(Debug, Clone, Copy)]
pub struct RefOutcome {
    pub plan: [f64; K],
    pub cost: f64,
    /// Step on the first input from the first QP (same data for every engine).
    pub first_du0: f64,
    /// Time spent in the QP engine, ns, per QP.
    pub qp_ns: [u64; spec::SQP_ITERATIONS],
    pub max_qp_iterations: u32,
    pub qp_failures: u32,
}

/// The template's refinement step, re-implemented over [`RefProblem`].
#[derive(Debug, Clone)]
pub struct RefSolver {
    w: Trajectory,
    sens: [[[f64; NX]; N]; N + 1],
    tail_hess: [[f64; 4]; M],
    tail_grad: [f64; NX],
    pub qp: DenseQp,
}

impl Default for RefSolver {
    fn default() -> Self {
        RefSolver::new()
    }
}

impl RefSolver {
    pub fn new() -> RefSolver {
        RefSolver {
            w: Trajectory::new(),
            sens: [[[0.0; NX]; N]; N + 1],
            tail_hess: [[0.0; 4]; M],
            tail_grad: [0.0; NX],
            qp: DenseQp {
                h: [[0.0; N]; N],
                g: [0.0; N],
                lo: [0.0; N],
                hi: [0.0; N],
            },
        }
    }

    /// The plan the SQP starts from: `plan` (if any) or the table's plan tail
    /// from `e`, whichever is cheaper (as the generated solver does).
    pub fn start_plan(
        problem: &RefProblem,
        e: &[f64; NX],
        plan: Option<&[f64; K]>,
    ) -> Option<([f64; K], f64)> {
        let mut best = plan.map(|p| (*p, problem.cost(e, p)));
        let mut cand = [0.0; K];
        if solver::lookup_tail(e, &mut cand).is_some() {
            let c = problem.cost(e, &cand);
            if best.as_ref().is_none_or(|b| c < b.1) {
                best = Some((cand, c));
            }
        }
        best
    }

    /// One full refinement step from `e` with `engine` as the QP engine.
    pub fn refine(
        &mut self,
        problem: &RefProblem,
        engine: &mut dyn QpEngine,
        e: &[f64; NX],
        plan: Option<&[f64; K]>,
    ) -> Option<RefOutcome> {
        let (mut plan, mut cost) = Self::start_plan(problem, e, plan)?;
        let mut out = RefOutcome {
            plan,
            cost,
            first_du0: 0.0,
            qp_ns: [0; spec::SQP_ITERATIONS],
            max_qp_iterations: 0,
            qp_failures: 0,
        };
        let mut x = [0.0; N];
        for it in 0..spec::SQP_ITERATIONS {
            self.build_qp(problem, e, &plan);
            let ((iters, ok), ns) = timed(|| engine.solve(&self.qp, &mut x));
            out.qp_ns[it] = ns;
            out.max_qp_iterations = out.max_qp_iterations.max(iters);
            if !ok {
                out.qp_failures += 1;
            }
            if it == 0 {
                out.first_du0 = x[0];
            }
            let mut step = 1.0;
            for _ in 0..spec::LINE_SEARCH_TRIES {
                let mut cand = plan;
                for j in 0..N {
                    cand[j] = problem.clamp(plan[j] + step * x[j]);
                }
                let c = problem.cost(e, &cand);
                if c < cost {
                    plan = cand;
                    cost = c;
                    break;
                }
                step *= 0.5;
            }
        }
        out.plan = plan;
        out.cost = cost;
        Some(out)
    }

    /// Linearizes along `plan` and condenses the window QP into `self.qp`.
    pub fn build_qp(&mut self, problem: &RefProblem, e: &[f64; NX], plan: &[f64; K]) {
        problem.rollout(e, plan, &mut self.w);
        let (q, p, r) = (&problem.q, &problem.p, problem.r);
        let states = &self.w.states;
        // Tail cost-to-go from K back to N (Gauss-Newton).
        for i in 0..M {
            let (xi, vi) = (2 * i, 2 * i + 1);
            let mut h = [p[xi], 0.0, 0.0, p[vi]];
            let mut g = [p[xi] * states[K][xi], p[vi] * states[K][vi]];
            for k in (N..K).rev() {
                let a = &self.w.a[k][i];
                let t0 = h[0] * a[0] + h[1] * a[2];
                let t1 = h[0] * a[1] + h[1] * a[3];
                let t2 = h[1] * a[0] + h[3] * a[2];
                let t3 = h[1] * a[1] + h[3] * a[3];
                let n0 = a[0] * t0 + a[2] * t2 + q[xi];
                let n1 = a[0] * t1 + a[2] * t3;
                let n3 = a[1] * t1 + a[3] * t3 + q[vi];
                h = [n0, n1, n1, n3];
                g = [
                    a[0] * g[0] + a[2] * g[1] + q[xi] * states[k][xi],
                    a[1] * g[0] + a[3] * g[1] + q[vi] * states[k][vi],
                ];
            }
            self.tail_hess[i] = h;
            self.tail_grad[xi] = g[0];
            self.tail_grad[vi] = g[1];
        }
        // Window sensitivities sens[k][j] = d e_k / d u_j.
        for k in 0..N {
            for i in 0..M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                let a = self.w.a[k][i];
                for j in 0..k {
                    let (s0, s1) = (self.sens[k][j][xi], self.sens[k][j][vi]);
                    self.sens[k + 1][j][xi] = a[0] * s0 + a[1] * s1;
                    self.sens[k + 1][j][vi] = a[2] * s0 + a[3] * s1;
                }
                self.sens[k + 1][k][xi] = self.w.b[k][i][0];
                self.sens[k + 1][k][vi] = self.w.b[k][i][1];
            }
        }
        // Condense.
        let qp = &mut self.qp;
        for a in 0..N {
            let mut g = r * plan[a];
            for b in a..N {
                qp.h[a][b] = if a == b { r } else { 0.0 };
            }
            for k in a + 1..N {
                let sa = &self.sens[k][a];
                for rr in 0..NX {
                    g += sa[rr] * q[rr] * states[k][rr];
                }
                for b in a..k {
                    let sb = &self.sens[k][b];
                    let mut acc = 0.0;
                    for rr in 0..NX {
                        acc += sa[rr] * q[rr] * sb[rr];
                    }
                    qp.h[a][b] += acc;
                }
            }
            let sa = &self.sens[N][a];
            for i in 0..M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                g += sa[xi] * self.tail_grad[xi] + sa[vi] * self.tail_grad[vi];
                let hh = &self.tail_hess[i];
                for b in a..N {
                    let sb = &self.sens[N][b];
                    qp.h[a][b] += sa[xi] * (hh[0] * sb[xi] + hh[1] * sb[vi])
                        + sa[vi] * (hh[2] * sb[xi] + hh[3] * sb[vi]);
                }
            }
            qp.g[a] = g;
            qp.lo[a] = -problem.u_max - plan[a];
            qp.hi[a] = problem.u_max - plan[a];
        }
        for a in 0..N {
            for b in 0..a {
                qp.h[a][b] = qp.h[b][a];
            }
        }
    }
}

/// OpEn (PANOC) on the nonlinear window problem; returns (plan, cost,
/// iterations, converged).
pub struct OpenPeer {
    cache: optimization_engine::panoc::PANOCCache,
}

/// PANOC tolerance on the fixed-point residual (T/m) and iteration bound.
pub const OPEN_TOLERANCE: f64 = 1e-6;
pub const OPEN_MAX_ITERATIONS: usize = 200;
/// L-BFGS memory of PANOC.
pub const OPEN_LBFGS_MEMORY: usize = 5;

impl Default for OpenPeer {
    fn default() -> Self {
        OpenPeer::new()
    }
}

impl OpenPeer {
    pub fn new() -> OpenPeer {
        OpenPeer {
            cache: optimization_engine::panoc::PANOCCache::new(
                N,
                OPEN_TOLERANCE,
                OPEN_LBFGS_MEMORY,
            ),
        }
    }

    /// From the same start plan as the reference loop (table selection
    /// included), solves the window problem to PANOC's tolerance.
    pub fn refine(
        &mut self,
        problem: &RefProblem,
        e: &[f64; NX],
        plan: Option<&[f64; K]>,
    ) -> Option<([f64; K], f64, usize, bool)> {
        use optimization_engine::{
            constraints::Rectangle, panoc::PANOCOptimizer, Optimizer, Problem,
        };
        let (start, _) = RefSolver::start_plan(problem, e, plan)?;
        let lo = [-problem.u_max; N];
        let hi = [problem.u_max; N];
        let bounds = Rectangle::new(Some(&lo), Some(&hi));
        let full = |w: &[f64]| {
            let mut p = start;
            p[..N].copy_from_slice(w);
            p
        };
        let cost = |w: &[f64], c: &mut f64| {
            *c = problem.cost(e, &full(w));
            Ok(())
        };
        let grad = |w: &[f64], g: &mut [f64]| {
            problem.window_cost_gradient(e, &full(w), g);
            Ok(())
        };
        let p = Problem::new(&bounds, grad, cost);
        let mut opt = PANOCOptimizer::new(p, &mut self.cache).with_max_iter(OPEN_MAX_ITERATIONS);
        let mut w = [0.0; N];
        w.copy_from_slice(&start[..N]);
        let status = opt.solve(&mut w).ok()?;
        let plan = full(&w);
        Some((
            plan,
            problem.cost(e, &plan),
            status.iterations(),
            status.has_converged(),
        ))
    }
}

// ---------------------------------------------------------------------------
// The command.
// ---------------------------------------------------------------------------

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

/// `capsule-mpc bench`.
pub fn run_cli(args: &BenchArgs) -> Result<()> {
    if args.states == 0 {
        bail!("--states must be at least 1");
    }
    let config = Config::embedded_default();
    let problem = RefProblem::from_config(&config)?;
    let mismatch = problem.spec_mismatch();
    if mismatch > 1e-9 {
        eprintln!(
            "warning: the embedded config differs from the generated spec (relative {mismatch:.1e}); peers use the config"
        );
    }
    eprintln!(
        "bench: sampling {} states (seed {})",
        args.states, args.seed
    );
    let states = sample_states(&config, args.states, args.seed)?;
    let proto = prototype_controller_with(args.sampling.runtime())?;
    let peer_count = args.peer_states.min(states.len());
    let result = std::thread::scope(|scope| {
        scope
            .spawn(|| measure(&states, &proto, &problem, peer_count))
            .join()
            .map_err(|_| anyhow::anyhow!("the benchmark thread panicked"))
    })??;
    let mut report = result;
    report["states"] = json!(states.len());
    report["seed"] = json!(args.seed);
    report["sampling"] = json!(args.sampling.name());
    report["spec_mismatch"] = json!(mismatch);
    if let Some(path) = &args.json {
        crate::report::write_json_atomic(path, &report)?;
    }
    Ok(())
}

fn measure(
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

    println!(
        "capsule-mpc bench: {} states ({origins:?}), core {core:?}, timer overhead {overhead} ns",
        states.len()
    );
    println!(
        "{:<34} {:>11} {:>11} {:>11} {:>11}",
        "single shot", "median", "p99", "p99.9", "max"
    );
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
    for (name, p) in rows {
        println!(
            "{name:<34} {:>11} {:>11} {:>11} {:>11}",
            fmt_us(p.median),
            fmt_us(p.p99),
            fmt_us(p.p999),
            fmt_us(p.max)
        );
    }
    println!("QP iterations (max per QP, per solve): max {max_iter}, histogram {hist:?}; statuses {statuses:?}");
    println!(
        "QP iteration map (offline, per index cell; largest entry {}): {above_map} of {} solves above their cell's count, {unmapped} in cells without one",
        qp_iteration_map::CONTROLLER_MAX,
        2 * timings.len()
    );
    println!("worst states (by max of cold/warm controller step; re-timed medians show whether the max was noise):");
    for w in &worst {
        println!(
            "  #{} {} e = {:?}: cold {} ns, warm {} ns, re-timed median cold {} ns, warm {} ns, {} QP iterations",
            w["index"],
            w["origin"].as_str().unwrap_or(""),
            states[w["index"].as_u64().unwrap_or(0) as usize].e,
            w["step_cold_ns"],
            w["step_warm_ns"],
            w["retimed_step_cold_median_ns"],
            w["retimed_step_warm_median_ns"],
            w["max_qp_iterations"]
        );
    }

    let peers = run_peers(states, problem, peer_count);

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
        "allocations_per_step": 0,
        "allocations_source": "tests/alloc_free.rs (counting global allocator over set_target, cycle_full_state and cycle along closed-loop runs)",
        "workspace_bytes": std::mem::size_of::<DefaultController>(),
        "solver_bytes": std::mem::size_of::<solver::Solver>(),
        "table_bytes": tables::TABLE_BYTES,
        "timer_overhead_ns": overhead,
        "pinned_core": core,
        "origins": origins,
        "what_is_timed": "step_ns/solver_ns: the warm step (solve from the predicted next state after shift(1) of the plan of a first solve); *_cold_ns: that first solve of a fresh controller/solver. Per-call Instant timing, one pinned thread, after warm-up.",
    }))
}

fn run_peers(states: &[BenchState], problem: &RefProblem, count: usize) -> Value {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjoint_gradient_matches_finite_differences() {
        let problem = RefProblem::from_config(&Config::embedded_default()).unwrap();
        let e = [0.01, 0.05, -0.02, -0.1];
        let mut plan = [0.0; K];
        for (k, u) in plan.iter_mut().enumerate() {
            *u = 0.03 * ((k as f64) * 0.7).sin();
        }
        let mut g = [0.0; N];
        let c = problem.window_cost_gradient(&e, &plan, &mut g);
        assert!((c - problem.cost(&e, &plan)).abs() <= 1e-9 * c.abs());
        for j in 0..N {
            let h = 1e-6;
            let (mut p1, mut p2) = (plan, plan);
            p1[j] += h;
            p2[j] -= h;
            let fd = (problem.cost(&e, &p1) - problem.cost(&e, &p2)) / (2.0 * h);
            assert!(
                (fd - g[j]).abs() <= 1e-5 * fd.abs().max(1.0),
                "{j}: fd {fd} adjoint {}",
                g[j]
            );
        }
    }

    #[test]
    fn reference_loop_reproduces_generated_solver() {
        let problem = RefProblem::from_config(&Config::embedded_default()).unwrap();
        let mut rs = RefSolver::new();
        let mut engine = ActiveSetEngine::default();
        for e in [[0.02, 0.0, -0.01, 0.0], [-0.03, 0.1, 0.02, -0.2]] {
            let mut s = solver::Solver::new();
            let r = s.solve(&e);
            let ours = rs.refine(&problem, &mut engine, &e, None).unwrap();
            assert!(
                (ours.cost - r.cost).abs() <= 1e-6 * r.cost,
                "{} vs {}",
                ours.cost,
                r.cost
            );
            assert!((ours.plan[0] - s.plan()[0]).abs() < 1e-9);
        }
    }

    #[test]
    fn percentiles_nearest_rank() {
        let v: Vec<u64> = (1..=1000).collect();
        let p = Percentiles::of(&v);
        assert_eq!((p.median, p.p99, p.p999, p.max), (500, 990, 999, 1000));
    }
}
