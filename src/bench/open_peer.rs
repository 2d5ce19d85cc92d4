//! OpEn (PANOC) on the nonlinear window problem, from the plan the
//! refinement starts from.
//!
//! PANOC needs the window problem's cost and gradient. Both come from the
//! solver crate's public rollout (`rollout_cost`, `rollout_with_jacobians`
//! with the per-sample RK4 Jacobians, ideal schedule, the generated spec's
//! weights); the gradient is the adjoint (costate) recursion on those
//! Jacobians, written here: it is the peer's algorithm, the refinement
//! condenses a Gauss-Newton QP instead.

use capsule_mpc_runtime::generated::controller::{spec, Spec, TABLES};
use capsule_mpc_runtime::solver::lookup::{lookup_fine, lookup_tail};
use capsule_mpc_runtime::solver::rollout::{
    rollout_cost, rollout_with_jacobians, Schedule, StepJacobian,
};
use spec::{K, M, N, NX};

/// PANOC tolerance on the fixed-point residual (T/m) and iteration bound.
pub const OPEN_TOLERANCE: f64 = 1e-6;
pub const OPEN_MAX_ITERATIONS: usize = 200;
/// L-BFGS memory of PANOC.
pub const OPEN_LBFGS_MEMORY: usize = 5;

/// Nonlinear cost of `plan` from `e0` over K samples (ideal schedule), as
/// the solver measures it.
pub fn plan_cost(e0: &[f64; NX], plan: &[f64; K]) -> f64 {
    rollout_cost::<Spec, M, NX, K>(e0, plan, &Schedule::BACK_TO_BACK)
}

/// The cost of `plan` from `e0` and, in `grad`, its gradient with respect
/// to `plan[..grad.len()]` (the rest of the plan fixed): the rollout with
/// Jacobians, then lambda_K = 2 P e_K, dJ/du_k = 2 R u_k + lambda_{k+1}' b_k,
/// lambda_k = 2 Q e_k + A_k' lambda_{k+1}.
pub fn window_cost_gradient(e0: &[f64; NX], plan: &[f64; K], grad: &mut [f64]) -> f64 {
    let mut states = [[0.0; NX]; K];
    let mut end = [0.0; NX];
    let mut jac = [StepJacobian::<M>::ZERO; K];
    let cost = rollout_with_jacobians::<Spec, M, NX, K>(
        e0,
        plan,
        &Schedule::BACK_TO_BACK,
        &mut states,
        &mut end,
        &mut jac,
    );
    let mut lam = [0.0; NX];
    for j in 0..NX {
        lam[j] = 2.0 * spec::P[j] * end[j];
    }
    let window = grad.len().min(K);
    for k in (0..K).rev() {
        let e = &states[k];
        let mut gu = 2.0 * spec::R * plan[k];
        let mut next = [0.0; NX];
        for i in 0..M {
            let (xi, vi) = (2 * i, 2 * i + 1);
            let (a, b) = (&jac[k].a[i], &jac[k].b[i]);
            gu += lam[xi] * b[0] + lam[vi] * b[1];
            next[xi] = 2.0 * spec::Q[xi] * e[xi] + a[0] * lam[xi] + a[2] * lam[vi];
            next[vi] = 2.0 * spec::Q[vi] * e[vi] + a[1] * lam[xi] + a[3] * lam[vi];
        }
        if k < window {
            grad[k] = gu;
        }
        lam = next;
    }
    cost
}

/// The plan `Solver::solve` refines from `e` when it holds `plan` (None:
/// no plan), and its cost: the cheaper of `plan` and the stored plan tail
/// from `e` (without a plan, the fine grid's plan first); ideal schedule.
pub fn start_plan(e: &[f64; NX], plan: Option<&[f64; K]>) -> Option<([f64; K], f64)> {
    let mut best = plan.map(|p| (*p, plan_cost(e, p)));
    let mut cand = [0.0; K];
    let found = (plan.is_none() && lookup_fine(&TABLES, e, &mut cand, false).is_some())
        || lookup_tail(&TABLES, e, &mut cand).is_some();
    if found {
        let c = plan_cost(e, &cand);
        if best.as_ref().is_none_or(|b| c < b.1) {
            best = Some((cand, c));
        }
    }
    best
}

/// OpEn (PANOC) on the nonlinear window problem: the N window inputs in
/// the box, the nonlinear cost over the whole plan with the tail fixed.
pub struct OpenPeer {
    cache: optimization_engine::panoc::PANOCCache,
}

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

    /// From the plan the refinement starts from (table selection
    /// included, [`start_plan`]), solves the window problem to PANOC's
    /// tolerance; returns (plan, cost, iterations, converged).
    pub fn refine(
        &mut self,
        e: &[f64; NX],
        plan: Option<&[f64; K]>,
    ) -> Option<([f64; K], f64, usize, bool)> {
        use optimization_engine::{
            constraints::Rectangle, panoc::PANOCOptimizer, Optimizer, Problem,
        };
        let (start, _) = start_plan(e, plan)?;
        let lo = [-spec::U_MAX_T_PER_M; N];
        let hi = [spec::U_MAX_T_PER_M; N];
        let bounds = Rectangle::new(Some(&lo), Some(&hi));
        let full = |w: &[f64]| {
            let mut p = start;
            p[..N].copy_from_slice(w);
            p
        };
        let cost = |w: &[f64], c: &mut f64| {
            *c = plan_cost(e, &full(w));
            Ok(())
        };
        let grad = |w: &[f64], g: &mut [f64]| {
            window_cost_gradient(e, &full(w), g);
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
            plan_cost(e, &plan),
            status.iterations(),
            status.has_converged(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use capsule_mpc_runtime::generated::controller::Solver;

    #[test]
    fn adjoint_gradient_matches_finite_differences() {
        let e = [0.01, 0.05, -0.02, -0.1];
        let mut plan = [0.0; K];
        for (k, u) in plan.iter_mut().enumerate() {
            *u = 0.03 * ((k as f64) * 0.7).sin();
        }
        let mut g = [0.0; N];
        let c = window_cost_gradient(&e, &plan, &mut g);
        assert!((c - plan_cost(&e, &plan)).abs() <= 1e-9 * c.abs());
        for j in 0..N {
            let h = 1e-6;
            let (mut p1, mut p2) = (plan, plan);
            p1[j] += h;
            p2[j] -= h;
            let fd = (plan_cost(&e, &p1) - plan_cost(&e, &p2)) / (2.0 * h);
            assert!(
                (fd - g[j]).abs() <= 1e-5 * fd.abs().max(1.0),
                "{j}: fd {fd} adjoint {}",
                g[j]
            );
        }
    }

    #[test]
    fn start_plan_is_the_solvers_table_choice() {
        // Without a plan the solver's start is the stored tail; the cold
        // solve's first input differs from it only by the SQP's step.
        for e in [[0.02, 0.0, -0.01, 0.0], [-0.03, 0.1, 0.02, -0.2]] {
            let (start, c) = start_plan(&e, None).expect("in range");
            let mut s = Solver::new();
            let r = s.solve(&e);
            assert!(r.took_table_plan);
            assert!(r.cost <= c, "{} > {c}", r.cost);
            assert_eq!(&start[N..], &s.plan()[N..]);
        }
    }
}
