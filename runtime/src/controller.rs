//! The scanner-cycle controller: estimator + generated solver + switching
//! rule + fault handling, in one fixed-size struct.

use crate::estimator::{CapsuleFilter, REACQUIRE_SPEED_STD_M_PER_S};
use crate::switching::{
    extra_deviation_bound, paper_actuation_samples, propagate_error_box, tight_actuation_samples,
    PaperConstants, TightInputs,
};
use capsule_mpc_generated::{Leg, PlanSolver, SolveReport, SolveStatus};

/// How the scanner interleaves tracking and actuation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampling {
    /// Every sample actuates and the full state is known instantly (the
    /// paper's nominal idealization).
    Ideal,
    /// One actuation sample per tracking phase (Fig. 2a).
    Constant,
    /// The switching rule chooses the actuation length (Fig. 2b).
    Variable,
}

/// Which switching rule `Sampling::Variable` uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwitchingRule {
    /// Condition (17) with the worst-case constants of the paper.
    Paper,
    /// The local-bound variant (see [`crate::switching`]).
    Tight,
}

/// Settings; defaults come from the generated spec.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerSettings {
    pub sampling: Sampling,
    pub switching: SwitchingRule,
    /// Predict the state through tracking + delay before solving (true), or
    /// solve from the measured state and treat the delay as a disturbance
    /// (false, the paper's way).
    pub compensate_delay: bool,
    /// Tracking phase duration, s: the fixed timing of
    /// [`Controller::cycle`], and the gap the plans model until
    /// [`Controller::cycle_at`] has measured one.
    pub tracking_time_s: f64,
    /// Extra compute/transfer delay after tracking, s (as `tracking_time_s`).
    pub extra_delay_s: f64,
    /// Measurement noise standard deviation, m.
    pub position_noise_m: f64,
    /// Disturbance bound gamma, SI (m/s and m/s^2 on the state derivative).
    pub disturbance_bound: f64,
    /// Largest actuation length, samples (<= N).
    pub max_actuation_samples: usize,
    /// Terminal hold (dual-mode MPC): entered when every estimated position
    /// error is within `hold_enter_position_m` and every speed within
    /// `hold_enter_speed_m_per_s`; left when a position error exceeds
    /// `hold_release_position_m` or a speed `hold_release_speed_m_per_s`.
    /// Inside, a gentle linear law damps the capsules' common motion instead
    /// of re-planning separation manoeuvres for errors at the noise level.
    pub hold_enter_position_m: f64,
    pub hold_enter_speed_m_per_s: f64,
    pub hold_release_position_m: f64,
    pub hold_release_speed_m_per_s: f64,
    /// Re-acquisition: after this many gated-out frames in a row (finite,
    /// within `MAX_ABS_POSITION_M`, but beyond `MEASUREMENT_GATE_NIS` of the
    /// estimate) that agree with one another, with no accepted frame in
    /// between, the estimate is taken to be wrong (e.g. a `reset` to the
    /// wrong place) and is restarted from those frames: positions and
    /// speeds from a filter run over them (see `glitch_frames` for an
    /// established estimate). Lost and invalid frames neither count nor
    /// break the run. 0 disables re-acquisition; 1 is refused (every single
    /// outlier would restart the estimate).
    pub reacquire_after_rejections: usize,
    /// Tracking glitches: an estimate confirmed by at least
    /// `ESTABLISHED_AFTER_FRAMES` accepted frames since the last `reset` or
    /// re-acquisition is a physical track that cannot jump, so gated-out
    /// frames that contradict it, even when they agree with one another,
    /// are taken for a glitch of the tracking and rejected for up to this
    /// many frames in a row; the next one re-acquires (never before
    /// `reacquire_after_rejections`).
    pub glitch_frames: usize,
}
impl ControllerSettings {
    /// Tracking phase + extra delay: the zero-gradient wait between a
    /// measurement and the actuation it leads to, s.
    pub fn wait_s(&self) -> f64 {
        self.tracking_time_s + self.extra_delay_s
    }

    /// The actuation schedule the solver models under these settings:
    /// (samples per actuation phase, zero-gradient coast after each phase
    /// in s). Ideal sampling has no coast (samples back to back); constant
    /// sampling plays one sample per phase; variable sampling plays
    /// `phase_samples`.
    pub fn schedule(&self, phase_samples: usize) -> (usize, f64) {
        self.schedule_with_gap(phase_samples, self.wait_s())
    }

    /// [`ControllerSettings::schedule`] with a zero-gradient gap of `gap_s`
    /// between phases instead of the configured `wait_s()` (the gap the
    /// host's time stamps show, see `Controller::cycle_at`).
    pub fn schedule_with_gap(&self, phase_samples: usize, gap_s: f64) -> (usize, f64) {
        match self.sampling {
            Sampling::Ideal => (phase_samples, 0.0),
            Sampling::Constant => (1, gap_s),
            Sampling::Variable => (phase_samples, gap_s),
        }
    }
}

/// Default hold entry: 0.7 of the 1 mm settle tolerance, m.
pub const HOLD_ENTER_POSITION_M: f64 = 0.7e-3;
/// Default hold entry speed: 0.8 of the 5 mm/s settle tolerance, m/s.
pub const HOLD_ENTER_SPEED_M_PER_S: f64 = 4.0e-3;
/// Default hold release: 0.8 of the settle tolerance, m (hysteresis keeps
/// estimate noise from toggling the mode).
pub const HOLD_RELEASE_POSITION_M: f64 = 1.0e-3;
/// Default hold release speed, m/s.
pub const HOLD_RELEASE_SPEED_M_PER_S: f64 = 10.0e-3;
/// How far ahead the hold entry extrapolates the capsules' relative drift, s.
pub const HOLD_DRIFT_HORIZON_S: f64 = 1.0;
/// Natural frequency of the hold law, rad/s (critically damped).
pub const HOLD_NATURAL_FREQUENCY_RAD_PER_S: f64 = 6.0;
/// The hold law uses at most this fraction of u_max.
pub const HOLD_MAX_GRADIENT_FRACTION: f64 = 0.25;
/// Default re-acquisition count, frames: 0.2 s at the default constant
/// sampling (20 ms actuation + 20 ms tracking per frame). Five gross
/// outliers in a row, with none of the frames between them accepted, are
/// far likelier a wrong estimate than wrong data.
pub const REACQUIRE_AFTER_REJECTIONS: usize = 5;
/// Default `ControllerSettings::glitch_frames`: 0.8 s of tracking frames at
/// the default constant sampling.
pub const GLITCH_FRAMES: usize = 20;
/// Accepted frames after which an estimate counts as established (see
/// `ControllerSettings::glitch_frames`).
pub const ESTABLISHED_AFTER_FRAMES: usize = 2;

