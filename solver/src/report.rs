//! What one solve reports: status (separate from errors: every status comes
//! with a usable plan that respects |u| <= u_max), figures for monitoring,
//! and the legs of a move through chained stored plans.

/// Outcome of one solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveStatus {
    /// Refined plan; every QP converged within its iteration bound.
    Refined,
    /// The state lies outside the warm-start index and there is no current
    /// plan: the caller must apply its fallback law.
    OutOfRange,
    /// A QP hit its iteration bound: the best feasible iterate was used.
    IterationLimit,
}

/// Figures of one solve, for monitoring and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    pub status: SolveStatus,
    /// Nonlinear cost of the returned plan over the plan length.
    pub cost: f64,
    /// True when the plan was replaced by a stored plan tail this step.
    pub took_table_plan: bool,
    /// Active-set iterations summed over this step's QPs.
    pub qp_iterations: u32,
    /// Largest active-set iteration count of one QP in this step.
    pub max_qp_iterations: u32,
    /// Which tier produced the plan.
    pub tier: Tier,
}

/// The two tiers of the online solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tier {
    /// The explicit tier: a stored plan sample's window QP, linearized
    /// offline, solved at the state's deviation (no model rollout).
    Explicit,
    /// The SQP refinement (Gauss-Newton on the nonlinear rollout) replaced
    /// the explicit plan with a cheaper one.
    Refined,
}

/// One leg of a move: the stored plan from rest at `start_offset_m`
/// (relative positions `x - leg_target`, speeds 0) brings the capsules to
/// rest at the leg's target. `last`: the leg ends at the final target
/// (then `start_offset_m` is the whole displacement); otherwise its target
/// is a waypoint, `x_start - start_offset_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg<const NX: usize> {
    pub start_offset_m: [f64; NX],
    pub last: bool,
}
