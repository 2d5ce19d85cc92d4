//! Settings of the scanner-cycle controller: the sampling mode, the
//! switching rule, the tunable values with their defaults (named
//! constants), and the range check every setting passes.

use super::status::RuntimeError;

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

/// When the SQP refinement runs after the explicit tier (see
/// `Controller::refine_plan`). The explicit answer is always computed
/// first; a refined plan replaces it only when its true (rolled-out) cost
/// is lower.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refine {
    /// The explicit tier alone: no model rollout in the solver.
    None,
    /// One refinement (SQP_ITERATIONS Gauss-Newton steps) per cycle.
    Once,
    /// One refinement per sample the coming actuation phase plays
    /// (variable sampling: up to N; ideal and constant sampling: one).
    PerSample,
}

/// When the solver looks for minimum-time shots
/// (`capsule_mpc_solver::shooting`): the plan is the shortest one that
/// ends at the target at rest, re-solved every cycle, wherever one
/// converges. Without them, the refinement of the stored plans alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shooting {
    Off,
    On,
    /// The controller's default: on, under every sampling and for every
    /// build (measured: docs/decisions.md). The paper preset asks for
    /// `Off`.
    Auto,
}

impl Shooting {
    /// Whether shots are on.
    pub fn is_on(self) -> bool {
        match self {
            Shooting::Off => false,
            Shooting::On | Shooting::Auto => true,
        }
    }
}

impl From<bool> for Shooting {
    fn from(on: bool) -> Self {
        if on {
            Shooting::On
        } else {
            Shooting::Off
        }
    }
}

/// Settings; defaults come from the generated spec.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerSettings {
    pub sampling: Sampling,
    /// Refinement after the explicit tier (default `PerSample`: see
    /// `Controller::default_settings`).
    pub refine: Refine,
    pub switching: SwitchingRule,
    /// Predict the state through tracking + delay before solving (true), or
    /// solve from the measured state and treat the delay as a disturbance
    /// (false, the paper's way).
    pub compensate_delay: bool,
    /// Tracking phase duration, s: the fixed timing of
    /// [`Controller::cycle`](super::Controller::cycle), and the gap the plans model until
    /// [`Controller::cycle_at`](super::Controller::cycle_at) has measured one.
    pub tracking_time_s: f64,
    /// Extra compute/transfer delay after tracking, s (as `tracking_time_s`).
    pub extra_delay_s: f64,
    /// Measurement noise standard deviation, m.
    pub position_noise_m: f64,
    /// Disturbance bound gamma, SI (m/s and m/s^2 on the state derivative).
    pub disturbance_bound: f64,
    /// Largest actuation length, samples (<= N).
    pub max_actuation_samples: usize,
    /// Terminal hold (dual-mode MPC): entered when every speed is within
    /// `hold_enter_speed_m_per_s`, the capsules' position errors lie within
    /// `hold_enter_position_m` of the group's centre (their relative drift
    /// extrapolated over `HOLD_DRIFT_HORIZON_S`; within
    /// `hold_release_position_m` now) and the centre within
    /// `HOLD_CENTRE_ENTER_M` of the target; left when a speed exceeds
    /// `hold_release_speed_m_per_s`, an error lies farther than
    /// `hold_release_position_m` from the centre, or the centre farther
    /// than `HOLD_CENTRE_RELEASE_M`. Inside, a gentle linear law brings the
    /// centre to the target and damps the common motion instead of
    /// re-planning separation manoeuvres for errors at the noise level.
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
    /// Relative uncertainty of the model's magnetic gain and of its drag,
    /// which the estimator adds to its process noise (fractions; 0 trusts
    /// the model exactly). Real capsules are known to 10-20 %.
    pub model_gain_uncertainty: f64,
    pub model_drag_uncertainty: f64,
    /// Minimum-time shots (`capsule_mpc_solver::shooting`; default
    /// `Shooting::Auto`).
    pub shooting: Shooting,
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

/// Within this distance of their targets (every capsule), m, and once
/// the learned factors differ from the ones the loop was given (the
/// model's, or a calibration's) by `SCALE_SIGNIFICANCE` deviations, the
/// switching rule counts the factors' remaining uncertainty in how far
/// the state may stray from the plan open loop: the phases that end a
/// move set the relative speed of the arrival, which the hold cannot
/// remove (docs/decisions.md).
pub const ARRIVAL_REGION_M: f64 = 20e-3;

