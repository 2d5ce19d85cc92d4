//! The mode's transitions: the one place where the controller decides
//! what a cycle does (see [`Mode`]).

use super::state::Mode;
use super::{Controller, Refine};
use capsule_mpc_solver::{PlanSolver, SolveReport, SolveStatus};

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// The mode before the solve, from absolute state `x`. In order: no
    /// target; the leg advanced (a waypoint reached); the terminal hold
    /// entered or kept (last leg only, with hysteresis, see
    /// `update_hold`); a stalled end game (last leg, refinement on, see
    /// `stalled`); else follow the plan.
    pub(super) fn next_mode(&mut self, x: &[f64; NX]) -> Mode {
        if !self.sup.has_target {
            return Mode::NoTarget;
        }
        self.advance_leg(x);
        let e = self.relative(x, &self.sup.target);
        // Actuation time since the last cycle: progress is what the
        // gradient achieves, whatever the tracking phases in between.
        let since_s = self.law.applied_samples.max(1) as f64 * S::DT_S;
        if self.sup.on_last_leg && self.update_hold(&e) {
            return Mode::Hold;
        }
        if self.sup.on_last_leg
            && self.settings.refine != Refine::None
            && self.solver.shot_samples() <= self.law.applied_samples
            && self.stalled(&e, since_s)
        {
            return Mode::Brake;
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
