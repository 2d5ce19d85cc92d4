//! The mode's transitions: the one place where the controller decides
//! what a cycle does (see [`Mode`]).

use super::state::Mode;
use super::Controller;
use capsule_mpc_solver::{PlanSolver, SolveReport, SolveStatus};

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// The mode before the solve, from absolute state `x`. In order: no
    /// target; the leg advanced (a waypoint reached); the terminal hold
    /// entered or kept (last leg only, with hysteresis, see
    /// `update_hold`); else follow the plan.
    pub(super) fn next_mode(&mut self, x: &[f64; NX]) -> Mode {
        if !self.sup.has_target {
            return Mode::NoTarget;
        }
        self.advance_leg(x);
        let e = self.relative(x, &self.sup.target);
        if self.sup.on_last_leg && self.update_hold(&e) {
            return Mode::Hold;
        }
        Mode::Plan
    }
}

impl Mode {
    /// The mode after the solve: a state no stored plan covers falls back.
    pub(super) fn after_solve(report: &SolveReport) -> Mode {
        if report.status == SolveStatus::OutOfRange {
            Mode::Fallback
        } else {
            Mode::Plan
        }
    }
}
