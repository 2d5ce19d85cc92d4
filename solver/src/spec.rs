//! What a generated module specializes: the model, the weights, the
//! scanner timing and the tables of one config. An emitted module is a
//! unit struct implementing [`Spec`] with these as constants.

use crate::drag::DragLaw;
use crate::tables::Tables;

/// The constants (SI) of one controller: `M` capsules, `NX = 2 M` states.
pub trait Spec<const M: usize, const NX: usize>: 'static {
    /// Controller sample time, s.
    const DT_S: f64;
    /// RK4 sub-steps per sample.
    const RK4_SUBSTEPS: usize;
    /// Gradient bound, T/m.
    const U_MAX_T_PER_M: f64;
    /// Magnetic acceleration per gradient, m/s^2 per T/m.
    const G: [f64; M];
    /// Drag law of each capsule.
    const DRAG: [DragLaw; M];
    /// Stage weights on the relative state, the input weight per (T/m)^2
    /// and the terminal weights.
    const Q: [f64; NX];
    const R: f64;
    const P: [f64; NX];
    /// State bounds (alpha): relative position (m) and speed (m/s).
    const POSITION_BOUND_M: f64;
    const SPEED_BOUND_M_PER_S: f64;
    /// SQP iterations per control step.
    const SQP_ITERATIONS: usize;
    /// Active-set iterations allowed per QP (hard cap).
    const QP_MAX_ITERATIONS: usize;
    /// Halvings tried in the line search.
    const LINE_SEARCH_TRIES: usize;
    /// Multipliers below this count as zero in the active-set QP.
    const QP_MULTIPLIER_TOLERANCE: f64;
    /// Whether plans come from offline tables (false: the paper's NMPC).
    const USE_TABLES: bool;
    /// Scanner timing from the config, s.
    const TRACKING_TIME_S: f64;
    const EXTRA_DELAY_S: f64;
    /// Position noise the estimator assumes (standard deviation), m.
    const POSITION_NOISE_M: f64;
    /// Disturbance bound the estimator assumes, SI (m/s and m/s^2 on the
    /// state derivative).
    const DISTURBANCE_BOUND_SI: f64;
    /// sigma of the switching rule (17) and the Lipschitz constants of
    /// section III: dynamics, stage cost, terminal cost; ||2 alpha||.
    const SWITCHING_SIGMA: f64;
    const L_F: f64;
    const L_L: f64;
    const L_V: f64;
    const X_DIAMETER: f64;
    /// Workspace: every capsule position of a target or start lies in
    /// [WORKSPACE_MIN_M, WORKSPACE_MAX_M], m.
    const WORKSPACE_MIN_M: f64;
    const WORKSPACE_MAX_M: f64;
    /// SHA-256 of the config the module was generated from (hex), and of
    /// the parts of it that shape the solver.
    const CONFIG_SHA256: &'static str;
    const SOLVER_SHA256: &'static str;
    /// The module's tables, parsed at compile time.
    const TABLES: Tables<'static>;
    /// Per kept index cell: most QP iterations measured offline (empty when
    /// not measured).
    const QP_ITERATION_MAP: &'static [u8];
    /// Checks the tables' SHA-256 trailer (once per process).
    fn verify_tables() -> Result<(), crate::tables::TableError>;
}