/// The capsules' learned gain-drag products agree within this fraction:
/// the law alone's similar model state is then nearly exact. While they
/// do, the law alone under variable sampling plays one sample per phase
/// on the coasted plans; once they differ, the back-to-back plans in the
/// rule's phases, and under every sampling each plan to its end (re-solved
/// every cycle, a drag split (x1.2, x0.8) left 84 of 192 constant-sampling
/// mismatch runs unsettled: docs/decisions.md).
pub const SIMILAR_PRODUCT_AGREEMENT: f64 = 0.1;

/// How far the estimated gap may be from the one the coasted plans were
/// solved for (tracking time + extra delay) for the law alone under
/// variable sampling to play them one sample per phase, s.
pub const COASTED_GAP_TOLERANCE_S: f64 = 1.0e-3;

/// From this many capsules the minimum-time shots carry the moves under
/// the scanner cycle: the refinement of their stored plans (1 cm apart,
/// from rest, no explicit tier) is a poor fallback from a moving state
/// (it swung three capsules about the start for up to 1.3 s before a shot
/// was found again). So under variable sampling a shot that cannot be
/// re-solved for longer actuation phases keeps flying on the phases it
/// was solved for, a tracked shot aims at
/// `SHOT_SPEED_TOLERANCE_TRACKED_MANY_M_PER_S`, a chained move flies
/// one shot through its waypoints (`Controller::shoot_through_legs`), and
/// a refined plan that does not settle within the horizon looks for a
/// shot from the stored plan tail (`Controller::tail_shots_wanted`; the
/// last two with fewer capsules only under ideal sampling). With two
/// capsules all four measured slower or mixed (docs/decisions.md).
pub const SHOTS_CARRY_FROM_CAPSULES: usize = 3;

