//! The explicit law alone (`refine = none`) on capsules off the model. It
//! answers from the model state similar to theirs
//! (`Solver::set_explicit_similarity`), which is exact while their learned
//! gain-drag products agree. Once they differ no model state is similar:
//! each answer is then played to its end instead of re-solved every cycle
//! from states the stored plans' linearizations misjudge (re-solved, the
//! law cycled about the target 1-2 mm off at 140 mm/s).

use super::numeric::*;
use super::settings::*;
use super::Controller;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Whether the capsules' learned gain-drag products agree: no two
    /// differ by more than `SIMILAR_PRODUCT_AGREEMENT` and by more than
    /// `SCALE_SIGNIFICANCE` standard deviations of their difference (the
    /// similar model state is then nearly exact). The factors' means, not
    /// the significant ones the rollouts use: those switch one capsule at
    /// a time, and in between capsules alike looked apart.
    pub(super) fn learned_products_agree(&self) -> bool {
        let product = |i: usize| {
            let s = &self.est.scales[i];
            let [g, b] = s.mean;
            let var = b * b * s.cov[0] + g * g * s.cov[3] + 2.0 * g * b * s.cov[1];
            (g * b, var)
        };
        (0..NX / 2).all(|i| {
            (i + 1..NX / 2).all(|j| {
                let ((pi, vi), (pj, vj)) = (product(i), product(j));
                let d = libm::fabs(pi - pj);
                d <= SIMILAR_PRODUCT_AGREEMENT * pi.min(pj)
                    || d <= SCALE_SIGNIFICANCE * libm::sqrt(vi + vj)
            })
        })
    }

    /// Whether the law alone under variable sampling plays one sample per
    /// phase on the coasted plans: while the learned products agree and
    /// the gap is the one those plans were solved for (with 10 ms more,
    /// 15-19 of 64 off-model runs of an off-lattice grid did not settle,
    /// against 0-1 with the back-to-back plans in the rule's phases).
    pub(super) fn plays_coasted_plans(&self) -> bool {
        let tables_gap_s = S::TRACKING_TIME_S + S::EXTRA_DELAY_S;
        libm::fabs(self.est.gap_s - tables_gap_s) <= COASTED_GAP_TOLERANCE_S
            && self.learned_products_agree()
    }

    /// The law alone on capsules whose products differ, with a plan still
    /// acting: the report of keeping it (no solve). None: solve.
    pub(super) fn plan_kept_to_its_end(&self) -> Option<SolveReport> {
        if self.settings.refine != Refine::None || self.learned_products_agree() {
            return None;
        }
        let left = acting_samples(
            self.solver.plan(),
            IDLE_GRADIENT_FRACTION * S::U_MAX_T_PER_M,
        );
        (left > 0).then_some(SolveReport {
            status: SolveStatus::Refined,
            cost: self.law.last_cost,
            took_table_plan: false,
            qp_iterations: 0,
            max_qp_iterations: 0,
            tier: Tier::Explicit,
        })
    }
}
