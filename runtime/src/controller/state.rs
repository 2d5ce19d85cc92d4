//! The controller's memory, split by concern: what the frames say
//! (`Estimation`), where to go and in which mode (`Supervision`), and what
//! the law carries from one cycle to the next (`LawMemory`). The mode
//! enum lives here too; its transitions are in `mode`.

use super::hold_frames::HoldFrames;
use super::StationKeeper;
use crate::estimator::{CapsuleFilter, ScaleEstimate};
use crate::factor_fit::FactorWindow;

/// What a cycle does. Decided in one place (`Controller::next_mode`, then
/// `Mode::after_solve`); each mode's step is one call in `plan_from`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// No target set: zero gradient, status `NoTarget`.
    NoTarget,
    /// Terminal hold: nearly at rest at the target; the hold law
    /// (centre PD plus station-keeping dither) keeps the capsules there.
    Hold,
    /// The end game stalled (`Controller::stalled`): one braking sample,
    /// then the stored plan from rest takes over.
    Brake,
    /// Following a plan: the explicit tier, then the refinement.
    Plan,
    /// No stored plan covers the state: braking, and the legs are
    /// re-planned once the capsules are at rest.
    Fallback,
}

impl Mode {
    /// Every mode, in declaration order.
    pub const ALL: [Mode; 5] = [
        Mode::NoTarget,
        Mode::Hold,
        Mode::Brake,
        Mode::Plan,
        Mode::Fallback,
    ];

    /// The mode's name in reports (snake case).
    pub const fn name(self) -> &'static str {
        match self {
            Mode::NoTarget => "no_target",
            Mode::Hold => "hold",
            Mode::Brake => "brake",
            Mode::Plan => "plan",
            Mode::Fallback => "fallback",
        }
    }
}

/// The state estimate and the frame gate's memory.
#[derive(Debug, Clone)]
pub(super) struct Estimation<const NX: usize> {
    /// One position/speed filter per capsule (first M entries).
    pub filters: [CapsuleFilter; NX],
    /// Gated-out frames since the last accepted one (see
    /// `ControllerSettings::reacquire_after_rejections`).
    pub gated_rejections: usize,
    /// Per capsule: how far (m) and how fast (m/s) it may have drifted
    /// from the prediction since the last accepted frame because the model
    /// is not the plant (see `accumulate_model_drift`).
    pub model_drift: [[f64; 2]; NX],
    /// Per capsule: the estimate of its gain and drag factors against the
    /// model, and the factors in use (estimator and refinement; 1 until
    /// the estimate differs from the model significantly).
    pub scales: [ScaleEstimate; NX],
    pub applied_scales: [[f64; 2]; NX],
    /// The factors the loop was given: the model's (1), or a calibration
    /// (`Controller::set_model_factors`).
    pub told_factors: [[f64; 2]; NX],
    /// The frames and gradients to which the factors are fitted: since
    /// the target was set, the track re-acquired or the last window
    /// filled (sized by NX, of which the first M entries are used).
    pub window: FactorWindow<NX>,
    /// Re-acquisition candidate: a filter started at the first gated-out
    /// frame and updated with the gated-out frames that agree with it, so
    /// that a re-acquired estimate has speeds from the frames.
    pub candidate: [CapsuleFilter; NX],
    /// Frames the candidate has absorbed (0: none).
    pub candidate_frames: usize,
    /// Whether the candidate's first frame was within the estimate's gate
    /// widened by the whole model drift: a capsule off the model, followed
    /// after `MODEL_ERROR_FOLLOW_FRAMES` (else a glitch, see
    /// `ControllerSettings::glitch_frames`).
    pub candidate_continues_track: bool,
    /// Whether the candidate's first frame was within `MODEL_DRIFT_MAX_M`
    /// of the estimate for every capsule: near enough for a model error
    /// the told uncertainty understates (see
    /// `Controller::candidate_speed_departs`).
    pub candidate_starts_near: bool,
    /// The estimate the last re-acquisition replaced, predicted along (see
    /// `REPLACED_TRACK_MAX_STD_M`).
    pub replaced: [CapsuleFilter; NX],
    pub has_replaced: bool,
    /// Frames accepted since the last `reset` or re-acquisition (see
    /// `ControllerSettings::glitch_frames`).
    pub confirmed_frames: usize,
    /// End of the last actuation phase on the host's clock, s (`cycle_at`;
    /// None before the first timed cycle, after `reset` and after `cycle`).
    pub actuation_end_s: Option<f64>,
    /// Running estimate of the zero-gradient gap between actuation phases
    /// (tracking + delay), s: the coast the plans model.
    pub gap_s: f64,
    /// Ideal sampling: the gradient played since the last full state, T/m
    /// (None before the first one, after `reset` and after a rejected one).
    pub full_state_gradient: Option<f64>,
    /// The capsules are at rest where the last `reset` put them (no cycle
    /// since): told factors then also set the speeds' uncertainty.
    pub at_start: bool,
}