/// Default hold entry: 0.7 of the 1 mm settle tolerance, m.
pub const HOLD_ENTER_POSITION_M: f64 = 0.7e-3;
/// Default hold entry speed: the 5 mm/s settle tolerance, m/s. The hold
/// brakes the group's common speed, where the plans, given an arrival in
/// the band at a few mm/s, swing the group about the target
/// (docs/decisions.md, "Hold entry and exit").
pub const HOLD_ENTER_SPEED_M_PER_S: f64 = 5.0e-3;
/// The explicit law alone enters the hold up to this speed (or the
/// setting's `hold_enter_speed_m_per_s`, when larger), m/s, where
/// the centre law brings the group's centre to rest within
/// `HOLD_CENTRE_RELEASE_M`: its stored plans cannot be re-solved for an
/// arrival that keeps a common speed of 10-30 mm/s, and played on from
/// there they swing the group by centimetres (the refined loop re-solves;
/// docs/decisions.md, "Hold entry and exit").
pub const EXPLICIT_HOLD_ENTER_SPEED_M_PER_S: f64 = 40.0e-3;
/// ... and keeps it up to this speed, m/s.
pub const EXPLICIT_HOLD_RELEASE_SPEED_M_PER_S: f64 = 45.0e-3;
/// Default hold release: 0.8 of the settle tolerance, m (hysteresis keeps
/// estimate noise from toggling the mode).
pub const HOLD_RELEASE_POSITION_M: f64 = 1.0e-3;
/// Default hold release speed, m/s.
pub const HOLD_RELEASE_SPEED_M_PER_S: f64 = 10.0e-3;
/// The hold is also left when a capsule is estimated outside the release
/// distance while the spread is at least this, m: centring can no longer
/// bring every capsule back with margin, and waiting for the spread to
/// reach the release distance only spends time outside the band.
pub const HOLD_SPREAD_EXIT_M: f64 = 0.8e-3;
/// ... but only after the hold has run this long, s: on arrival the hold
/// is still centring the group ...
pub const HOLD_SETTLING_S: f64 = 0.5;
/// ... and only with at most this many capsules: with three, the end
/// game's corrections take seconds (docs/three-capsules.md), and leaving
/// the hold early only started them sooner (the 1.5 cm drift grid under
/// variable sampling: 40 runs never settled against 38).
pub const HOLD_EARLY_EXIT_MAX_CAPSULES: usize = 2;
/// How far ahead the hold entry extrapolates the capsules' relative drift, s.
pub const HOLD_DRIFT_HORIZON_S: f64 = 1.0;
/// Under the scanner cycle the hold is entered only where its station
/// keeping can stop the capsules' relative motion with their relative
/// position within this, m (`StationKeeper::can_stop`; 1.4, 3 and 4 mm
/// measured worse, docs/decisions.md).
pub const HOLD_STOP_SPREAD_M: f64 = 2.0e-3;
/// While the hold is settling (`HOLD_SETTLING_S`) it is left when the
/// relative motion, as the frames since entry tell it, would stop beyond
/// this spread, m: the estimate at entry can miss a relative speed the
/// model did not predict (capsules off the model) by a few mm/s, and the
/// dither then only watches it drift for seconds. 2 mm (the entry's) and
/// 3 mm also left holds that would have settled (docs/decisions.md).
pub const HOLD_CONFIRM_SPREAD_M: f64 = 4.0e-3;
/// ... and this spread once the learned factors differ from the told ones,
/// m: off the model the arrivals keep relative speeds the dither stops
/// only near the band's edge, where the capsules then sit for seconds
/// before leaving it, while a shot from the hold's first half second
/// lands on the learned factors. On the model 2 mm leaves holds that would
/// have settled (the reach grid's runs above 2x: docs/decisions.md).
pub const HOLD_CONFIRM_SPREAD_OFF_MODEL_M: f64 = 2.0e-3;
/// ... for this many holds per target: factors learned from wrong frames
/// (a 2 mm tracking glitch taken for true) otherwise leave hold after hold.
pub const HOLD_CONFIRM_OFF_MODEL_EXITS: u32 = 2;
/// ... while the capsules' learned gains agree within this fraction:
/// where they differ, the centre law's common gradient itself moves them
/// apart or together, the stopping test misjudges the motion, and the
/// tighter confirm left hold after hold (docs/decisions.md).
pub const HOLD_CONFIRM_GAIN_AGREEMENT: f64 = 0.05;
/// The station keeper takes its coordinate across the capsules' gains in
/// use once their learned gain factors differ from one another by more
/// than this many standard deviations (see `StationKeeper::set_gains`).
pub const STATION_GAIN_DIFFERENCE_SIGMAS: f64 = 3.0;
/// Frames of hold through which the relative drift's line is fitted
/// before the hold may be left for it, s (see `hold_frames`): the rate to
/// about 0.3 mm/s on 0.2 mm frames 40 ms apart. Judged once per hold:
/// judged every cycle from 0.8 s to 2 s, the many looks found a 3-sigma
/// line in holds that settled (docs/decisions.md).
pub const HOLD_DRIFT_FIT_S: f64 = 0.8;
/// How far apart the capsules may stop for the hold to go on once the
/// frames tell the drift, m: inside the band's 2 mm with room for the
/// disturbance.
pub const HOLD_DRIFT_SPREAD_M: f64 = 2.0e-3;
/// Standard deviations of the drift line's rate within which some rate
/// must stop inside for the hold to go on.
pub const HOLD_DRIFT_RATE_SIGMAS: f64 = 2.0;
/// Holds left for the frames' drift per target.
pub const HOLD_DRIFT_EXITS: u32 = 1;
/// Time in the hold at which a drift kept only on its rate's uncertainty
/// is judged again, s: 32 frames 40 ms apart know the rate to about
/// 0.14 mm/s (docs/decisions.md).
pub const HOLD_DRIFT_RECHECK_S: f64 = 1.3;
/// Frames of hold through which three capsules' third combination is
/// fitted before the hold may be left for its walk, s (see
/// `third_combination`): the rate to about 0.07 mm/s on 0.2 mm frames
/// 40 ms apart. At 1.0 s the traced 0.28 mm/s walk was within two
/// deviations of rest (docs/decisions.md).
pub const HOLD_THIRD_FIT_S: f64 = 1.6;
/// How far ahead the third combination's line is extrapolated, s.
pub const HOLD_THIRD_HORIZON_S: f64 = 3.0;
/// How far along the third combination the capsules may walk for the hold
/// to go on, m (a unit direction: a capsule's share is at most this).
/// 0.8 mm and 1.3 mm traded unsettled runs against medians
/// (docs/decisions.md).
pub const HOLD_THIRD_SPREAD_M: f64 = 1.0e-3;
/// Standard deviations of the line's rate taken toward zero: two left
/// holds on a drifting disturbance's swings, which reverse
/// (docs/decisions.md).
pub const HOLD_THIRD_RATE_SIGMAS: f64 = 3.0;
/// Holds left for the third combination's walk per target.
pub const HOLD_THIRD_EXITS: u32 = 1;
/// Latest frames through which the hold tells that the third combination
/// has walked a capsule out of the band, s: 10-11 frames 40 ms apart, the
/// coordinate to about 0.06 mm, recent enough to follow the walk.
pub const HOLD_THIRD_RECENT_S: f64 = 0.4;
/// How far the third combination's walk alone may carry its most exposed
/// capsule from its target before the hold is left for a shot, m: the
/// settle band's 1 mm. At 0.8-0.9 mm the hold is also left on walks that
/// stop inside, and more arrivals off the model go unsettled
/// (docs/decisions.md).
pub const HOLD_THIRD_OUT_M: f64 = 1.0e-3;
/// How far the third combination's unit direction may turn, as the
/// learned factors move, before its frames are fitted afresh.
pub const HOLD_THIRD_DIRECTION_TOLERANCE: f64 = 0.02;
/// Fewest frames a hold's line is fitted through (`hold_frames`).
pub const HOLD_LINE_MIN_FRAMES: usize = 8;
/// The hold's entry test gives the estimated relative rate this many of
/// its standard deviations (see `Controller::update_hold`).
pub const HOLD_ENTRY_RATE_SIGMAS: f64 = 1.0;
/// The hold is entered only while the group's centre (midpoint of the
/// extreme position errors) is within this distance of the target, m: the
/// hold law (critically damped at `HOLD_NATURAL_FREQUENCY_RAD_PER_S`) then
/// moves the group at most w x / e, under 8 mm/s.
pub const HOLD_CENTRE_ENTER_M: f64 = 2.0e-3;
/// The hold is left when the centre is farther than this, m.
pub const HOLD_CENTRE_RELEASE_M: f64 = 3.0e-3;
/// Natural frequency of the hold law, rad/s (critically damped).
pub const HOLD_NATURAL_FREQUENCY_RAD_PER_S: f64 = 10.0;
/// The hold law uses at most this fraction of u_max.
pub const HOLD_MAX_GRADIENT_FRACTION: f64 = 0.25;
/// End-game stall detection (see `Controller::stalled`): within this
/// distance of the target, m, ...
pub const STALL_REGION_M: f64 = 10.0e-3;
/// ... the largest position error (plus the distance its speed covers in
/// `STALL_LOOKAHEAD_S`) must shrink to this fraction of its
/// best ...
pub const STALL_PROGRESS: f64 = 0.8;
/// ... within this much actuation time, s, or the controller brakes and
/// re-plans from the stored plan.
pub const STALL_S: f64 = 0.25;
/// See `STALL_PROGRESS`, s.
pub const STALL_LOOKAHEAD_S: f64 = 0.1;
/// Default re-acquisition count, frames: 0.2 s at the default constant
/// sampling (20 ms actuation + 20 ms tracking per frame). Five gross
/// outliers in a row, with none of the frames between them accepted, are
/// far likelier a wrong estimate than wrong data.
pub const REACQUIRE_AFTER_REJECTIONS: usize = 5;
/// Gated-out frames that agree with one another and whose run started
/// within the model's drift bound (see `Controller::track_candidate`) are
/// a capsule off the model: the estimate follows them at the third (or at
/// `reacquire_after_rejections`, if fewer).
pub const MODEL_ERROR_FOLLOW_FRAMES: usize = 3;
/// Gated-out frames that agree with one another, whose run started within
/// `MODEL_DRIFT_MAX_M` of the estimate, and whose speed departs from the
/// estimate's by more than this many standard deviations of the two are
/// a capsule off the model too (one farther off than told): a glitch
/// offsets the frames and keeps their speed (docs/decisions.md).
pub const MODEL_ERROR_SPEED_SIGMAS: f64 = 3.0;
/// Default `ControllerSettings::glitch_frames`: 0.8 s of tracking frames at
/// the default constant sampling.
pub const GLITCH_FRAMES: usize = 20;
/// Default `ControllerSettings::model_gain_uncertainty` and
/// `model_drag_uncertainty`: the magnetization and the effective mass are
/// known to about 10 %, the drag coefficient to about 20 %.
pub const MODEL_GAIN_UNCERTAINTY: f64 = 0.1;
/// Range `Controller::set_model_factors` accepts for a factor: a capsule
/// 4x off its model is a different capsule (regenerate for it).
pub const MODEL_FACTOR_MIN: f64 = 0.25;
pub const MODEL_FACTOR_MAX: f64 = 4.0;
/// Range of a factor's standard deviation there: 0.1 % (a calibration's
/// best) to 100 %.
pub const MODEL_FACTOR_STD_MIN: f64 = 1e-3;
pub const MODEL_FACTOR_STD_MAX: f64 = 1.0;
pub const MODEL_DRAG_UNCERTAINTY: f64 = 0.2;
/// Share of the model-error speed drift kept after an accepted frame (the
/// frame corrects the position at once, the speed over a few frames).
pub const MODEL_DRIFT_SPEED_KEPT: f64 = 0.8;
/// Largest model drift the gate allows for, m: a capsule within 10-20 %
/// of the model drifts a few mm from the prediction over the longest
/// actuation phase (10 samples at u_max: 14 mm for a 10 % gain error), and
/// tracking glitches beyond it stay recognized as such.
pub const MODEL_DRIFT_MAX_M: f64 = 0.004;
/// Ideal sampling: the speed of a full state counts as measured to this
/// when it regresses the factors, m/s (one step's speed change is
/// 1e-3 m/s for a 10 % gain error at full gradient).
pub const FULL_STATE_SPEED_STD_M_PER_S: f64 = 1.0e-4;
/// A factor is used once it differs from the model's 1 by this many
/// standard deviations of its estimate. On the model itself chance
/// differences pass it now and then, and the refinement then plans on a
/// factor within a few of its deviations of 1; used later, a factor off
/// the model comes too late for the first arrival (docs/decisions.md).
pub const SCALE_SIGNIFICANCE: f64 = 2.0;
/// The factor fit's prior on a steady position rate: what the disturbance
/// bound adds to the speed in this time, s.
pub const FIT_RATE_PRIOR_TIME_S: f64 = 1.0;
/// Largest model uncertainty accepted (a factor of two).
pub const MAX_MODEL_UNCERTAINTY: f64 = 1.0;
/// Accepted frames after which an estimate counts as established (see
/// `ControllerSettings::glitch_frames`).
pub const ESTABLISHED_AFTER_FRAMES: usize = 2;

