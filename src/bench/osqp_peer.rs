//! OSQP as the refinement's window-QP engine (feature `peers-osqp`).

use crate::bench::engine::upper_triangle_csc;
use capsule_mpc_runtime::generated::controller::spec::N;
use capsule_mpc_runtime::solver::qp::{BoxQp, QpEngine};

/// OSQP 0.6 (ADMM): one workspace, `P`, `q` and the bounds updated per QP;
/// OSQP's default warm start (from the previous QP's solution) is kept.
#[derive(Default)]
pub struct OsqpEngine {
    problem: Option<osqp::Problem>,
}

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

    fn upper(qp: &BoxQp<N>) -> osqp::CscMatrix<'static> {
        let (indptr, indices, data) = upper_triangle_csc(&qp.h);
        osqp::CscMatrix {
            nrows: N,
            ncols: N,
            indptr: indptr.into(),
            indices: indices.into(),
            data: data.into(),
        }
    }
}

impl QpEngine<N> for OsqpEngine {
    fn solve(&mut self, qp: &mut BoxQp<N>) -> (u32, bool) {
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
                        qp.x = [0.0; N];
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
                    qp.x[j] = s.x()[j].clamp(qp.lo[j], qp.hi[j]);
                }
                (iters, true)
            }
            _ => {
                qp.x = [0.0; N];
                (iters, false)
            }
        }
    }
}