/// Largest gap between the end of one actuation phase and the start of
/// the next that `Controller::cycle_at` accepts, s. Tracking phases are
/// tens of ms; a longer pause means the loop stopped (call `reset`).
pub const MAX_CYCLE_GAP_S: f64 = 1.0;
/// How far a measurement time may precede the end of the previous
/// actuation phase (clock rounding between host and controller), s. Within
/// it the measurement is taken at the actuation end.
pub const TIME_TOLERANCE_S: f64 = 1.0e-3;
/// Weight of the newest gap in the running estimate of the tracking gap
/// the plans model (exponential smoothing): jittering tracking phases are
/// modelled by about their mean, a change of length is followed within a
/// few cycles.
pub const GAP_SMOOTHING: f64 = 0.3;
/// Speed below which the fallback considers a capsule at rest, m/s (the
/// settle tolerance).
pub const REST_SPEED_M_PER_S: f64 = 5.0e-3;
/// Coasting horizon the fallback's braking law minimizes the drift over, s.
pub const BRAKING_HORIZON_S: f64 = 1.0;
/// After re-acquisition the estimate it replaced is kept as an alternative
/// (a frame glitch re-acquires onto the glitch; when true frames return
/// they match the replaced estimate) until its position uncertainty
/// exceeds this, m.
pub const REPLACED_TRACK_MAX_STD_M: f64 = 5.0e-3;

/// An accepted frame whose normalized innovation squared (summed over the
/// capsules) exceeds this (3 sigma) keeps the estimate before it as the
/// replaced track (see `REPLACED_TRACK_MAX_STD_M`); a gated-out frame
/// within it of the replaced track restores that track.
pub const REPLACED_TRACK_NIS: f64 = 9.0;

/// A waypoint counts as reached when every position is within this of it, m
/// (the next leg's plan absorbs the residual).
pub const WAYPOINT_POSITION_M: f64 = 2.0e-3;
/// ... and every speed below this, m/s.
pub const WAYPOINT_SPEED_M_PER_S: f64 = 20.0e-3;
/// Speed below which the end game restarts from a fine stored plan, m/s
/// (the settle tolerance).
pub const END_GAME_REST_SPEED_M_PER_S: f64 = 5.0e-3;
/// Braking outside the tables re-plans the legs once every speed is below
/// this, m/s (the stored plans start at rest).
pub const REPLAN_SPEED_M_PER_S: f64 = 20.0e-3;

/// Normalized innovation squared above which a measurement is rejected
/// (5 sigma: with Gaussian tracking noise about one frame in two million;
/// glitches of a few mm at rest are caught, see `glitch_frames`).
pub const MEASUREMENT_GATE_NIS: f64 = 25.0;
/// Positions farther than this from the origin are not physical, m.
pub const MAX_ABS_POSITION_M: f64 = 1.0;
/// Speeds above this are not physical, m/s (terminal speeds at u_max: 0.23
/// and 0.64 m/s for the default capsules). The estimator's model is not
/// integrated there: its RK4 prediction overflows to NaN from about 2 m/s,
/// and a NaN estimate would reject every later frame.
pub const MAX_ABS_SPEED_M_PER_S: f64 = 1.0;
/// Floor on the estimator's process noise (acceleration PSD, (m/s^2)^2 s):
/// model error is never exactly zero.
pub const MIN_ACCEL_PSD: f64 = 1.0e-6;

/// Status of one cycle (the plan is always usable and within |u| <= u_max).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub enum RuntimeStatus {
    Ok = 0,
    /// The state is outside the tables: one braking sample (see
    /// [`braking_gradient`]), never an extrapolated table value. The next
    /// cycle looks the state up again; at rest outside the tables it starts
    /// a recovery leg (`Recovering`).
    Fallback = 1,
    /// A QP hit its iteration bound; the best feasible plan was used.
    IterationLimit = 2,
    /// The measurement was non-finite, beyond `MAX_ABS_POSITION_M`, beyond
    /// the innovation gate, or part of a glitch (see
    /// `ControllerSettings::glitch_frames`), and was ignored: the estimate
    /// was predicted only.
    MeasurementRejected = 3,
    /// No measurement this cycle: the estimate was predicted only.
    MeasurementLost = 4,
    /// No target set: zero gradient.
    NoTarget = 5,
    /// The estimate jumped: `reacquire_after_rejections` gated-out frames
    /// in a row that agree with one another (`glitch_frames` + 1 against an
    /// established estimate) replaced it, with the positions and speeds they
    /// show; or frames returned to the estimate the last re-acquisition
    /// replaced (a glitch ended) and it was restored. The plan restarted.
    /// Reported for that one cycle whatever the plan (which may be the
    /// fallback or, without a target, zero).
    Reacquired = 6,
    /// A QP of this solve took more active-set iterations than the offline
    /// map (`capsule-mpc generate`) measured in the state's index cell: the
    /// plan converged and is used, but the state lies outside what the
    /// offline worst-case timing covered.
    AboveIterationMap = 7,
    /// The state was outside the tables' range at rest (after the fallback
    /// braked it): the controller is moving the capsules along a stored plan
    /// to an intermediate point from which the tables reach the target
    /// (one or more legs), then plans to the target itself.
    Recovering = 8,
}

