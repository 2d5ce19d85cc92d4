//! When the solver looks for minimum-time shots, and which ones.

use super::settings::*;
use super::Controller;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Whether the solver looks for minimum-time shots (see
    /// `capsule_mpc_solver::shooting`): wherever one converges, up to the
    /// target, once these settings shoot at all (`Shooting::is_on`; the
    /// explicit tier alone never does). Near the target under the scanner
    /// cycle a shot can arrive with a relative speed the hold cannot stop
    /// (its settling confirm then leaves the hold), but on the learned
    /// factors it is the fastest way back from a hold that cannot hold:
    /// limiting shots to beyond 3 mm was slower off the model
    /// (docs/decisions.md).
    pub(super) fn shots_on(&self) -> bool {
        let s = &self.settings;
        s.shooting.is_on() && s.refine != Refine::None
    }

    /// Whether a refined plan that does not settle within the horizon looks
    /// first for a shot from the stored plan tail (`Solver::set_tail_shots`).
    /// Under ideal sampling always (the full state every sample). Under the
    /// scanner cycle from `SHOTS_CARRY_FROM_CAPSULES` capsules, and only
    /// while the learned factors agree with the ones the loop was given:
    /// the tail's shot is long and plays open loop between frames, so on
    /// capsules the frames show to be off it arrives off (three capsules
    /// with per-capsule factors off the model: 30 instead of 23 of 800
    /// random runs unsettled; two capsules' off-model runs rejected up to
    /// 1.1 % of true frames: docs/decisions.md).
    pub(super) fn tail_shots_wanted(&self) -> bool {
        self.settings.sampling == Sampling::Ideal
            || (NX / 2 >= SHOTS_CARRY_FROM_CAPSULES && !self.factors_differ_from_told())
    }

    /// Whether some capsule's learned gain or drag factor differs from the
    /// one the loop was given (the model's, or a calibration's) by
    /// `SCALE_SIGNIFICANCE` deviations.
    pub(super) fn factors_differ_from_told(&self) -> bool {
        (0..NX / 2)
            .any(|i| self.est.scales[i].differs_from(self.est.told_factors[i], SCALE_SIGNIFICANCE))
    }
}
