//! The scanner-cycle controller: estimator + generated solver + switching
//! rule + fault handling, in one fixed-size struct.

use crate::estimator::{CapsuleFilter, ScaleEstimate, INITIAL_SPEED_STD_M_PER_S};
use crate::switching::{
    extra_deviation_bound, paper_actuation_samples, propagate_error_box, tight_actuation_samples,
    widen_error_box, PaperConstants, TightInputs,
};
use capsule_mpc_solver::shooting::{
    SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S, SHOT_SPEED_TOLERANCE_TRACKED_MANY_M_PER_S,
    SHOT_SPEED_TOLERANCE_TRACKED_M_PER_S,
};
use capsule_mpc_solver::{PlanSolver, SolveReport, SolveStatus, Tier};

mod braking;
mod checks;
mod fusion;
mod hold;
mod hold_frames;
mod law_alone;
mod legs;
mod mode;
mod numeric;
mod settings;
mod shots;
mod stall;
mod state;
mod station;
mod status;
mod third_combination;
mod tracking;

pub use braking::braking_gradient;
use braking::*;
pub use checks::check_workspace;
use checks::*;
use hold_frames::HoldFrames;
use numeric::*;
pub use settings::*;
pub use state::Mode;
use state::{Estimation, LawMemory, Supervision};
pub use station::*;
pub use status::*;