/// How much longer than the gap its tables were generated for (the
/// config's tracking time + extra delay) a cycle's gap between actuation
/// phases may be, s, for two capsules: the proven range. Measured on the
/// default config (1 cm grid in +-4 cm, seeds 1-8, the paper's
/// disturbance, 10 s, 640 runs per sampling): with 30 ms gaps every run
/// settles, the worst at 6.2 s constant / 3.8 s variable against 2.6 /
/// 5.2 s with 20 ms (2.4x, within the 3x asked); with 40 ms the constant
/// worst is 7.7 s (2.9x), with 50 ms 7 of 480 constant runs over +-5 cm do
/// not settle in 10 s, with 80 ms about half. Regenerate for a longer tracking
/// phase.
pub const PROVEN_EXTRA_GAP_S: f64 = 0.01;
/// The same for three or more capsules: none (their end game falls off a
/// cliff at 30 ms: 89 of 124 targets unsettled against 8 at 20 ms).
pub const PROVEN_EXTRA_GAP_MANY_S: f64 = 0.0;

/// The longest gap between the end of one actuation phase and the start
/// of the next (tracking + delay) that a controller of `capsules` capsules
/// generated for `generated_gap_s` is proven to settle with, s: settings
/// and cycles beyond it are refused (`RuntimeError::GapBeyondProven`).
pub const fn max_proven_gap_s(generated_gap_s: f64, capsules: usize) -> f64 {
    generated_gap_s + proven_extra_gap_s(capsules)
}