/// Errors of calls with bad arguments (nothing changes when one is returned).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RuntimeError {
    /// A value was NaN or infinite; names the argument.
    NonFinite(&'static str),
    /// A slice had the wrong length; names the argument.
    WrongLength(&'static str),
    /// The target cannot be reached from the current state with the stored
    /// plans, even chained (only when the estimate lies outside the
    /// workspace the tables were made for).
    TargetOutOfRange,
    /// A position lies outside the workspace `[S::WORKSPACE_MIN_M,
    /// S::WORKSPACE_MAX_M]`: names the argument, the capsule (0-based) and
    /// by how much (m; negative below the box, positive above).
    OutsideWorkspace {
        argument: &'static str,
        capsule: usize,
        excess_m: f64,
    },
    /// A setting is out of its range; names it.
    BadSetting(&'static str),
    /// A time stamp is implausible: before the previous actuation ended
    /// (time going backwards), an actuation start before its measurement,
    /// or a gap above `MAX_CYCLE_GAP_S`; names the argument.
    BadTime(&'static str),
    /// A target speed is not zero: the plans bring the capsules to rest.
    TargetNotAtRest,
}

/// What one cycle returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput<const K: usize> {
    /// Gradient per sample, T/m; the first `actuation_samples` are to be played.
    pub gradients_t_per_m: [f64; K],
    pub actuation_samples: usize,
    pub status: RuntimeStatus,
    /// The solver's report (None for fallback / no target).
    pub solve: Option<SolveReport>,
    /// Estimated state at the actuation start (absolute, SI).
    pub estimate: [f64; K2],
}

/// Room for the estimate in [`CycleOutput`] (2 x the maximum capsule count).
pub const K2: usize = 16;

/// The closed loop's whole memory.
#[derive(Debug, Clone)]
pub struct Controller<S: PlanSolver<NX, K>, const NX: usize, const K: usize> {
    solver: S,
    settings: ControllerSettings,
    filters: [CapsuleFilter; NX],
    /// Target of the current leg (the final target on the last leg, else
    /// a waypoint), absolute SI.
    target: [f64; NX],
    /// Where the capsules are to end, absolute SI.
    final_target: [f64; NX],
    /// Whether the current leg ends at `final_target`.
    on_last_leg: bool,
    has_target: bool,
    /// Plan samples applied since the last solve.
    applied_samples: usize,
    /// Last solver cost, for the decrease check (18).
    last_cost: f64,
    /// Inside the terminal hold set (see [`ControllerSettings`]).
    holding: bool,
    /// Samples per actuation phase the plan is refined for.
    planned_phase_samples: usize,
    /// Mean acceleration per unit gradient near rest, (m/s^2)/(T/m): fixed
    /// by the model, computed once for the hold law.
    mean_gain: f64,
    /// Gated-out frames since the last accepted one (see
    /// `ControllerSettings::reacquire_after_rejections`).
    gated_rejections: usize,
    /// Re-acquisition candidate: a filter started at the first gated-out
    /// frame and updated with the gated-out frames that agree with it, so
    /// that a re-acquired estimate has speeds from the frames.
    candidate: [CapsuleFilter; NX],
    /// Frames the candidate has absorbed (0: none).
    candidate_frames: usize,
    /// The estimate the last re-acquisition replaced, predicted along (see
    /// `REPLACED_TRACK_MAX_STD_M`).
    replaced: [CapsuleFilter; NX],
    has_replaced: bool,
    /// Frames accepted since the last `reset` or re-acquisition (see
    /// `ControllerSettings::glitch_frames`).
    confirmed_frames: usize,
    /// The legs were re-planned after a fallback (`Recovering` until the
    /// last leg).
    recovering: bool,
    /// End of the last actuation phase on the host's clock, s (`cycle_at`;
    /// None before the first timed cycle, after `reset` and after `cycle`).
    actuation_end_s: Option<f64>,
    /// Running estimate of the zero-gradient gap between actuation phases
    /// (tracking + delay), s: the coast the plans model.
    gap_s: f64,
}

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Default settings for this solver (constant sampling, tight rule).
    pub fn default_settings() -> ControllerSettings {
        ControllerSettings {
            sampling: Sampling::Constant,
            switching: SwitchingRule::Tight,
            compensate_delay: true,
            tracking_time_s: S::TRACKING_TIME_S,
            extra_delay_s: S::EXTRA_DELAY_S,
            position_noise_m: S::POSITION_NOISE_M,
            disturbance_bound: 0.0,
            max_actuation_samples: S::N,
            hold_enter_position_m: HOLD_ENTER_POSITION_M,
            hold_enter_speed_m_per_s: HOLD_ENTER_SPEED_M_PER_S,
            hold_release_position_m: HOLD_RELEASE_POSITION_M,
            hold_release_speed_m_per_s: HOLD_RELEASE_SPEED_M_PER_S,
            reacquire_after_rejections: REACQUIRE_AFTER_REJECTIONS,
            glitch_frames: GLITCH_FRAMES,
        }
    }

    /// A controller with every capsule at rest at `positions_m`.
    pub fn new(settings: ControllerSettings, positions_m: &[f64]) -> Result<Self, RuntimeError> {
        const { assert!(NX <= K2 && NX.is_multiple_of(2)) };
        check_settings(&settings, S::N)?;
        let mut c = Controller {
            solver: S::new(),
            settings,
            filters: [CapsuleFilter::new(0.0, 0.0); NX],
            target: [0.0; NX],
            final_target: [0.0; NX],
            on_last_leg: true,
            has_target: false,
            applied_samples: 0,
            last_cost: f64::INFINITY,
            holding: false,
            planned_phase_samples: settings.max_actuation_samples,
            mean_gain: mean_gradient_gain::<S, NX, K>(),
            gated_rejections: 0,
            candidate: [CapsuleFilter::new(0.0, 0.0); NX],
            candidate_frames: 0,
            replaced: [CapsuleFilter::new(0.0, 0.0); NX],
            has_replaced: false,
            confirmed_frames: 0,
            recovering: false,
            actuation_end_s: None,
            gap_s: settings.wait_s(),
        };
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
        let std = self.settings.position_noise_m.max(1e-6);
        for (i, &p) in positions_m.iter().enumerate() {
            self.filters[i] = CapsuleFilter::new(p, std);
        }
        self.gated_rejections = 0;
        self.candidate_frames = 0;
        self.has_replaced = false;
        self.confirmed_frames = 0;
        // A new start: the host's clock restarts too.
        self.actuation_end_s = None;
        self.restart_plan();
        Ok(())
    }

    /// Forgets the plan and the mode (new start state or new target).
    fn restart_plan(&mut self) {
        self.solver.reset();
        self.applied_samples = 0;
        self.last_cost = f64::INFINITY;
        self.holding = false;
        self.planned_phase_samples = self.settings.max_actuation_samples;
        self.update_schedule();
    }

    /// Tells the solver how the plan will be played: ideal sampling plays
    /// it back to back; otherwise each actuation phase is followed by the
    /// zero-gradient gap (tracking + delay) the recent cycles showed.
    fn update_schedule(&mut self) {
        let (samples, coast_s) = self
            .settings
            .schedule_with_gap(self.planned_phase_samples, self.gap_s);
        self.solver.set_schedule(samples, coast_s);
    }

    /// Whether the last cycle was in the terminal hold.
    pub fn holding(&self) -> bool {
        self.holding
    }

    pub fn settings(&self) -> &ControllerSettings {
        &self.settings
    }

    /// The final target, when set.
    pub fn target(&self) -> Option<&[f64; NX]> {
        self.has_target.then_some(&self.final_target)
    }

    /// The current leg's target: the final target on the last leg, else the
    /// waypoint the capsules are heading for.
    pub fn leg_target(&self) -> Option<&[f64; NX]> {
        self.has_target.then_some(&self.target)
    }

    /// Whether the current leg ends at the final target.
    pub fn on_last_leg(&self) -> bool {
        self.on_last_leg
    }

    /// The current state estimate (absolute, SI).
    pub fn estimate(&self) -> [f64; NX] {
        let mut x = [0.0; NX];
        for i in 0..NX / 2 {
            x[2 * i] = self.filters[i].mean[0];
            x[2 * i + 1] = self.filters[i].mean[1];
        }
        x
    }

    /// Position standard deviations of the estimate, m (first M entries).
    pub fn filter(&self, capsule: usize) -> Option<&CapsuleFilter> {
        (capsule < NX / 2).then(|| &self.filters[capsule])
    }

    /// Sets a new target `[x1, v1, x2, v2, ...]`: positions inside the
    /// workspace, speeds exactly 0 (the plans bring the capsules to rest; a
    /// moving target is refused with `TargetNotAtRest`). Reached from
    /// wherever the capsules are, through waypoints when one stored plan
    /// does not reach (see [`Leg`]); the plan restarts.
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
        self.final_target = *target;
        self.has_target = true;
        self.recovering = false;
        self.apply_leg(&x, &leg);
        self.restart_plan();
        Ok(())
    }

    /// The next leg from the capsules' positions in `x` to `target`. A
    /// displacement beyond the chain table (the state outside the
    /// workspace, e.g. after a fault) is clamped to it: the first leg of
    /// the clamped displacement still moves every capsule toward its
    /// target and no farther, and is never the last.
    fn leg_from(x: &[f64; NX], target: &[f64; NX]) -> Option<Leg<NX>> {
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
    fn apply_leg(&mut self, x: &[f64; NX], leg: &Leg<NX>) {
        self.on_last_leg = leg.last;
        if leg.last {
            self.recovering = false;
        }
        if leg.last {
            self.target = self.final_target;
        } else {
            for i in 0..NX / 2 {
                self.target[2 * i] = x[2 * i] - leg.start_offset_m[2 * i];
                self.target[2 * i + 1] = 0.0;
            }
        }
    }

    /// On a waypoint leg: once the capsules are near the waypoint, nearly at
    /// rest, head for the next leg (true when the leg changed).
    fn advance_leg(&mut self, x: &[f64; NX]) -> bool {
        if self.on_last_leg {
            return false;
        }
        let e = self.relative(x, &self.target);
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
    fn replan_legs(&mut self, x: &[f64; NX]) -> bool {
        match Self::leg_from(x, &self.final_target) {
            Some(leg) => {
                self.apply_leg(x, &leg);
                self.restart_plan();
                true
            }
            None => false,
        }
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
        if !physical {
            let kept = self.estimate();
            return Ok(self.plan_from(&kept, RuntimeStatus::MeasurementRejected, 1));
        }
        for i in 0..NX / 2 {
            self.filters[i].mean = [x[2 * i], x[2 * i + 1]];
        }
        self.gated_rejections = 0;
        self.candidate_frames = 0;
        self.has_replaced = false;
        self.confirmed_frames = self.confirmed_frames.saturating_add(1);
        Ok(self.plan_from(x, RuntimeStatus::Ok, 1))
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
        self.actuation_end_s = None;
        Ok(self.step(measured_positions_m, 0.0, wait_s, (wait_s, false)))
    }

    /// One scanner cycle on the host's clock. `measured_positions_m` (None:
    /// lost) were measured at `t_measured_s`, at the start of the tracking
    /// phase that just ended; the actuation starts at
    /// `t_actuation_start_s`. The estimate is predicted at zero gradient
    /// from the end of the previous actuation phase to the measurement and
    /// on to the actuation start, and the plans model the gap between
    /// actuation phases these time stamps show (smoothed over cycles,
    /// `GAP_SMOOTHING`), so tracking phases of any length, fixed or
    /// varying, are handled.
    ///
    /// Refused with `BadTime` naming the argument, changing nothing: a
    /// measurement before the previous actuation ended (more than
    /// `TIME_TOLERANCE_S`: time going backwards), an actuation start before
    /// the measurement, or more than `MAX_CYCLE_GAP_S` from the previous
    /// actuation end (or from the measurement, on the first timed cycle) to
    /// the actuation start. After a longer pause, `reset`.
    pub fn cycle_at(
        &mut self,
        measured_positions_m: Option<&[f64]>,
        t_measured_s: f64,
        t_actuation_start_s: f64,
    ) -> Result<CycleOutput<K>, RuntimeError> {
        check_frame_length::<NX>(measured_positions_m)?;
        let (before_s, wait_s, gap_s) = self.check_times(t_measured_s, t_actuation_start_s)?;
        let first = self.actuation_end_s.is_none();
        let out = self.step(measured_positions_m, before_s, wait_s, (gap_s, first));
        self.actuation_end_s = Some(t_actuation_start_s + out.actuation_samples as f64 * S::DT_S);
        Ok(out)
    }

    /// End of the last actuation phase on the host's clock (the instant
    /// `estimate()` describes after a `cycle_at`), s.
    pub fn actuation_end_s(&self) -> Option<f64> {
        self.actuation_end_s
    }

    /// Checks a measurement time against the end of the previous actuation
    /// phase: `BadTime("t_measured_s")` when it goes backwards, otherwise
    /// the zero-gradient time from the previous actuation end to it, s.
    pub fn check_measurement_time(&self, t_measured_s: f64) -> Result<f64, RuntimeError> {
        if !t_measured_s.is_finite() {
            return Err(RuntimeError::NonFinite("t_measured_s"));
        }
        match self.actuation_end_s {
            None => Ok(0.0),
            Some(end_s) => {
                if t_measured_s < end_s - TIME_TOLERANCE_S {
                    return Err(RuntimeError::BadTime("t_measured_s"));
                }
                if t_measured_s - end_s > MAX_CYCLE_GAP_S {
                    return Err(RuntimeError::BadTime("t_measured_s"));
                }
                Ok((t_measured_s - end_s).max(0.0))
            }
        }
    }

    /// (previous actuation end -> measurement, measurement -> actuation
    /// start, previous actuation end -> actuation start), s, or the error.
    fn check_times(
        &self,
        t_measured_s: f64,
        t_actuation_start_s: f64,
    ) -> Result<(f64, f64, f64), RuntimeError> {
        let before_s = self.check_measurement_time(t_measured_s)?;
        if !t_actuation_start_s.is_finite() {
            return Err(RuntimeError::NonFinite("t_actuation_start_s"));
        }
        let wait_s = t_actuation_start_s - t_measured_s;
        if wait_s < 0.0 || before_s + wait_s > MAX_CYCLE_GAP_S {
            return Err(RuntimeError::BadTime("t_actuation_start_s"));
        }
        Ok((before_s, wait_s, before_s + wait_s))
    }

    /// The cycle after argument checks: predict `before_s` at zero gradient
    /// to the measurement, fuse it, predict `wait_s` to the actuation
    /// start, fold `gap.0` (the gap between the last actuation phase and
    /// this one; `gap.1`: the first of a time base) into the gap the plans
    /// model, plan.
    fn step(
        &mut self,
        measured_positions_m: Option<&[f64]>,
        before_s: f64,
        wait_s: f64,
        gap: (f64, bool),
    ) -> CycleOutput<K> {
        if before_s > 0.0 {
            self.predict_filters(0.0, before_s);
        }
        let status = match measured_positions_m {
            None => RuntimeStatus::MeasurementLost,
            Some(z) => self.fuse(z),
        };
        self.note_gap(gap.0, gap.1);
        // Tracking + delay pass with u = 0 before the next actuation.
        let measured = self.estimate();
        self.predict_filters(0.0, wait_s);
        let x_start = if self.settings.compensate_delay {
            self.estimate()
        } else {
            measured
        };
        let n_max = match self.settings.sampling {
            Sampling::Ideal | Sampling::Constant => 1,
            Sampling::Variable => self.settings.max_actuation_samples,
        };
        let mut out = self.plan_from(&x_start, status, n_max);
        if status == RuntimeStatus::Reacquired {
            // The host must learn that the estimate jumped, even when the
            // plan is the fallback or there is no target.
            out.status = RuntimeStatus::Reacquired;
        }
        // The estimator follows the actuation that will be played.
        for k in 0..out.actuation_samples {
            self.predict_filters(out.gradients_t_per_m[k], S::DT_S);
        }
        out
    }

    /// Folds a measured gap between actuation phases into the running
    /// estimate the plans model (`GAP_SMOOTHING`; the first cycle of a time
    /// base takes its gap as is).
    fn note_gap(&mut self, gap_s: f64, first: bool) {
        let next = if first {
            gap_s
        } else {
            self.gap_s + GAP_SMOOTHING * (gap_s - self.gap_s)
        };
        if next != self.gap_s {
            self.gap_s = next;
            self.update_schedule();
        }
    }

    /// Fuses frame `z` (length checked): accepted, rejected as invalid,
    /// gated out (counted towards re-acquisition), or re-acquired.
    fn fuse(&mut self, z: &[f64]) -> RuntimeStatus {
        let r = sq(self.settings.position_noise_m.max(1e-6));
        let mut class = self.classify_measurement(z);
        if class == Measurement::Accepted && self.continues_candidate(z, r) {
            // The estimate's gate has widened while it predicted through
            // the gated-out frames; a frame that carries on their sequence
            // belongs to it, not to the estimate.
            class = Measurement::GatedOut;
        }
        match class {
            Measurement::Invalid => RuntimeStatus::MeasurementRejected,
            Measurement::Accepted => {
                self.gated_rejections = 0;
                self.candidate_frames = 0;
                self.confirmed_frames = self.confirmed_frames.saturating_add(1);
                let m = NX / 2;
                if !self.has_replaced && nis(&self.filters[..m], z, r) > REPLACED_TRACK_NIS {
                    // A frame that pulls the estimate far (behind a gate
                    // widened by long open-loop phases) may be the first of
                    // a glitch: keep the estimate it pulls away from.
                    self.replaced = self.filters;
                    self.has_replaced = true;
                }
                update_filters(&mut self.filters[..m], z, r);
                RuntimeStatus::Ok
            }
            Measurement::GatedOut => {
                if self.has_replaced && nis(&self.replaced[..NX / 2], z, r) <= REPLACED_TRACK_NIS {
                    // The frames are back on the track the last
                    // re-acquisition replaced: that one was a glitch.
                    self.filters = self.replaced;
                    self.has_replaced = false;
                    update_filters(&mut self.filters[..NX / 2], z, r);
                    self.after_reacquisition();
                    self.confirmed_frames = 1;
                    return RuntimeStatus::Reacquired;
                }
                self.gated_rejections = self.gated_rejections.saturating_add(1);
                self.track_candidate(z, r);
                let after = self.settings.reacquire_after_rejections;
                let needed = if self.confirmed_frames >= ESTABLISHED_AFTER_FRAMES {
                    after.max(self.settings.glitch_frames.saturating_add(1))
                } else {
                    after
                };
                if after != 0 && self.candidate_frames >= needed {
                    self.replaced = self.filters;
                    self.has_replaced = true;
                    self.filters = self.candidate;
                    self.after_reacquisition();
                    RuntimeStatus::Reacquired
                } else {
                    RuntimeStatus::MeasurementRejected
                }
            }
        }
    }

    /// Whether frame `z` carries on the run of gated-out frames: the
    /// candidate has seen at least two (so it knows their speed) and `z`
    /// fits it better than the estimate.
    fn continues_candidate(&self, z: &[f64], r: f64) -> bool {
        let m = NX / 2;
        self.candidate_frames >= 2
            && within_gate(&self.candidate[..m], z, r)
            && nis(&self.candidate[..m], z, r) < nis(&self.filters[..m], z, r)
    }

    /// Feeds a gated-out frame to the re-acquisition candidate: fused when
    /// it agrees with the frames before it, else the candidate restarts at
    /// it (position at the frame, speed zero with a wide uncertainty, so
    /// that the next frame sets the speed).
    fn track_candidate(&mut self, z: &[f64], r: f64) {
        let m = NX / 2;
        if self.candidate_frames > 0 && within_gate(&self.candidate[..m], z, r) {
            update_filters(&mut self.candidate[..m], z, r);
            self.candidate_frames += 1;
        } else {
            let std = self.settings.position_noise_m.max(1e-6);
            for (c, &p) in self.candidate.iter_mut().zip(z) {
                *c = CapsuleFilter::with_speed_std(p, std, REACQUIRE_SPEED_STD_M_PER_S);
            }
            self.candidate_frames = 1;
        }
    }

    /// The estimate jumped (re-acquired): forget the counters and the plan.
    fn after_reacquisition(&mut self) {
        self.gated_rejections = 0;
        self.candidate_frames = 0;
        self.confirmed_frames = 0;
        // A leg chosen from the old estimate means nothing now.
        if self.has_target {
            let x = self.estimate();
            self.replan_legs(&x);
        }
        self.restart_plan();
    }

    /// Invalid when any position is non-finite or beyond
    /// `MAX_ABS_POSITION_M` (bad data, says nothing about the estimate);
    /// else gated out when any innovation exceeds the gate.
    fn classify_measurement(&self, z: &[f64]) -> Measurement {
        if z.iter()
            .any(|zi| !zi.is_finite() || libm::fabs(*zi) > MAX_ABS_POSITION_M)
        {
            return Measurement::Invalid;
        }
        let r = sq(self.settings.position_noise_m.max(1e-6));
        if within_gate(&self.filters[..NX / 2], z, r) {
            Measurement::Accepted
        } else {
            Measurement::GatedOut
        }
    }

    /// Predicts the estimate (and the re-acquisition candidate and the
    /// replaced track, while they exist) over `duration_s` at gradient `u`.
    fn predict_filters(&mut self, u: f64, duration_s: f64) {
        let gamma = self.settings.disturbance_bound;
        // A disturbance of bound gamma, read as white noise over one sample.
        let accel_psd = (gamma * gamma * S::DT_S).max(MIN_ACCEL_PSD);
        let vel_psd = gamma * gamma * S::DT_S;
        let predict = |filters: &mut [CapsuleFilter]| {
            for (i, f) in filters.iter_mut().enumerate() {
                let (next, a) = S::capsule_transition(i, f.mean, u, duration_s);
                f.predict(next, a, duration_s, accel_psd, vel_psd);
            }
        };
        let m = NX / 2;
        predict(&mut self.filters[..m]);
        if self.candidate_frames > 0 {
            predict(&mut self.candidate[..m]);
        }
        if self.has_replaced {
            predict(&mut self.replaced[..m]);
            self.has_replaced = self.replaced[..m]
                .iter()
                .all(|f| f.position_std_m() <= REPLACED_TRACK_MAX_STD_M);
        }
    }

    /// Solves from absolute state `x` and chooses the actuation length.
    fn plan_from(&mut self, x: &[f64; NX], status: RuntimeStatus, n_max: usize) -> CycleOutput<K> {
        let mut out = CycleOutput {
            gradients_t_per_m: [0.0; K],
            actuation_samples: 1,
            status,
            solve: None,
            estimate: [0.0; K2],
        };
        out.estimate[..NX].copy_from_slice(x);
        if !self.has_target {
            out.status = RuntimeStatus::NoTarget;
            return out;
        }
        self.advance_leg(x);
        let e = self.relative(x, &self.target);
        if self.on_last_leg && self.update_hold(&e) {
            out.gradients_t_per_m[0] = self.hold_gradient(&e);
            self.applied_samples = 0;
            return out;
        }
        self.solver.shift(self.applied_samples);
        if self.creeping(&e) {
            // Nearly at rest and still away from the target: the stored
            // minimum-time plan from here is the best start; a refined plan
            // that creeps on the quadratic cost can take seconds.
            self.solver.reset();
        }
        let report = self.refine_plan(&e);
        out.solve = Some(report);
        if report.status == SolveStatus::OutOfRange {
            out.gradients_t_per_m[0] = braking_gradient::<S, NX, K>(x);
            out.status = RuntimeStatus::Fallback;
            self.applied_samples = 0;
            // No plan: the next cycle looks the (braked) state up again;
            // once at rest (and only while frames agree with the
            // estimate, which may be wrong), the legs are re-planned from
            // here and reported as `Recovering` until the last one.
            self.restart_plan();
            if at_rest(x) && self.gated_rejections == 0 && self.replan_legs(x) {
                self.recovering = !self.on_last_leg;
            }
            return out;
        }
        if self.recovering && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::Recovering;
        }
        if report.status == SolveStatus::IterationLimit && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::IterationLimit;
        }
        let measured = S::qp_iterations_measured(&e);
        if measured > 0 && report.max_qp_iterations > measured && out.status == RuntimeStatus::Ok {
            out.status = RuntimeStatus::AboveIterationMap;
        }
        for (o, &u) in out.gradients_t_per_m.iter_mut().zip(self.solver.plan()) {
            // The solver keeps |u| <= u_max; clamp again as a last invariant.
            *o = u.clamp(-S::U_MAX_T_PER_M, S::U_MAX_T_PER_M);
        }
        let n = if n_max <= 1 {
            1
        } else {
            self.actuation_length(&e, n_max.min(S::N))
        };
        out.actuation_samples = n;
        self.applied_samples = n;
        self.last_cost = report.cost;
        if self.settings.sampling == Sampling::Variable {
            // Model (and refine for) the next phase as long as this one:
            // phase lengths change slowly, so the model stays close to what
            // plays.
            self.planned_phase_samples = n;
            self.update_schedule();
        }
        out
    }

    /// Refines the plan from `e`: one solve (SQP_ITERATIONS Gauss-Newton
    /// steps) per sample the coming phase is expected to play. This is the
    /// real-time iteration argument: constant sampling re-refines the plan
    /// before every played sample, so a plan that variable sampling plays
    /// open loop for n samples gets n refinements too. With one solve per
    /// phase, long phases played barely refined plans, and variable sampling
    /// settled later than constant sampling although its predictions held
    /// to 0.3 mm. Worst case N solves per cycle, inside the tracking time.
    fn refine_plan(&mut self, e: &[f64; NX]) -> SolveReport {
        let rounds = match self.settings.sampling {
            Sampling::Variable => self.planned_phase_samples.max(1),
            Sampling::Ideal | Sampling::Constant => 1,
        };
        let mut report = self.solver.solve(e);
        for _ in 1..rounds {
            if report.status == SolveStatus::OutOfRange {
                break;
            }
            let r = self.solver.solve(e);
            report.cost = r.cost;
            report.took_table_plan |= r.took_table_plan;
            report.qp_iterations += r.qp_iterations;
            report.max_qp_iterations = report.max_qp_iterations.max(r.max_qp_iterations);
            if r.status == SolveStatus::IterationLimit {
                report.status = SolveStatus::IterationLimit;
            }
        }
        report
    }

    /// Nearly at rest away from the target, where a stored plan from here
    /// beats refining: every speed below `REPLAN_SPEED_M_PER_S` with some
    /// position error beyond `WAYPOINT_POSITION_M` (main grid), or every
    /// speed below the settle tolerance with some error beyond the hold's
    /// entry (the fine grid of the end game).
    fn creeping(&self, e: &[f64; NX]) -> bool {
        let below = |speed: f64| (0..NX / 2).all(|i| libm::fabs(e[2 * i + 1]) <= speed);
        let beyond = |position: f64| (0..NX / 2).any(|i| libm::fabs(e[2 * i]) > position);
        (below(REPLAN_SPEED_M_PER_S) && beyond(WAYPOINT_POSITION_M))
            || (below(END_GAME_REST_SPEED_M_PER_S) && beyond(self.settings.hold_enter_position_m))
    }

    /// Enters or leaves the terminal hold (with hysteresis); true inside.
    fn update_hold(&mut self, e: &[f64; NX]) -> bool {
        let s = &self.settings;
        let within = |pos_m: f64, speed: f64| {
            (0..NX / 2).all(|i| libm::fabs(e[2 * i]) <= pos_m && libm::fabs(e[2 * i + 1]) <= speed)
        };
        let was = self.holding;
        self.holding = if was {
            within(s.hold_release_position_m, s.hold_release_speed_m_per_s)
        } else {
            within(s.hold_enter_position_m, s.hold_enter_speed_m_per_s)
                && relative_drift_within(e, s.hold_enter_position_m)
        };
        if was && !self.holding {
            // Re-plan from the tables, not from the plan before the hold.
            self.solver.reset();
            self.planned_phase_samples = self.settings.max_actuation_samples;
            self.update_schedule();
        }
        self.holding
    }

    /// The hold law: critically damped PD on the capsules' mean error (the
    /// one mode a single gradient controls near rest), scaled by the duty
    /// of the schedule and bounded by a fraction of u_max.
    fn hold_gradient(&self, e: &[f64; NX]) -> f64 {
        let (mean_x, mean_v) = capsule_means(e);
        let mean_g = self.mean_gain;
        if mean_g.is_nan() || mean_g <= 0.0 {
            return 0.0;
        }
        let w = HOLD_NATURAL_FREQUENCY_RAD_PER_S;
        let period_s = match self.settings.sampling {
            Sampling::Ideal => S::DT_S,
            Sampling::Constant | Sampling::Variable => S::DT_S + self.gap_s,
        };
        let accel = -(w * w * mean_x + 2.0 * w * mean_v) * period_s / S::DT_S;
        let bound = HOLD_MAX_GRADIENT_FRACTION * S::U_MAX_T_PER_M;
        (accel / mean_g).clamp(-bound, bound)
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
        for (b, f) in start.iter_mut().zip(&self.filters) {
            *b = [3.0 * f.position_std_m(), 3.0 * f.speed_std_m_per_s()];
        }
        let mut boxes = start;
        let gamma_dt = self.settings.disturbance_bound * S::DT_S;
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

/// What a finite-length frame is to the estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Measurement {
    Accepted,
    /// Non-finite or beyond the physical range: ignored, not counted.
    Invalid,
    /// Plausible but beyond the innovation gate: ignored, counted toward
    /// re-acquisition.
    GatedOut,
}

/// Every capsule's speed within `REST_SPEED_M_PER_S`.
fn at_rest<const NX: usize>(x: &[f64; NX]) -> bool {
    (0..NX / 2).all(|i| libm::fabs(x[2 * i + 1]) <= REST_SPEED_M_PER_S)
}

/// `WrongLength("measured_positions_m")` unless a frame has M positions.
fn check_frame_length<const NX: usize>(z: Option<&[f64]>) -> Result<(), RuntimeError> {
    match z {
        Some(z) if z.len() != NX / 2 => Err(RuntimeError::WrongLength("measured_positions_m")),
        _ => Ok(()),
    }
}

/// Whether every position of frame `z` is within the innovation gate
/// (`MEASUREMENT_GATE_NIS`) of `filters` (measurement variance `r_m2`).
fn within_gate(filters: &[CapsuleFilter], z: &[f64], r_m2: f64) -> bool {
    filters.iter().zip(z).all(|(f, &zi)| {
        let innovation = zi - f.mean[0];
        innovation * innovation / (f.cov[0] + r_m2) <= MEASUREMENT_GATE_NIS
    })
}

/// Normalized innovation squared of frame `z` against `filters`, summed
/// over the capsules.
fn nis(filters: &[CapsuleFilter], z: &[f64], r_m2: f64) -> f64 {
    filters
        .iter()
        .zip(z)
        .map(|(f, &zi)| sq(zi - f.mean[0]) / (f.cov[0] + r_m2))
        .sum()
}

/// Measurement update of every capsule's filter with frame `z`.
fn update_filters(filters: &mut [CapsuleFilter], z: &[f64], r_m2: f64) {
    for (f, &zi) in filters.iter_mut().zip(z) {
        f.update(zi, r_m2);
        // Behind a wide gate (a fresh candidate, or a large disturbance
        // bound) one frame can imply any speed; beyond the physical range
        // the model's prediction overflows to NaN.
        f.mean[1] = f.mean[1].clamp(-MAX_ABS_SPEED_M_PER_S, MAX_ABS_SPEED_M_PER_S);
    }
}

/// A one-sample plan (rest zero) for single-step prediction.
fn single<const K: usize>(u: f64) -> [f64; K] {
    let mut p = [0.0; K];
    if K > 0 {
        p[0] = u;
    }
    p
}

/// Fallback outside the tables: one braking sample, bounded by u_max,
/// never an extrapolated table value. One gradient changes every capsule's
/// speed alike, so braking the mean speed can leave the capsules moving
/// apart (e.g. 86 and 231 mm/s braked on the mean: -72 and +73 mm/s), and a
/// low-drag capsule then coasts far (drag ~ v^2: 73 mm/s coasts 12 cm in
/// 5 s for the large default capsule). The law minimizes instead the
/// distance the capsules would coast after this sample,
/// sum_i ln(1 + b_i |v_i'| T) / b_i over `BRAKING_HORIZON_S` with b_i
/// measured from the model: that sum is concave in each |v_i'|, so its
/// minimum over the gradient lies where one capsule stops or at +-u_max.
/// At rest (every speed within `REST_SPEED_M_PER_S`) it is zero.
pub fn braking_gradient<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    x: &[f64; NX],
) -> f64 {
    let m = NX / 2;
    if at_rest(x) {
        return 0.0;
    }
    let u_max = S::U_MAX_T_PER_M;
    // Speed change per unit gradient over one sample, and drag per capsule.
    let mut gain = [0.0; K2];
    let mut drag = [0.0; K2];
    for i in 0..m {
        (gain[i], drag[i]) = capsule_gain_and_drag::<S, NX, K>(i);
        if gain[i].is_nan() || gain[i] <= 0.0 || !x[2 * i + 1].is_finite() {
            return 0.0;
        }
    }
    let coast_m = |u: f64| -> f64 {
        let mut d = 0.0;
        for i in 0..m {
            let v = libm::fabs(x[2 * i + 1] + gain[i] * u);
            d += if drag[i] > 0.0 {
                libm::log1p(drag[i] * v * BRAKING_HORIZON_S) / drag[i]
            } else {
                v * BRAKING_HORIZON_S
            };
        }
        d
    };
    let mut best_u = 0.0;
    let mut best = coast_m(0.0);
    let mut consider = |u: f64| {
        let u = u.clamp(-u_max, u_max);
        let d = coast_m(u);
        if d < best {
            best = d;
            best_u = u;
        }
    };
    consider(-u_max);
    consider(u_max);
    for i in 0..m {
        consider(-x[2 * i + 1] / gain[i]);
    }
    best_u
}

