//! What a cycle reports: its status, its output, and the errors of calls
//! with bad arguments.

use capsule_mpc_solver::{SolveReport, TableError};

/// Status of one cycle (the plan is always usable and within |u| <= u_max).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub enum RuntimeStatus {
    Ok = 0,
    /// The state is outside the tables: one braking sample (see
    /// [`braking_gradient`](super::braking_gradient)), never an extrapolated table value. The next
    /// cycle looks the state up again; outside the tables with every speed
    /// below `REPLAN_SPEED_M_PER_S` it starts a recovery leg (`Recovering`).
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
    /// (time going backwards) or an actuation start before its
    /// measurement; names the argument.
    BadTime(&'static str),
    /// Tracking + delay (a setting's, or a cycle's gap between actuation
    /// phases) longer than the range the loop is proven to settle with,
    /// `max_s` ([`max_proven_gap_s`](super::max_proven_gap_s)): regenerate
    /// the tables for the longer tracking phase, or, after a pause, `reset`.
    GapBeyondProven { gap_s: f64, max_s: f64 },
    /// A target speed is not zero: the plans bring the capsules to rest.
    TargetNotAtRest,
    /// The solver's table file failed its integrity check (SHA-256
    /// trailer): no number of it is used. Rebuild from a clean checkout or
    /// regenerate.
    CorruptTables(TableError),
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