impl<const NX: usize> Estimation<NX> {
    pub fn new(gap_s: f64, gain_uncertainty: f64, drag_uncertainty: f64) -> Self {
        Estimation {
            filters: [CapsuleFilter::new(0.0, 0.0); NX],
            gated_rejections: 0,
            model_drift: [[0.0; 2]; NX],
            scales: [ScaleEstimate::new(gain_uncertainty, drag_uncertainty); NX],
            applied_scales: [[1.0, 1.0]; NX],
            told_factors: [[1.0, 1.0]; NX],
            window: FactorWindow::new(),
            candidate: [CapsuleFilter::new(0.0, 0.0); NX],
            candidate_frames: 0,
            candidate_continues_track: false,
            candidate_starts_near: false,
            replaced: [CapsuleFilter::new(0.0, 0.0); NX],
            has_replaced: false,
            confirmed_frames: 0,
            actuation_end_s: None,
            gap_s,
            full_state_gradient: None,
            at_start: false,
        }
    }
}

/// Where the capsules are to go, by which legs, and in which mode.
#[derive(Debug, Clone)]
pub(super) struct Supervision<const NX: usize> {
    /// Target of the current leg (the final target on the last leg, else
    /// a waypoint), absolute SI.
    pub target: [f64; NX],
    /// Where the capsules are to end, absolute SI.
    pub final_target: [f64; NX],
    /// Whether the current leg ends at `final_target`.
    pub on_last_leg: bool,
    pub has_target: bool,
    /// The legs were re-planned after a fallback (`Recovering` until the
    /// last leg).
    pub recovering: bool,
    /// The mode of the last cycle.
    pub mode: Mode,
    /// End-game progress (see `Controller::stalled`): the best (smallest)
    /// largest error since the last progress, m, and the actuation time
    /// since, s.
    pub stall_best_m: f64,
    pub stall_clock_s: f64,
    /// Settling holds left at the off-model confirm spread since the
    /// target was set (see `Controller::hold_confirm_spread_m`).
    pub off_model_confirm_exits: u32,
    /// Holds left for the frames' relative drift since the target was set
    /// (see `Controller::hold_drifts_out`).
    pub drift_exits: u32,
    /// Holds left for the third combination's walk since the target was
    /// set (see `third_combination`).
    pub third_exits: u32,
}

impl<const NX: usize> Supervision<NX> {
    pub fn new() -> Self {
        Supervision {
            target: [0.0; NX],
            final_target: [0.0; NX],
            on_last_leg: true,
            has_target: false,
            recovering: false,
            mode: Mode::NoTarget,
            stall_best_m: f64::INFINITY,
            stall_clock_s: 0.0,
            off_model_confirm_exits: 0,
            drift_exits: 0,
            third_exits: 0,
        }
    }

    /// A new start or target: the next cycle decides the mode afresh
    /// (in particular, not in the hold).
    pub fn forget_mode(&mut self) {
        self.mode = if self.has_target {
            Mode::Plan
        } else {
            Mode::NoTarget
        };
    }
}

/// What the law carries between cycles besides the solver's plan.
#[derive(Debug, Clone)]
pub(super) struct LawMemory<const NX: usize> {
    /// Plan samples applied since the last solve.
    pub applied_samples: usize,
    /// Last solver cost, for the decrease check (18).
    pub last_cost: f64,
    /// Samples per actuation phase the plan is refined for.
    pub planned_phase_samples: usize,
    /// Mean acceleration per unit gradient near rest, (m/s^2)/(T/m): fixed
    /// by the model, computed once for the hold law.
    pub mean_gain: f64,
    /// The hold's relative-position law (see `station`).
    pub station: StationKeeper<NX>,
    /// The hold's frames along the drag direction (see `hold_frames`).
    pub hold_frames: HoldFrames,
    /// Three capsules' third combination with the factors in use (zero:
    /// none; see `third_combination`).
    pub third_direction: [f64; NX],
    /// The hold's frames along it.
    pub third_frames: HoldFrames,
}