/// (speed change per unit gradient over one sample at rest, (m/s)/(T/m);
/// drag coefficient b_i, 1/m) of capsule `i`, from one-sample predictions
/// of the model (no second copy of g_i or b_i).
fn capsule_gain_and_drag<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    i: usize,
) -> (f64, f64) {
    let du = 1.0e-3;
    let (pushed, _) = S::capsule_transition(i, [0.0, 0.0], du, S::DT_S);
    let gain = pushed[1] / du;
    // Coasting from v0: v' = -b v^2 gives 1/v(T) - 1/v0 = b T.
    let v0 = 0.1;
    let (coasted, _) = S::capsule_transition(i, [0.0, v0], 0.0, S::DT_S);
    let drag = if coasted[1] > 0.0 {
        (1.0 / coasted[1] - 1.0 / v0) / S::DT_S
    } else {
        0.0
    };
    (gain, drag.max(0.0))
}

/// Near rest one gradient moves every capsule alike: the motion relative to
/// the capsules' mean is beyond the hold law. True when that relative
/// motion, extrapolated over [`HOLD_DRIFT_HORIZON_S`], keeps every capsule
/// within `position_m` of the mean-corrected target.
fn relative_drift_within<const NX: usize>(e: &[f64; NX], position_m: f64) -> bool {
    let (mean_x, mean_v) = capsule_means(e);
    (0..NX / 2).all(|i| {
        let d = e[2 * i] - mean_x;
        let w = e[2 * i + 1] - mean_v;
        libm::fabs(d + w * HOLD_DRIFT_HORIZON_S) <= position_m
    })
}

