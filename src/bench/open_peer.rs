//! OpEn (PANOC) on the nonlinear window problem, from the reference loop's
//! start plan.

use crate::bench::reference::{RefProblem, RefSolver};
use capsule_mpc_runtime::generated::controller::spec::{K, N, NX};

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
