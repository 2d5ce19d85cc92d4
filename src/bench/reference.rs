//! Reference refinement loop with a pluggable QP engine: the template's
//! refinement step re-implemented over the config's model and weights, and
//! the generated solver's active-set method as its reference engine.

use crate::bench::timing::timed;
use anyhow::{bail, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::{rk4_capsule, CapsuleParams, Model};
use capsule_mpc_generator::ocp::OcpWeights;
use capsule_mpc_runtime::generated::controller::{spec, TABLES};
use capsule_mpc_runtime::solver::lookup;
use capsule_mpc_runtime::solver::qp::BoxQp;
use spec::{K, M, N, NX};

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
#[derive(Debug, Clone)]
pub struct ActiveSetEngine {
    pub qp: BoxQp<N>,
}

impl Default for ActiveSetEngine {
    fn default() -> Self {
        ActiveSetEngine {
            qp: BoxQp::<{ spec::N }>::new(spec::QP_MAX_ITERATIONS, spec::QP_MULTIPLIER_TOLERANCE),
        }
    }
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
pub(crate) fn upper_triangle_csc(qp: &DenseQp) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
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
        if lookup::lookup_tail(&TABLES, e, &mut cand).is_some() {
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

#[cfg(test)]
mod tests {
    use super::*;
    use capsule_mpc_runtime::generated::controller::Solver;

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
            let mut s = Solver::new();
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
}