/// Mean position and mean speed over the capsules of `[x1, v1, x2, v2, ...]`.
fn capsule_means<const NX: usize>(x: &[f64; NX]) -> (f64, f64) {
    let m = NX / 2;
    let (mut mean_x, mut mean_v) = (0.0, 0.0);
    for i in 0..m {
        mean_x += x[2 * i] / m as f64;
        mean_v += x[2 * i + 1] / m as f64;
    }
    (mean_x, mean_v)
}

/// The capsules' mean acceleration per unit gradient near rest,
/// (m/s^2)/(T/m), from one-sample predictions of the model (no second copy
/// of g_i).
fn mean_gradient_gain<S: PlanSolver<NX, K>, const NX: usize, const K: usize>() -> f64 {
    let m = NX / 2;
    let mut mean_g = 0.0;
    for i in 0..m {
        let (next, _) = S::capsule_transition(i, [0.0, 0.0], 1.0e-3, S::DT_S);
        mean_g += next[1] / (1.0e-3 * S::DT_S) / m as f64;
    }
    mean_g
}

/// Positions of `x` (every `stride`-th entry: 1 for positions only, 2 for
/// a full state) must lie in the solver's workspace.
pub fn check_workspace<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    argument: &'static str,
    x: &[f64],
    stride: usize,
) -> Result<(), RuntimeError> {
    for (capsule, &p) in x.iter().step_by(stride).enumerate() {
        let excess_m = if p < S::WORKSPACE_MIN_M {
            p - S::WORKSPACE_MIN_M
        } else if p > S::WORKSPACE_MAX_M {
            p - S::WORKSPACE_MAX_M
        } else {
            continue;
        };
        return Err(RuntimeError::OutsideWorkspace {
            argument,
            capsule,
            excess_m,
        });
    }
    Ok(())
}

