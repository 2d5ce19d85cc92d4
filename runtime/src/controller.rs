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
    /// Tracking phase duration, s.
    pub tracking_time_s: f64,
    /// Extra compute/transfer delay after tracking, s.
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
    /// estimate) with no accepted frame in between, the estimate is taken
    /// to be wrong (e.g. a `reset` to the wrong place) and is restarted at
    /// the measured positions. Lost and invalid frames neither count nor
    /// break the run. 0 disables re-acquisition; 1 is refused (every single
    /// outlier would restart the estimate).
    pub reacquire_after_rejections: usize,
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
        match self.sampling {
            Sampling::Ideal => (phase_samples, 0.0),
            Sampling::Constant => (1, self.wait_s()),
            Sampling::Variable => (phase_samples, self.wait_s()),
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

/// A waypoint counts as reached when every position is within this of it, m
/// (the next leg's plan absorbs the residual).
pub const WAYPOINT_POSITION_M: f64 = 2.0e-3;
/// ... and every speed below this, m/s.
pub const WAYPOINT_SPEED_M_PER_S: f64 = 20.0e-3;
/// Braking outside the tables re-plans the legs once every speed is below
/// this, m/s (the stored plans start at rest).
pub const REPLAN_SPEED_M_PER_S: f64 = 20.0e-3;

/// Normalized innovation squared above which a measurement is rejected
/// (10 sigma: only gross outliers and wrong data).
pub const MEASUREMENT_GATE_NIS: f64 = 100.0;
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
    /// The state is outside the tables: a bounded braking input is applied.
    Fallback = 1,
    /// A QP hit its iteration bound; the best feasible plan was used.
    IterationLimit = 2,
    /// The measurement was non-finite or implausible and was ignored.
    MeasurementRejected = 3,
    /// No measurement this cycle: the estimate was predicted only.
    MeasurementLost = 4,
    /// No target set: zero gradient.
    NoTarget = 5,
    /// `reacquire_after_rejections` frames in a row disagreed with the
    /// estimate: it was restarted at this frame's positions (speeds zero,
    /// wide uncertainty) and the plan restarted. Reported for that one
    /// cycle whatever the plan (which may be the fallback or, without a
    /// target, zero).
    Reacquired = 6,
    /// A QP of this solve took more active-set iterations than the offline
    /// map (`capsule-mpc generate`) measured in the state's index cell: the
    /// plan converged and is used, but the state lies outside what the
    /// offline worst-case timing covered.
    AboveIterationMap = 7,
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
    /// A target speed is not zero: targets are rest states.
    TargetSpeedNotZero { capsule: usize },
    /// A setting is out of its range; names it.
    BadSetting(&'static str),
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
        self.restart_plan();
        Ok(())
    }

    /// Restarts the estimate at measured positions `z` (length checked by
    /// the caller). Unlike `reset`, the capsules are not known to be at
    /// rest: the controller has been pushing them from a wrong estimate,
    /// so the speed uncertainty is wide enough for the next frame to pass
    /// the gate and fix the speeds.
    fn reacquire(&mut self, z: &[f64]) {
        let std = self.settings.position_noise_m.max(1e-6);
        for (i, &p) in z.iter().enumerate() {
            self.filters[i] = CapsuleFilter::with_speed_std(p, std, REACQUIRE_SPEED_STD_M_PER_S);
        }
        self.gated_rejections = 0;
        self.restart_plan();
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
    /// it back to back; otherwise each actuation phase is followed by
    /// tracking + delay at zero gradient.
    fn update_schedule(&mut self) {
        let (samples, coast_s) = self.settings.schedule(self.planned_phase_samples);
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
    /// workspace, speeds 0. Reached from wherever the capsules are, through
    /// waypoints when one stored plan does not reach (see [`Leg`]); the
    /// plan restarts.
    pub fn set_target(&mut self, target: &[f64; NX]) -> Result<(), RuntimeError> {
        if target.iter().any(|v| !v.is_finite()) {
            return Err(RuntimeError::NonFinite("target"));
        }
        if let Some(capsule) = (0..NX / 2).find(|&i| target[2 * i + 1] != 0.0) {
            return Err(RuntimeError::TargetSpeedNotZero { capsule });
        }
        check_workspace::<S, NX, K>("target", target, 2)?;
        let x = self.estimate();
        let leg = Self::leg_from(&x, target).ok_or(RuntimeError::TargetOutOfRange)?;
        self.final_target = *target;
        self.has_target = true;
        self.apply_leg(&x, &leg);
        self.restart_plan();
        Ok(())
    }

    /// The next leg from the capsules' positions in `x` to `target`.
    fn leg_from(x: &[f64; NX], target: &[f64; NX]) -> Option<Leg<NX>> {
        let mut d = [0.0; NX];
        for i in 0..NX / 2 {
            d[2 * i] = x[2 * i] - target[2 * i];
        }
        S::first_leg(&d)
    }

    /// Heads for the end of `leg`, starting from `x`.
    fn apply_leg(&mut self, x: &[f64; NX], leg: &Leg<NX>) {
        self.on_last_leg = leg.last;
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
        Ok(self.plan_from(x, RuntimeStatus::Ok, 1))
    }

    /// One scanner cycle. `measured_positions_m` are the tracked positions
    /// at the start of the tracking phase that just ended (None: frame lost).
    /// Returns the gradients to play from the actuation start and how many
    /// samples to play before the next tracking phase.
    pub fn cycle(
        &mut self,
        measured_positions_m: Option<&[f64]>,
    ) -> Result<CycleOutput<K>, RuntimeError> {
        let m = NX / 2;
        let mut status = RuntimeStatus::Ok;
        match measured_positions_m {
            None => status = RuntimeStatus::MeasurementLost,
            Some(z) if z.len() != m => {
                return Err(RuntimeError::WrongLength("measured_positions_m"))
            }
            Some(z) => match self.classify_measurement(z) {
                Measurement::Invalid => status = RuntimeStatus::MeasurementRejected,
                Measurement::GatedOut => {
                    self.gated_rejections = self.gated_rejections.saturating_add(1);
                    let after = self.settings.reacquire_after_rejections;
                    if after != 0 && self.gated_rejections >= after {
                        self.reacquire(z);
                        status = RuntimeStatus::Reacquired;
                    } else {
                        status = RuntimeStatus::MeasurementRejected;
                    }
                }
                Measurement::Accepted => {
                    self.gated_rejections = 0;
                    let r = sq(self.settings.position_noise_m.max(1e-6));
                    for (i, &zi) in z.iter().enumerate() {
                        let f = &mut self.filters[i];
                        f.update(zi, r);
                        // Behind a wide gate (just after re-acquisition, or
                        // with a large disturbance bound) one frame can
                        // imply any speed; beyond the physical range the
                        // model's prediction overflows to NaN.
                        f.mean[1] = f.mean[1].clamp(-MAX_ABS_SPEED_M_PER_S, MAX_ABS_SPEED_M_PER_S);
                    }
                }
            },
        }
        // Tracking + delay pass with u = 0 before the next actuation.
        let wait_s = self.settings.wait_s();
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
        Ok(out)
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
        let within_gate = z.iter().enumerate().all(|(i, &zi)| {
            let f = &self.filters[i];
            let innovation = zi - f.mean[0];
            innovation * innovation / (f.cov[0] + r) <= MEASUREMENT_GATE_NIS
        });
        if within_gate {
            Measurement::Accepted
        } else {
            Measurement::GatedOut
        }
    }

    fn predict_filters(&mut self, u: f64, duration_s: f64) {
        let gamma = self.settings.disturbance_bound;
        // A disturbance of bound gamma, read as white noise over one sample.
        let accel_psd = (gamma * gamma * S::DT_S).max(MIN_ACCEL_PSD);
        let vel_psd = gamma * gamma * S::DT_S;
        for i in 0..NX / 2 {
            let (next, a) = S::capsule_transition(i, self.filters[i].mean, u, duration_s);
            self.filters[i].predict(next, a, duration_s, accel_psd, vel_psd);
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
            self.solver.reset();
            // Outside the tables (e.g. a new target while moving fast):
            // brake, and once nearly at rest head for the legs from here.
            if (0..NX / 2).all(|i| libm::fabs(x[2 * i + 1]) <= REPLAN_SPEED_M_PER_S) {
                self.replan_legs(x);
            }
            return out;
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

    /// Every speed below `REPLAN_SPEED_M_PER_S` while some position error
    /// exceeds `WAYPOINT_POSITION_M`.
    fn creeping(&self, e: &[f64; NX]) -> bool {
        let slow = (0..NX / 2).all(|i| libm::fabs(e[2 * i + 1]) <= REPLAN_SPEED_M_PER_S);
        let away = (0..NX / 2).any(|i| libm::fabs(e[2 * i]) > WAYPOINT_POSITION_M);
        slow && away
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
            Sampling::Constant | Sampling::Variable => S::DT_S + self.settings.wait_s(),
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

/// A one-sample plan (rest zero) for single-step prediction.
fn single<const K: usize>(u: f64) -> [f64; K] {
    let mut p = [0.0; K];
    if K > 0 {
        p[0] = u;
    }
    p
}

/// Fallback outside the tables: brake the mean speed within one sample,
/// bounded by u_max (drag brakes further). Never extrapolates a table.
pub fn braking_gradient<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    x: &[f64; NX],
) -> f64 {
    let (_, mean_v) = capsule_means(x);
    let mean_g = mean_gradient_gain::<S, NX, K>();
    if mean_g.is_nan() || mean_g <= 0.0 || !mean_v.is_finite() {
        return 0.0;
    }
    (-mean_v / (mean_g * S::DT_S)).clamp(-S::U_MAX_T_PER_M, S::U_MAX_T_PER_M)
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
