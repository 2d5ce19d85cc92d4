//! The bench's side of the refinement's pluggable QP engine
//! (`capsule_mpc_solver::qp::QpEngine`): [`Timed`], a wrapper around any
//! engine that times each window QP it solves, and the dense upper
//! triangle of a QP's Hessian that the sparse peers take.
//!
//! The peers run inside the real solver,
//! `capsule_mpc_solver::Solver::<Spec, M, NX, N, K, Timed<E>>::with_engine`,
//! so a peer's step is the generated module's own `solve` (table check,
//! rollouts, tail cost-to-go, condensing, line search) with only the QP
//! engine swapped. The active-set row wraps [`ActiveSet`] the same way, so
//! every row pays the same wrapper overhead.

use crate::bench::timing::timed;
use capsule_mpc_runtime::solver::qp::{ActiveSet, BoxQp, QpEngine};
use std::cell::Cell;

/// One recorded QP call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QpCall {
    /// Time spent in the inner engine's `solve`, ns.
    pub ns: u64,
    pub iterations: u32,
    pub converged: bool,
}

/// A QP engine that times the calls of its inner engine `E`.
///
/// Disarmed (as built, and after [`disarm`](Timed::disarm)) the calls go
/// to the active-set method, unrecorded: the cold solve that sets up a
/// warm case is then bit for bit the plain solver's, whatever `E` is, and
/// every engine's warm step starts from the same plan. Armed, the calls go
/// to `E` and each is recorded (time, iterations, convergence, and the
/// first call's step `x[0]`). Arming goes through a shared reference
/// (`Cell`), as the solver hands its engine back by `Solver::engine`.
#[derive(Debug, Clone)]
pub struct Timed<E> {
    inner: E,
    armed: Cell<bool>,
    /// Set by `arm`: the next call starts a new record.
    fresh: Cell<bool>,
    calls: Vec<QpCall>,
    first_step: f64,
}

impl<E: Default> Default for Timed<E> {
    fn default() -> Self {
        Timed::new(E::default())
    }
}

impl<E> Timed<E> {
    /// Disarmed, around `inner`.
    pub fn new(inner: E) -> Timed<E> {
        Timed {
            inner,
            armed: Cell::new(false),
            fresh: Cell::new(true),
            // Room for the SQP iterations of a solve: recording does not
            // allocate inside the timed step.
            calls: Vec::with_capacity(16),
            first_step: 0.0,
        }
    }

    /// The wrapped engine.
    pub fn inner(&self) -> &E {
        &self.inner
    }

    /// From the next call on, QPs go to the inner engine and are recorded;
    /// the record of earlier calls is dropped.
    pub fn arm(&self) {
        self.armed.set(true);
        self.fresh.set(true);
    }

    /// From the next call on, QPs go to the active-set method, unrecorded
    /// (the record so far is kept).
    pub fn disarm(&self) {
        self.armed.set(false);
    }

    /// The calls recorded since the last `arm`.
    pub fn calls(&self) -> &[QpCall] {
        if self.fresh.get() {
            &[]
        } else {
            &self.calls
        }
    }

    /// The first recorded call's step on the first input, `x[0]`.
    pub fn first_step(&self) -> Option<f64> {
        (!self.calls().is_empty()).then_some(self.first_step)
    }
}

impl<const N: usize, E: QpEngine<N>> QpEngine<N> for Timed<E> {
    fn solve(&mut self, qp: &mut BoxQp<N>) -> (u32, bool) {
        if !self.armed.get() {
            return ActiveSet.solve(qp);
        }
        if self.fresh.replace(false) {
            self.calls.clear();
        }
        let ((iterations, converged), ns) = timed(|| self.inner.solve(qp));
        if self.calls.is_empty() {
            self.first_step = qp.x.first().copied().unwrap_or(0.0);
        }
        self.calls.push(QpCall {
            ns,
            iterations,
            converged,
        });
        (iterations, converged)
    }
}

/// H's upper triangle in compressed sparse columns (column pointers, row
/// indices, values), dense: the form both clarabel and OSQP take.
pub(crate) fn upper_triangle_csc<const N: usize>(
    h: &[[f64; N]; N],
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let mut colptr = Vec::with_capacity(N + 1);
    let mut rowval = Vec::with_capacity(N * (N + 1) / 2);
    let mut nzval = Vec::with_capacity(N * (N + 1) / 2);
    colptr.push(0);
    for c in 0..N {
        for r in 0..=c {
            rowval.push(r);
            nzval.push(h[r][c]);
        }
        colptr.push(rowval.len());
    }
    (colptr, rowval, nzval)
}

#[cfg(test)]
mod tests {
    use super::*;
    use capsule_mpc_runtime::generated::controller::spec;

    fn small_qp() -> BoxQp<3> {
        let mut qp = BoxQp::<3>::new(spec::QP_MAX_ITERATIONS, spec::QP_MULTIPLIER_TOLERANCE);
        qp.h = [[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]];
        qp.g = [-8.0, 1.0, 0.3];
        qp.lo = [-1.0; 3];
        qp.hi = [1.0; 3];
        qp
    }

    #[test]
    fn records_only_armed_calls() {
        let mut t = Timed::new(ActiveSet);
        let mut qp = small_qp();
        let plain = {
            let mut q = small_qp();
            (q.solve(), q.x)
        };
        assert_eq!(t.solve(&mut qp), plain.0);
        assert!(t.calls().is_empty() && t.first_step().is_none());
        t.arm();
        assert!(t.calls().is_empty());
        t.solve(&mut qp);
        t.solve(&mut qp);
        assert_eq!(qp.x, plain.1);
        assert_eq!(t.calls().len(), 2);
        assert_eq!(t.first_step(), Some(plain.1[0]));
        assert!(t.calls().iter().all(|c| c.converged));
        t.disarm();
        t.solve(&mut qp);
        assert_eq!(t.calls().len(), 2);
        t.arm();
        assert!(t.calls().is_empty());
    }

    #[test]
    fn upper_triangle_is_column_major() {
        let h = [[1.0, 2.0], [2.0, 3.0]];
        let (c, r, v) = upper_triangle_csc(&h);
        assert_eq!(
            (c, r, v),
            (vec![0, 1, 3], vec![0, 0, 1], vec![1.0, 2.0, 3.0])
        );
    }
}