/// How much longer than its generated gap a controller of `capsules`
/// capsules is proven to settle with, s (`PROVEN_EXTRA_GAP_S` for two,
/// `PROVEN_EXTRA_GAP_MANY_S` from three).
pub const fn proven_extra_gap_s(capsules: usize) -> f64 {
    if capsules <= 2 {
        PROVEN_EXTRA_GAP_S
    } else {
        PROVEN_EXTRA_GAP_MANY_S
    }
}
/// How far a measurement time may precede the end of the previous
/// actuation phase (clock rounding between host and controller), s. Within
/// it the measurement is taken at the actuation end.
pub const TIME_TOLERANCE_S: f64 = 1.0e-3;
/// Weight of the newest gap in the running estimate of the tracking gap
/// the plans model (exponential smoothing): jittering tracking phases are
/// modelled by about their mean, a change of length is followed within a
/// few cycles.
pub const GAP_SMOOTHING: f64 = 0.3;
/// Longest tracking phase a setting may give, s.
pub const MAX_TRACKING_TIME_S: f64 = 1.0;
/// Longest extra delay after tracking a setting may give, s.
pub const MAX_EXTRA_DELAY_S: f64 = 1.0;
/// Speed below which a capsule counts as at rest, m/s (the settle
/// tolerance): for the fallback's braking and the end game's restart from
/// a fine stored plan (the emitted solver's `FINE_REST_SPEED_M_PER_S`).
pub const REST_SPEED_M_PER_S: f64 = 5.0e-3;
/// Coasting horizon the fallback's braking law minimizes the drift over, s.
pub const BRAKING_HORIZON_S: f64 = 1.0;
/// A plan sample whose gradient is at most this fraction of u_max is idle:
/// from rest it moves the capsules by under 2 um (at 40 mT/m full scale,
/// 0.04 mT/m for 20 ms), so a plan from rest skips the idle samples it
/// starts with.
pub const IDLE_GRADIENT_FRACTION: f64 = 1.0e-3;
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
/// Most process noise (acceleration PSD, (m/s^2)^2 s) the model's error
/// adds to a capsule's filter (`ScaleEstimate::model_error_psd`): more
/// would let the estimate follow the frames' noise during manoeuvres. Also
/// the process noise of the re-acquisition candidate and the replaced
/// track, which know nothing of the factors.
pub const MODEL_ERROR_MAX_ACCEL_PSD: f64 = 1.0e-6;
/// Least process noise of a capsule's filter, (m/s^2)^2 s: near rest the
/// model's error vanishes with the magnetic and drag accelerations, and
/// the frames then tell the relative speed to about 0.13 mm/s RMS in the
/// hold, which its entry test needs (a 1e-6 floor leaves 0.35 mm/s).
pub const REST_ACCEL_PSD: f64 = 1.0e-9;

