//! Stall detection: the end game moving near the target without getting
//! nearer (mode `Brake`, see `Controller::next_mode`).

use super::settings::*;
use super::Controller;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Whether the end game has stalled: moving (some speed above
    /// `REST_SPEED_M_PER_S`) within `STALL_REGION_M` of the target while
    /// the largest position error has not shrunk by `STALL_PROGRESS` for
    /// `STALL_S` of actuation (`since_s`: actuation time since the last
    /// cycle). Seen on a 5 cm move under constant sampling: at 3 mm
    /// relative error the refinement reversed the group at 37 mm/s every
    /// 0.2 s for 0.9 s without changing it.
    pub(super) fn stalled(&mut self, e: &[f64; NX], since_s: f64) -> bool {
        // Position error plus the distance each capsule's speed covers in
        // `STALL_LOOKAHEAD_S`: passing through the target at speed (normal
        // in a separating manoeuvre) is not progress.
        let mut largest_m: f64 = 0.0;
        let mut moving = false;
        for i in 0..NX / 2 {
            let speed = libm::fabs(e[2 * i + 1]);
            largest_m = largest_m.max(libm::fabs(e[2 * i]) + STALL_LOOKAHEAD_S * speed);
            moving |= speed > REST_SPEED_M_PER_S;
        }
        if largest_m > STALL_REGION_M || !moving {
            self.forget_stall();
            return false;
        }
        if largest_m < STALL_PROGRESS * self.sup.stall_best_m {
            self.sup.stall_best_m = largest_m;
            self.sup.stall_clock_s = 0.0;
            return false;
        }
        self.sup.stall_clock_s += since_s;
        if self.sup.stall_clock_s < STALL_S {
            return false;
        }
        self.forget_stall();
        true
    }

    pub(super) fn forget_stall(&mut self) {
        self.sup.stall_best_m = f64::INFINITY;
        self.sup.stall_clock_s = 0.0;
    }
}
