//! Legs of a move: a target one stored plan does not reach is reached
//! through waypoints (chained rest-to-rest plans, see the generator's
//! `legs`), or, once a shot through them converges, without stopping at
//! them (`shoot_through_legs`).

use super::braking::at_rest;
use super::settings::*;
use super::Controller;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// The next leg from the capsules' positions in `x` to `target`. A
    /// displacement beyond the chain table (the state outside the
    /// workspace, e.g. after a fault) is clamped to it: the first leg of
    /// the clamped displacement still moves every capsule toward its
    /// target and no farther, and is never the last.
    pub(super) fn leg_from(x: &[f64; NX], target: &[f64; NX]) -> Option<Leg<NX>> {
        let span_m = S::WORKSPACE_MAX_M - S::WORKSPACE_MIN_M;
        let mut d = [0.0; NX];
        let mut clamped = false;
        for i in 0..NX / 2 {
            let raw = x[2 * i] - target[2 * i];
            d[2 * i] = raw.clamp(-span_m, span_m);
            clamped |= d[2 * i] != raw;
        }
        let mut leg = S::first_leg(&d)?;
        if clamped {
            leg.last = false;
        }
        Some(leg)
    }

    /// Heads for the end of `leg`, starting from `x`.
    pub(super) fn apply_leg(&mut self, x: &[f64; NX], leg: &Leg<NX>) {
        self.sup.on_last_leg = leg.last;
        if leg.last {
            self.sup.recovering = false;
        }
        if leg.last {
            self.sup.target = self.sup.final_target;
        } else {
            for i in 0..NX / 2 {
                self.sup.target[2 * i] = x[2 * i] - leg.start_offset_m[2 * i];
                self.sup.target[2 * i + 1] = 0.0;
            }
        }
    }

    /// On a waypoint leg (`e` relative to the waypoint), shots on: one
    /// shot from `x` to the final target through the rest of the chain
    /// (see `PlanSolver::shoot_through_chain`), flown without stopping at
    /// the waypoints. True when it converges: the move is on its last leg.
    /// Under the scanner cycle from `SHOTS_CARRY_FROM_CAPSULES` capsules
    /// only: two capsules' legs let the estimator learn the factors before
    /// the final approach, and off the model their shot through arrived
    /// with relative speeds the hold could not stop (worst settles up to
    /// 1.1 s later, docs/decisions.md).
    pub(super) fn shoot_through_legs(&mut self, x: &[f64; NX], e: &[f64; NX]) -> bool {
        let scanner = self.settings.sampling != Sampling::Ideal;
        if self.sup.on_last_leg
            || !self.shots_on()
            || (scanner && NX / 2 < SHOTS_CARRY_FROM_CAPSULES)
        {
            return false;
        }
        // Without a shot in flight the chain starts here, from rest.
        if self.solver.shot_samples() == 0 && !at_rest(x) {
            return false;
        }
        let e_final = self.relative(x, &self.sup.final_target);
        if !self.solver.shoot_through_chain(e, &e_final) {
            return false;
        }
        self.sup.on_last_leg = true;
        self.sup.recovering = false;
        self.sup.target = self.sup.final_target;
        true
    }

    /// On a waypoint leg: once the capsules are near the waypoint, nearly at
    /// rest, head for the next leg (true when the leg changed).
    pub(super) fn advance_leg(&mut self, x: &[f64; NX]) -> bool {
        if self.sup.on_last_leg {
            return false;
        }
        let e = self.relative(x, &self.sup.target);
        let arrived = (0..NX / 2).all(|i| {
            libm::fabs(e[2 * i]) <= WAYPOINT_POSITION_M
                && libm::fabs(e[2 * i + 1]) <= WAYPOINT_SPEED_M_PER_S
        });
        if !arrived {
            return false;
        }
        self.replan_legs(x)
    }

    /// Re-plans the legs from the capsules' positions in `x` (true when a
    /// chain exists; else the current leg is kept).
    pub(super) fn replan_legs(&mut self, x: &[f64; NX]) -> bool {
        match Self::leg_from(x, &self.sup.final_target) {
            Some(leg) => {
                self.apply_leg(x, &leg);
                self.restart_plan();
                true
            }
            None => false,
        }
    }

    /// Nearly at rest away from the target, where a stored plan from here
    /// beats refining: every speed below `REPLAN_SPEED_M_PER_S` with some
    /// position error beyond `WAYPOINT_POSITION_M` (main grid), or every
    /// speed below the settle tolerance with some error beyond the hold's
    /// entry (the fine grid of the end game).
    pub(super) fn creeping(&self, e: &[f64; NX]) -> bool {
        let below = |speed: f64| (0..NX / 2).all(|i| libm::fabs(e[2 * i + 1]) <= speed);
        let beyond = |position: f64| (0..NX / 2).any(|i| libm::fabs(e[2 * i]) > position);
        (below(REPLAN_SPEED_M_PER_S) && beyond(WAYPOINT_POSITION_M))
            || (below(REST_SPEED_M_PER_S) && beyond(self.settings.hold_enter_position_m))
    }
}