/// Every name `RuntimeError::BadSetting` can carry (the settings that are
/// range-checked), for hosts and tests that map errors back to fields.
pub const SETTING_NAMES: [&str; 13] = [
    "refine",
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
    "model_gain_uncertainty",
    "model_drag_uncertainty",
];

/// `has_explicit_tier`: whether the solver has explicit-tier data (a
/// controller without tables, the paper preset, has none and must refine);
/// `max_gap_s`: the proven range of tracking + delay ([`max_proven_gap_s`]).
pub(super) fn check_settings(
    s: &ControllerSettings,
    n: usize,
    has_explicit_tier: bool,
    max_gap_s: f64,
) -> Result<(), RuntimeError> {
    if s.refine == Refine::None && !has_explicit_tier {
        return Err(RuntimeError::BadSetting("refine"));
    }
    let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
    if !finite_nonneg(s.tracking_time_s) || s.tracking_time_s > MAX_TRACKING_TIME_S {
        return Err(RuntimeError::BadSetting("tracking_time_s"));
    }
    if !finite_nonneg(s.extra_delay_s) || s.extra_delay_s > MAX_EXTRA_DELAY_S {
        return Err(RuntimeError::BadSetting("extra_delay_s"));
    }
    if s.wait_s() > max_gap_s + TIME_TOLERANCE_S {
        return Err(RuntimeError::GapBeyondProven {
            gap_s: s.wait_s(),
            max_s: max_gap_s,
        });
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
    let fraction = |v: f64| (0.0..=MAX_MODEL_UNCERTAINTY).contains(&v);
    if !fraction(s.model_gain_uncertainty) {
        return Err(RuntimeError::BadSetting("model_gain_uncertainty"));
    }
    if !fraction(s.model_drag_uncertainty) {
        return Err(RuntimeError::BadSetting("model_drag_uncertainty"));
    }
    Ok(())
}
