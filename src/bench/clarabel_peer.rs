//! clarabel as the refinement's window-QP engine.

use crate::bench::engine::upper_triangle_csc;
use capsule_mpc_runtime::solver::qp::{BoxQp, QpEngine};

/// clarabel 0.11 (interior point; no warm start): a new solver per QP.
#[derive(Debug, Clone, Copy, Default)]
pub struct ClarabelEngine;

impl<const N: usize> QpEngine<N> for ClarabelEngine {
    fn solve(&mut self, qp: &mut BoxQp<N>) -> (u32, bool) {
        use clarabel::algebra::CscMatrix;
        use clarabel::solver::{
            DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
        };
        // Dense upper triangle of H; A = [I; -I], b = [hi; -lo].
        let (colptr, rowval, nzval) = upper_triangle_csc(&qp.h);
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
            qp.x = [0.0; N];
            return (0, false);
        };
        s.solve();
        let ok = matches!(
            s.solution.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        );
        for j in 0..N {
            qp.x[j] = if ok {
                s.solution.x[j].clamp(qp.lo[j], qp.hi[j])
            } else {
                0.0
            };
        }
        (s.solution.iterations, ok)
    }
}