/// Every name `RuntimeError::BadSetting` can carry (the settings that are
/// range-checked), for hosts and tests that map errors back to fields.
pub const SETTING_NAMES: [&str; 10] = [
    "tracking_time_s",
    "extra_delay_s",
    "position_noise_m",
    "disturbance_bound",
    "max_actuation_samples",
    "hold_enter_position_m",
    "hold_enter_speed_m_per_s",
    "hold_release_position_m",
    "hold_release_speed_m_per_s",
    "reacquire_after_rejections",
];

fn check_settings(s: &ControllerSettings, n: usize) -> Result<(), RuntimeError> {
    let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
    if !finite_nonneg(s.tracking_time_s) || s.tracking_time_s > 1.0 {
        return Err(RuntimeError::BadSetting("tracking_time_s"));
    }
    if !finite_nonneg(s.extra_delay_s) || s.extra_delay_s > 1.0 {
        return Err(RuntimeError::BadSetting("extra_delay_s"));
    }
    if !finite_nonneg(s.position_noise_m) || s.position_noise_m > 0.1 {
        return Err(RuntimeError::BadSetting("position_noise_m"));
    }
    if !finite_nonneg(s.disturbance_bound) || s.disturbance_bound > 1e3 {
        return Err(RuntimeError::BadSetting("disturbance_bound"));
    }
    if s.max_actuation_samples == 0 || s.max_actuation_samples > n {
        return Err(RuntimeError::BadSetting("max_actuation_samples"));
    }
    let tolerance = |v: f64| (0.0..=MAX_ABS_POSITION_M).contains(&v);
    if !tolerance(s.hold_enter_position_m) {
        return Err(RuntimeError::BadSetting("hold_enter_position_m"));
    }
    if !tolerance(s.hold_enter_speed_m_per_s) {
        return Err(RuntimeError::BadSetting("hold_enter_speed_m_per_s"));
    }
    if !tolerance(s.hold_release_position_m) || s.hold_release_position_m < s.hold_enter_position_m
    {
        return Err(RuntimeError::BadSetting("hold_release_position_m"));
    }
    if !tolerance(s.hold_release_speed_m_per_s)
        || s.hold_release_speed_m_per_s < s.hold_enter_speed_m_per_s
    {
        return Err(RuntimeError::BadSetting("hold_release_speed_m_per_s"));
    }
    if s.reacquire_after_rejections == 1 {
        return Err(RuntimeError::BadSetting("reacquire_after_rejections"));
    }
    Ok(())
}

fn sq(v: f64) -> f64 {
    v * v
}