/// The closed loop's whole memory: the solver (plan and workspace), the
/// settings, and the state split by concern (see `state`).
#[derive(Debug, Clone)]
pub struct Controller<S: PlanSolver<NX, K>, const NX: usize, const K: usize> {
    solver: S,
    settings: ControllerSettings,
    est: Estimation<NX>,
    sup: Supervision<NX>,
    law: LawMemory<NX>,
}

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Default settings for this solver (constant sampling, tight rule).
    pub fn default_settings() -> ControllerSettings {
        ControllerSettings {
            sampling: Sampling::Constant,
            // The explicit answer comes first either way; refining it per
            // played sample keeps the closed-loop results measured with
            // the refinement (docs/results.md) and costs at most N solves per cycle
            // inside the tracking phase. `None` is for hosts that need the
            // bounded explicit step alone.
            refine: Refine::PerSample,
            switching: SwitchingRule::Tight,
            compensate_delay: true,
            tracking_time_s: S::TRACKING_TIME_S,
            extra_delay_s: S::EXTRA_DELAY_S,
            position_noise_m: S::POSITION_NOISE_M,
            disturbance_bound: S::DISTURBANCE_BOUND_SI,
            max_actuation_samples: S::N,
            hold_enter_position_m: HOLD_ENTER_POSITION_M,
            hold_enter_speed_m_per_s: HOLD_ENTER_SPEED_M_PER_S,
            hold_release_position_m: HOLD_RELEASE_POSITION_M,
            hold_release_speed_m_per_s: HOLD_RELEASE_SPEED_M_PER_S,
            reacquire_after_rejections: REACQUIRE_AFTER_REJECTIONS,
            glitch_frames: GLITCH_FRAMES,
            model_gain_uncertainty: MODEL_GAIN_UNCERTAINTY,
            model_drag_uncertainty: MODEL_DRAG_UNCERTAINTY,
            shooting: Shooting::Auto,
        }
    }

    /// A controller with every capsule at rest at `positions_m`.
    pub fn new(settings: ControllerSettings, positions_m: &[f64]) -> Result<Self, RuntimeError> {
        const { assert!(NX <= K2 && NX.is_multiple_of(2)) };
        check_settings(&settings, S::N, S::HAS_EXPLICIT_TIER, Self::MAX_GAP_S)?;
        S::verify_tables().map_err(RuntimeError::CorruptTables)?;
        let mut c = Controller {
            solver: S::new(),
            settings,
            est: Estimation::new(
                settings.wait_s(),
                settings.model_gain_uncertainty,
                settings.model_drag_uncertainty,
            ),
            sup: Supervision::new(),
            law: LawMemory {
                applied_samples: 0,
                last_cost: f64::INFINITY,
                planned_phase_samples: settings.max_actuation_samples,
                mean_gain: mean_gradient_gain::<S, NX, K>(),
                station: StationKeeper::new(&capsule_drags::<S, NX, K>()),
                hold_frames: HoldFrames::new(),
                third_direction: [0.0; NX],
                third_frames: HoldFrames::new(),
            },
        };
        // What the hold can stop after a shot depends on the sampling
        // (see the constants).
        c.solver.set_shot_speed_tolerance(match settings.sampling {
            Sampling::Ideal => SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S,
            Sampling::Constant | Sampling::Variable if NX / 2 >= SHOTS_CARRY_FROM_CAPSULES => {
                SHOT_SPEED_TOLERANCE_TRACKED_MANY_M_PER_S
            }
            Sampling::Constant | Sampling::Variable => SHOT_SPEED_TOLERANCE_TRACKED_M_PER_S,
        });
        c.reset(positions_m)?;
        Ok(c)
    }

    /// Restarts the estimate at rest at `positions_m`, keeping the target.
    pub fn reset(&mut self, positions_m: &[f64]) -> Result<(), RuntimeError> {
        let m = NX / 2;
        if positions_m.len() != m {
            return Err(RuntimeError::WrongLength("positions_m"));
        }
        if positions_m.iter().any(|p| !p.is_finite()) {
            return Err(RuntimeError::NonFinite("positions_m"));
        }
        // A start outside the workspace is a wrong argument, as a target
        // there is (the tables cover the workspace, nothing beyond it).
        check_workspace::<S, NX, K>("positions_m", positions_m, 1)?;
        let std = self.settings.position_noise_m.max(1e-6);
        for (i, &p) in positions_m.iter().enumerate() {
            self.est.filters[i] = CapsuleFilter::new(p, std);
        }
        self.est.at_start = true;
        self.seed_start_speeds();
        self.est.gated_rejections = 0;
        self.est.model_drift = [[0.0; 2]; NX];
        self.est.candidate_frames = 0;
        self.est.has_replaced = false;
        self.est.confirmed_frames = 0;
        // A new start: the host's clock restarts too.
        self.est.actuation_end_s = None;
        self.est.full_state_gradient = None;
        self.restart_factor_window();
        self.restart_plan();
        self.sup.forget_mode();
        Ok(())
    }

    /// Forgets the plan and the hold's memory (new start state, new target,
    /// fallback).
    fn restart_plan(&mut self) {
        self.solver.reset();
        // Whatever the hold's frames and a shot asked for on leaving it
        // referred to is gone.
        self.solver.want_shot(0);
        self.law.hold_frames.clear();
        self.law.third_frames.clear();
        self.law.applied_samples = 0;
        self.law.last_cost = f64::INFINITY;
        self.law.station.forget();
        self.forget_stall();
        self.law.planned_phase_samples = self.settings.max_actuation_samples;
        self.update_schedule();
    }

    /// Tells the solver how the plan will be played: ideal sampling plays
    /// it back to back; otherwise each actuation phase is followed by the
    /// zero-gradient gap (tracking + delay) the recent cycles showed.
    fn update_schedule(&mut self) {
        let (samples, coast_s) = self
            .settings
            .schedule_with_gap(self.law.planned_phase_samples, self.est.gap_s);
        self.solver.set_schedule(samples, coast_s);
    }

    /// Samples left of the minimum-time shot being flown (0: none).
    pub fn shot_samples(&self) -> usize {
        self.solver.shot_samples()
    }

    /// Whether the last cycle was in the terminal hold.
    pub fn holding(&self) -> bool {
        self.sup.mode == Mode::Hold
    }

    /// The mode of the last cycle (see [`Mode`]).
    pub fn mode(&self) -> Mode {
        self.sup.mode
    }

    pub fn settings(&self) -> &ControllerSettings {
        &self.settings
    }

    /// Changes when the refinement runs; allowed at any time (no state
    /// depends on it). `Refine::None` needs explicit-tier data:
    /// `BadSetting("refine")` for a solver without tables.
    pub fn set_refine(&mut self, refine: Refine) -> Result<(), RuntimeError> {
        if refine == Refine::None && !S::HAS_EXPLICIT_TIER {
            return Err(RuntimeError::BadSetting("refine"));
        }
        self.settings.refine = refine;
        Ok(())
    }

    /// Turns the minimum-time shots on or off (`ControllerSettings::shooting`);
    /// any time: off drops a shot in flight, the next cycle refines instead.
    pub fn set_shooting(&mut self, on: bool) {
        self.settings.shooting = on.into();
        if !on {
            self.solver.set_shooting(false);
        }
    }

    /// The final target, when set.
    pub fn target(&self) -> Option<&[f64; NX]> {
        self.sup.has_target.then_some(&self.sup.final_target)
    }

    /// The current leg's target: the final target on the last leg, else the
    /// waypoint the capsules are heading for.
    pub fn leg_target(&self) -> Option<&[f64; NX]> {
        self.sup.has_target.then_some(&self.sup.target)
    }

    /// Whether the current leg ends at the final target.
    pub fn on_last_leg(&self) -> bool {
        self.sup.on_last_leg
    }

    /// The current state estimate (absolute, SI).
    pub fn estimate(&self) -> [f64; NX] {
        let mut x = [0.0; NX];
        for i in 0..NX / 2 {
            x[2 * i] = self.est.filters[i].mean[0];
            x[2 * i + 1] = self.est.filters[i].mean[1];
        }
        x
    }

    /// Position standard deviations of the estimate, m (first M entries).
    pub fn filter(&self, capsule: usize) -> Option<&CapsuleFilter> {
        (capsule < NX / 2).then(|| &self.est.filters[capsule])
    }

    /// The estimate of capsule `capsule`'s gain and drag factors against
    /// the model (mean and covariance; 1 = the model), as the estimator and
    /// the refinement use them.
    pub fn model_factors(&self, capsule: usize) -> Option<&ScaleEstimate> {
        (capsule < NX / 2).then(|| &self.est.scales[capsule])
    }

    /// What is known of capsule `capsule`'s gain and drag factors against
    /// the model (e.g. from `capsule-mpc calibrate`): `factors` [gain, drag]
    /// (1 = the model) with standard deviations `std_devs`. They replace
    /// the estimate; the refinement plans with them at once where they
    /// differ from the model significantly, as with learned ones, and the
    /// frames keep refining them. Without it the estimator starts from the
    /// model and learns the factors from frames, which under variable
    /// sampling arrive late (docs/known-limits.md). Kept across `reset` and
    /// new targets. Before the first cycle (after `new` or `reset`) the
    /// gain's deviation also sets the starting speeds' uncertainty (see
    /// `seed_start_speeds`).
    pub fn set_model_factors(
        &mut self,
        capsule: usize,
        factors: [f64; 2],
        std_devs: [f64; 2],
    ) -> Result<(), RuntimeError> {
        if capsule >= NX / 2 {
            return Err(RuntimeError::BadSetting("capsule"));
        }
        if factors.iter().any(|f| !f.is_finite()) {
            return Err(RuntimeError::NonFinite("factors"));
        }
        if std_devs.iter().any(|s| !s.is_finite()) {
            return Err(RuntimeError::NonFinite("std_devs"));
        }
        if factors
            .iter()
            .any(|f| !(MODEL_FACTOR_MIN..=MODEL_FACTOR_MAX).contains(f))
        {
            return Err(RuntimeError::BadSetting("factors"));
        }
        if std_devs
            .iter()
            .any(|s| !(MODEL_FACTOR_STD_MIN..=MODEL_FACTOR_STD_MAX).contains(s))
        {
            return Err(RuntimeError::BadSetting("std_devs"));
        }
        self.est.told_factors[capsule] = factors;
        let scale = &mut self.est.scales[capsule];
        scale.mean = factors;
        scale.cov = [
            std_devs[0] * std_devs[0],
            0.0,
            0.0,
            std_devs[1] * std_devs[1],
        ];
        self.refresh_applied_scales();
        if self.est.at_start {
            self.seed_start_speeds();
        }
        // After the seeding: the window starts from the speeds' new
        // uncertainty.
        self.restart_factor_window();
        Ok(())
    }

    /// The speed uncertainty of capsules at rest at the start: what the
    /// gain's uncertainty puts into the first full-gradient sample
    /// (`INITIAL_SPEED_STD_M_PER_S` under the model's 10 % prior), so that
    /// the first frames correct the speed as much as the model may be off
    /// and no more. A calibrated gain (1 %) trusts the model's speeds that
    /// much more: frame noise (0.2 mm, tens of ms apart) otherwise puts
    /// about 1 mm/s of relative speed into the first arrival, which the
    /// hold cannot remove (docs/decisions.md).
    fn seed_start_speeds(&mut self) {
        for i in 0..NX / 2 {
            let gain_std = libm::sqrt(self.est.scales[i].cov[0].max(0.0));
            let share = (gain_std / MODEL_GAIN_UNCERTAINTY).min(1.0);
            let f = &mut self.est.filters[i];
            f.cov[1] = 0.0;
            f.cov[2] = 0.0;
            f.cov[3] = sq(INITIAL_SPEED_STD_M_PER_S * share);
        }
    }

    /// Sets a new target `[x1, v1, x2, v2, ...]`: positions inside the
    /// workspace, speeds exactly 0 (the plans bring the capsules to rest; a
    /// moving target is refused with `TargetNotAtRest`). Reached from
    /// wherever the capsules are, through waypoints when one stored plan
    /// does not reach (see [`Leg`](capsule_mpc_solver::Leg)); the plan restarts.
    pub fn set_target(&mut self, target: &[f64; NX]) -> Result<(), RuntimeError> {
        if target.iter().any(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFinite("target"));
        }
        if (0..NX / 2).any(|i| target[2 * i + 1] != 0.0) {
            return Err(RuntimeError::TargetNotAtRest);
        }
        check_workspace::<S, NX, K>("target", target, 2)?;
        let x = self.estimate();
        let leg = Self::leg_from(&x, target).ok_or(RuntimeError::TargetOutOfRange)?;
        self.sup.final_target = *target;
        self.sup.has_target = true;
        self.sup.recovering = false;
        self.sup.off_model_confirm_exits = 0;
        self.sup.drift_exits = 0;
        self.sup.third_exits = 0;
        self.apply_leg(&x, &leg);
        self.restart_factor_window();
        self.restart_plan();
        self.sup.forget_mode();
        Ok(())
    }

    fn relative(&self, x: &[f64; NX], target: &[f64; NX]) -> [f64; NX] {
        let mut e = [0.0; NX];
        for j in 0..NX {
            e[j] = x[j] - target[j];
        }
        e
    }

    /// Ideal sampling: the full state `x` is known now; plan one sample.
    /// A state beyond the physical range (`MAX_ABS_POSITION_M`,
    /// `MAX_ABS_SPEED_M_PER_S`) is rejected like an implausible frame: the
    /// estimate is kept and planned from, status `MeasurementRejected`.
    pub fn cycle_full_state(&mut self, x: &[f64; NX]) -> Result<CycleOutput<K>, RuntimeError> {
        if x.iter().any(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFinite("x"));
        }
        let physical = (0..NX / 2).all(|i| {
            libm::fabs(x[2 * i]) <= MAX_ABS_POSITION_M
                && libm::fabs(x[2 * i + 1]) <= MAX_ABS_SPEED_M_PER_S
        });
        let played = self.est.full_state_gradient.take();
        self.est.at_start = false;
        if !physical {
            let kept = self.estimate();
            return Ok(self.plan_from(&kept, RuntimeStatus::MeasurementRejected, 1));
        }
        // Only the shots and the law alone's similar state use the learned
        // factors to advantage: the refinement of the stored plans on them
        // left more targets unsettled (docs/decisions.md).
        let explicit_only = self.settings.refine == Refine::None;
        if let (Some(u), true) = (played, self.shots_on() || explicit_only) {
            self.learn_from_full_state(x, u);
        }
        for i in 0..NX / 2 {
            self.est.filters[i].mean = [x[2 * i], x[2 * i + 1]];
        }
        self.est.gated_rejections = 0;
        self.est.candidate_frames = 0;
        self.est.has_replaced = false;
        self.est.confirmed_frames = self.est.confirmed_frames.saturating_add(1);
        let out = self.plan_from(x, RuntimeStatus::Ok, 1);
        self.est.full_state_gradient = Some(out.gradients_t_per_m[0]);
        Ok(out)
    }

    /// One scanner cycle with the configured timing: the frame
    /// `measured_positions_m` (None: lost) was measured at the end of the
    /// previous actuation phase and the actuation starts
    /// `settings().wait_s()` (tracking + extra delay) later. Returns the
    /// gradients to play from the actuation start and how many samples to
    /// play before the next tracking phase. Hosts whose tracking phases
    /// vary, or that know their clock, use [`Controller::cycle_at`].
    pub fn cycle(
        &mut self,
        measured_positions_m: Option<&[f64]>,
    ) -> Result<CycleOutput<K>, RuntimeError> {
        check_frame_length::<NX>(measured_positions_m)?;
        let wait_s = self.settings.wait_s();
        // No clock: a later `cycle_at` starts a new time base.
        self.est.actuation_end_s = None;
        Ok(self.step(measured_positions_m, 0.0, wait_s, (wait_s, false)))
    }

    /// One cycle from absolute state `x`: the mode's transition, then
    /// that mode's step.
    fn plan_from(&mut self, x: &[f64; NX], status: RuntimeStatus, n_max: usize) -> CycleOutput<K> {
        let mut out = CycleOutput {
            gradients_t_per_m: [0.0; K],
            actuation_samples: 1,
            status,
            solve: None,
            estimate: [0.0; K2],
        };
        out.estimate[..NX].copy_from_slice(x);
        self.sup.mode = self.next_mode(x);
        let mut e = self.relative(x, &self.sup.target);
        match self.sup.mode {
            Mode::NoTarget => out.status = RuntimeStatus::NoTarget,
            Mode::Hold => self.hold_step(&e, &mut out),
            Mode::Brake => self.brake_step(x, &mut out),
            Mode::Plan | Mode::Fallback => {
                let report = self.solve_step(x, &mut e);
                out.solve = Some(report);
                self.sup.mode = Mode::after_solve(&report);
                if self.sup.mode == Mode::Fallback {
                    self.fallback_step(x, &mut out);
                } else {
                    self.play_step(x, &e, &report, n_max, &mut out);
                }
            }
        }
        out
    }

    /// `Hold`: one sample of the hold law.
    fn hold_step(&mut self, e: &[f64; NX], out: &mut CycleOutput<K>) {
        out.gradients_t_per_m[0] = self.hold_gradient(e);
        self.law.applied_samples = 0;
    }

    /// `Brake`: the refinement is swinging the group back and forth
    /// without closing the error (a local minimum of its quadratic cost):
    /// brake, and let the stored plan from rest take over.
    fn brake_step(&mut self, x: &[f64; NX], out: &mut CycleOutput<K>) {
        out.gradients_t_per_m[0] = braking_gradient::<S, NX, K>(x);
        self.solver.reset();
        self.solver.want_shot(0);
        self.law.applied_samples = 0;
    }

    /// `Plan`, first half: shift the plan by what was played, restart it
    /// from the tables when creeping (not while a shot flies), and refine
    /// or re-shoot it from `e`.
    fn solve_step(&mut self, x: &[f64; NX], e: &mut [f64; NX]) -> SolveReport {
        self.solver.shift(self.law.applied_samples);
        self.solver.start_cycle();
        self.solver.set_shooting(self.shots_on());
        self.solver.set_tail_shots(self.tail_shots_wanted());
        if self.solver.shot_samples() == 0 && self.creeping(e) {
            // Nearly at rest and still away from the target: the stored
            // minimum-time plan from here is the best start; a refined plan
            // that creeps on the quadratic cost can take seconds.
            self.solver.reset();
        }
        let report = self.refine_plan(e);
        if report.status != SolveStatus::OutOfRange && self.shoot_through_legs(x, e) {
            *e = self.relative(x, &self.sup.target);
        }
        report
    }

    /// `Fallback`: no plan. The next cycle looks the (braked) state up
    /// again; once every speed is below `REPLAN_SPEED_M_PER_S` (not at
    /// rest: near rest only drag, vanishing as v^2, slows capsules moving
    /// apart) and while frames agree with the estimate, the legs are
    /// re-planned from here and reported as `Recovering` until the last.
    fn fallback_step(&mut self, x: &[f64; NX], out: &mut CycleOutput<K>) {
        out.gradients_t_per_m[0] = braking_gradient::<S, NX, K>(x);
        out.status = RuntimeStatus::Fallback;
        self.law.applied_samples = 0;
        self.restart_plan();
        let slow = (0..NX / 2).all(|i| libm::fabs(x[2 * i + 1]) <= REPLAN_SPEED_M_PER_S);
        if slow && self.est.gated_rejections == 0 && self.replan_legs(x) {
            self.sup.recovering = !self.sup.on_last_leg;
        }
    }

    /// `Plan`, second half: report the solve's status, play the plan and
    /// choose the actuation length.
    fn play_step(
        &mut self,
        x: &[f64; NX],
        e: &[f64; NX],
        report: &SolveReport,
        n_max: usize,
        out: &mut CycleOutput<K>,
    ) {
        if self.sup.recovering && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::Recovering;
        }
        if report.status == SolveStatus::IterationLimit && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::IterationLimit;
        }
        let measured = S::qp_iterations_measured(e);
        if measured > 0 && report.max_qp_iterations > measured && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::AboveIterationMap;
        }
        self.skip_idle_start(x);
        let mut n = self.phase_length(e, n_max);
        if self.settings.sampling == Sampling::Variable {
            if n > self.law.planned_phase_samples && self.settings.refine != Refine::None {
                // The plan was solved for shorter phases (a coast after
                // each): played back to back for n samples it would miss
                // (seen: a 1 cm move whose shot, solved for 1-sample phases,
                // played 6 samples through and arrived 2 mm and 14 mm/s
                // off). Solve it again for phases of n samples; a shot that
                // does not converge for them plays the phases it was
                // solved for.
                n = self.replan_for_phase(x, e, n, n_max);
            }
            // Model (and refine for) the next phase as long as this one:
            // phase lengths change slowly, so the model stays close to what
            // plays.
            self.law.planned_phase_samples = n;
            self.update_schedule();
        }
        for (o, &u) in out.gradients_t_per_m.iter_mut().zip(self.solver.plan()) {
            // The solver keeps |u| <= u_max; clamp again as a last invariant.
            *o = u.clamp(-S::U_MAX_T_PER_M, S::U_MAX_T_PER_M);
        }
        out.actuation_samples = n;
        self.law.applied_samples = n;
        self.law.last_cost = report.cost;
    }

    /// The plan re-solved for phases of `n` samples (see `play_step`);
    /// returns the phase length to play.
    fn replan_for_phase(&mut self, x: &[f64; NX], e: &[f64; NX], n: usize, n_max: usize) -> usize {
        let (samples, coast_s) = self.settings.schedule_with_gap(n, self.est.gap_s);
        let solved_for = self.law.planned_phase_samples;
        let in_flight = self.solver.shot_samples() > 0;
        self.law.planned_phase_samples = n;
        if !self.solver.reschedule_shot(e, samples, coast_s) {
            if in_flight && NX / 2 >= SHOTS_CARRY_FROM_CAPSULES {
                // The shot, its schedule and its plan are as they were.
                self.law.planned_phase_samples = solved_for;
                return solved_for.min(n);
            }
            self.update_schedule();
            if self.solver.solve(e).status == SolveStatus::OutOfRange {
                return n;
            }
        }
        self.skip_idle_start(x);
        n.min(self.phase_length(e, n_max))
    }

    /// At rest an idle sample (and the coast after it) leaves the state as
    /// it is: a plan that starts idle only waits, and re-planned from the
    /// same state it waits again, for ever (seen: a 5 cm move under
    /// constant sampling with 60 ms gaps played zero gradient for 14 s).
    /// Start at its first acting sample instead: from rest that is the same
    /// plan, earlier.
    fn skip_idle_start(&mut self, x: &[f64; NX]) {
        if at_rest(x) {
            let idle = leading_idle_samples(
                self.solver.plan(),
                IDLE_GRADIENT_FRACTION * S::U_MAX_T_PER_M,
            );
            if idle < K {
                self.solver.shift(idle);
            }
        }
    }

    /// Samples to play before the next tracking phase (the switching rule;
    /// 1 when the host allows no more). The law alone under variable
    /// sampling has plans for two schedules only: while the learned
    /// products agree (`SIMILAR_PRODUCT_AGREEMENT`; always on the model)
    /// one sample per phase on the coasted plans, as constant sampling;
    /// else the back-to-back plans in the rule's phases, a plan that ends
    /// within the phase to its end (a coast in the final manoeuvre misses;
    /// the refinement re-solves for the phase instead, `replan_for_phase`).
    fn phase_length(&self, e: &[f64; NX], n_max: usize) -> usize {
        if n_max <= 1 {
            return 1;
        }
        let n_max = n_max.min(S::N);
        let n = self.actuation_length(e, n_max);
        if self.settings.refine == Refine::None && self.settings.sampling == Sampling::Variable {
            if self.plays_coasted_plans() {
                return 1;
            }
            let end = acting_samples(
                self.solver.plan(),
                IDLE_GRADIENT_FRACTION * S::U_MAX_T_PER_M,
            );
            if end > n && end <= n_max {
                return end;
            }
        }
        n
    }

    /// Refines the plan from `e`: one solve (SQP_ITERATIONS Gauss-Newton
    /// steps) per sample the coming phase is expected to play. This is the
    /// real-time iteration argument: constant sampling re-refines the plan
    /// before every played sample, so a plan that variable sampling plays
    /// open loop for n samples gets n refinements too. With one solve per
    /// phase, long phases played barely refined plans, and variable sampling
    /// settled later than constant sampling although its predictions held
    /// to 0.3 mm. Worst case N solves per cycle, inside the tracking time.
    ///
    /// Two tiers: the explicit answer first (no rollout); with
    /// `Refine::None` it is the plan (outside the index: `OutOfRange`, the
    /// fallback). Otherwise the refinement weighs it by its true cost
    /// against the shifted plan and the stored tail and only accepts
    /// decreases, so the refined plan never costs more than the explicit
    /// one. The report's `tier` names the tier that produced the plan.
    fn refine_plan(&mut self, e: &[f64; NX]) -> SolveReport {
        let rounds = match (self.settings.refine, self.settings.sampling) {
            (Refine::None, _) => 0,
            (Refine::Once, _) => 1,
            (Refine::PerSample, Sampling::Variable) => self.law.planned_phase_samples.max(1),
            (Refine::PerSample, Sampling::Ideal | Sampling::Constant) => 1,
        };
        if let Some(kept) = self.plan_kept_to_its_end() {
            return kept;
        }
        let explicit = if S::HAS_EXPLICIT_TIER {
            self.solver.set_explicit_similarity(rounds == 0);
            Some(self.solver.solve_explicit(e))
        } else {
            None
        };
        if rounds == 0 {
            // check_settings refuses Refine::None without explicit data.
            let report = explicit.unwrap_or(SolveReport {
                status: SolveStatus::OutOfRange,
                cost: f64::INFINITY,
                took_table_plan: false,
                qp_iterations: 0,
                max_qp_iterations: 0,
                tier: Tier::Explicit,
            });
            if report.status != SolveStatus::OutOfRange {
                self.solver.adopt_explicit();
            }
            return report;
        }
        // The report counts the refinement's QPs only: the offline QP
        // iteration map it is checked against measured those.
        let mut report = self.solver.solve(e);
        for _ in 1..rounds {
            // A converged shot is already the answer from this state; the
            // cycle's compute budget bounds the rounds.
            if report.status == SolveStatus::OutOfRange
                || self.solver.shot_samples() > 0
                || !self.solver.refinement_fits()
            {
                break;
            }
            let r = self.solver.solve(e);
            report.cost = r.cost;
            report.tier = r.tier;
            report.took_table_plan |= r.took_table_plan;
            report.qp_iterations += r.qp_iterations;
            report.max_qp_iterations = report.max_qp_iterations.max(r.max_qp_iterations);
            if r.status == SolveStatus::IterationLimit {
                report.status = SolveStatus::IterationLimit;
            }
        }
        report
    }

    /// Switching rule along the predicted plan from `e`.
    fn actuation_length(&self, e: &[f64; NX], n_max: usize) -> usize {
        let plan = self.solver.plan();
        let mut costs = [0.0; K];
        let mut grads = [0.0; K];
        let mut deviation = [0.0; K];
        // Q recovered once from the stage cost of unit vectors (the spec's
        // weights, not a second copy of them).
        let mut q = [0.0; NX];
        let mut q_max: f64 = 0.0;
        for (j, qj) in q.iter_mut().enumerate() {
            let mut unit = [0.0; NX];
            unit[j] = 1.0;
            *qj = S::stage_cost(&unit, 0.0);
            q_max = q_max.max(*qj);
        }
        // The estimate's 3-sigma box per capsule, propagated along the plan.
        let mut start = [[0.0; 2]; K2];
        for (b, f) in start.iter_mut().zip(&self.est.filters) {
            *b = [3.0 * f.position_std_m(), 3.0 * f.speed_std_m_per_s()];
        }
        let mut boxes = start;
        let gamma_dt = self.settings.disturbance_bound * S::DT_S;
        // Near the target on capsules the frames have shown to be off the
        // factors the loop was given, the factors' remaining uncertainty
        // grows the error too.
        let cautious = (0..NX / 2).all(|i| libm::fabs(e[2 * i]) < ARRIVAL_REGION_M)
            && self.factors_differ_from_told();
        let mut state = *e;
        for (k, &u) in plan.iter().enumerate() {
            costs[k] = S::stage_cost(&state, u);
            // |grad (e'Qe)| = |2 Q e|.
            let mut g2 = 0.0;
            for j in 0..NX {
                g2 += sq(2.0 * q[j] * state[j]);
            }
            grads[k] = libm::sqrt(g2);
            for i in 0..NX / 2 {
                let (_, a) = S::capsule_transition(i, [state[2 * i], state[2 * i + 1]], u, S::DT_S);
                boxes[i] = propagate_error_box(&a, boxes[i], gamma_dt);
                if cautious {
                    let model_error = self.est.scales[i].model_error_accel(
                        self.est.applied_scales[i],
                        S::capsule_gain(i) * u,
                        S::capsule_drag(i, state[2 * i + 1]),
                    );
                    boxes[i] = widen_error_box(boxes[i], model_error, S::DT_S);
                }
            }
            deviation[k] = extra_deviation_bound(&boxes[..NX / 2], &start[..NX / 2]);
            state = S::predict_plan(&state, &single(u), 1);
        }
        match self.settings.switching {
            SwitchingRule::Paper => {
                let c = PaperConstants {
                    l_f: S::L_F,
                    l_l: S::L_L,
                    l_v: S::L_V,
                    x_diameter: S::X_DIAMETER,
                    gamma: self.settings.disturbance_bound,
                    sigma: S::SWITCHING_SIGMA,
                };
                paper_actuation_samples(&c, &costs[..n_max], S::DT_S, S::N as f64 * S::DT_S)
            }
            SwitchingRule::Tight => {
                let inp = TightInputs {
                    stage_costs: &costs,
                    cost_gradients: &grads,
                    extra_deviation: &deviation,
                    q_max,
                    sigma: S::SWITCHING_SIGMA,
                };
                tight_actuation_samples(&inp, n_max)
            }
        }
    }
}
