//! What the runtime needs from a solver, and its implementation by the
//! generic [`Solver`] for any module's [`Spec`].

use crate::explicit::explicit_step_ops;
use crate::lookup::{
    chain_time_s, coasted_time_s, covers_from_rest, first_leg, qp_iterations_measured,
};
use crate::qp::QpEngine;
use crate::refine::Solver;
use crate::report::{Leg, SolveReport};
use crate::rollout::{
    capsule_transition, capsule_transition_scaled, predict, predict_constant, stage_cost,
};
use crate::spec::Spec;
use crate::tables::TableError;

/// What the runtime drives. `NX` states, plans of `K` samples. Relative
/// states are `e = x - x_target` in SI units.
pub trait PlanSolver<const NX: usize, const K: usize>: Sized {
    /// Number of capsules (NX = 2 M).
    const M: usize;
    /// Online window N.
    const N: usize;
    /// Sample time, s.
    const DT_S: f64;
    /// Gradient bound, T/m.
    const U_MAX_T_PER_M: f64;
    /// State bounds (alpha): relative position (m) and speed (m/s).
    const POSITION_BOUND_M: f64;
    const SPEED_BOUND_M_PER_S: f64;
    /// Scanner timing from the config, s.
    const TRACKING_TIME_S: f64;
    const EXTRA_DELAY_S: f64;
    /// Position noise the estimator assumes, m.
    const POSITION_NOISE_M: f64;
    /// Disturbance bound the estimator assumes, SI.
    const DISTURBANCE_BOUND_SI: f64;
    /// Switching rule constants (section III) and sigma.
    const L_F: f64;
    const L_L: f64;
    const L_V: f64;
    const X_DIAMETER: f64;
    const SWITCHING_SIGMA: f64;
    /// QP iteration bound (hard cap per QP).
    const QP_MAX_ITERATIONS: usize;
    /// Bytes of the table file.
    const TABLE_BYTES: usize;
    /// Workspace: every position of a target or start lies in
    /// [WORKSPACE_MIN_M, WORKSPACE_MAX_M], m.
    const WORKSPACE_MIN_M: f64;
    const WORKSPACE_MAX_M: f64;
    /// Whether the explicit tier has data (false without tables).
    const HAS_EXPLICIT_TIER: bool;
    /// Certified worst-case floating-point operations of one explicit step.
    const EXPLICIT_CERTIFIED_OPS: u64;

    fn new() -> Self;
    /// Checks the tables' integrity (SHA-256 trailer), once per process:
    /// call before trusting any plan.
    fn verify_tables() -> Result<(), TableError>;
    fn reset(&mut self);
    /// Drops `samples` applied inputs from the front of the plan.
    fn shift(&mut self, samples: usize);
    /// The plan is played in actuation phases of `samples_per_phase`
    /// samples, each followed by `coast_s` of zero gradient (tracking +
    /// delay); `coast_s = 0` for back-to-back samples.
    fn set_schedule(&mut self, samples_per_phase: usize, coast_s: f64);
    /// Moves a shot in flight to a new schedule, arriving when it did
    /// (see `Solver::reschedule_shot`); false leaves everything as it was.
    fn reschedule_shot(&mut self, e: &[f64; NX], samples_per_phase: usize, coast_s: f64) -> bool;
    /// On a leg to a waypoint (`e_leg` relative to it, `e_final` to the
    /// final target): one shot to the final target through the rest of the
    /// chain (see `Solver::shoot_through_chain`); true when one converges
    /// (the plan is that shot), else nothing changes.
    fn shoot_through_chain(&mut self, e_leg: &[f64; NX], e_final: &[f64; NX]) -> bool;
    /// Refines the plan from relative state `e` (SQP on the nonlinear
    /// model). A plan from `solve_explicit` since the last call competes
    /// on its true cost, so the result never costs more than it.
    fn solve(&mut self, e: &[f64; NX]) -> SolveReport;
    /// The explicit tier from `e`: no rollout, no Jacobians; its plan
    /// becomes a candidate (see `solve`, `adopt_explicit`). `OutOfRange`
    /// outside the index.
    fn solve_explicit(&mut self, e: &[f64; NX]) -> SolveReport;
    /// Makes the last explicit plan the current plan.
    fn adopt_explicit(&mut self);
    /// Current plan, T/m per sample.
    fn plan(&self) -> &[f64; K];
    /// When the plan is a converged minimum-time shot: the samples left
    /// until it ends at the target at rest (0: not a shot).
    fn shot_samples(&self) -> usize;
    /// Whether `solve` looks for minimum-time shots (see `shooting`).
    fn set_shooting(&mut self, on: bool);
    /// Starts a control cycle: restores the per-cycle compute budget of
    /// the solves that follow (their shots and every refinement after the
    /// first).
    fn start_cycle(&mut self);
    /// Whether another `solve` fits this cycle's compute budget.
    fn refinement_fits(&self) -> bool;
    /// A converged shot's terminal speed tolerance, m/s (see
    /// `shooting::SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S`).
    fn set_shot_speed_tolerance(&mut self, tolerance_m_per_s: f64);
    /// Whether a refined plan that does not settle within the horizon
    /// looks first for a shot from the stored plan tail (`Solver::set_tail_shots`).
    fn set_tail_shots(&mut self, on: bool);
    /// Asks the next `solve` for a shot searched from `samples` down
    /// (`Solver::want_shot`).
    fn want_shot(&mut self, samples: usize);
    /// Whether the explicit tier answers from the model state similar to
    /// the capsules' (`Solver::set_explicit_similarity`).
    fn set_explicit_similarity(&mut self, on: bool);
    /// Whether a start at rest at relative positions `e` is covered.
    fn covers_from_rest(e: &[f64; NX]) -> bool;
    /// The first leg from rest at displacement `d = x_start - x_target`
    /// (positions; speeds ignored) through chained stored plans; None when
    /// no chain gets there.
    fn first_leg(d: &[f64; NX]) -> Option<Leg<NX>>;
    /// Minimum rest-to-rest time of that chain (summed over its legs), s;
    /// infinite without one.
    fn chain_time_s(d: &[f64; NX]) -> f64;
    /// Minimum rest-to-rest time of the stored constant-sampling plan for
    /// `d` (the coasted schedule's bound), s; infinite off the plan grid.
    fn coasted_time_s(d: &[f64; NX]) -> f64;
    /// Most active-set iterations one QP took in the offline solves in the
    /// warm-start index cell of `e` (`capsule-mpc generate`); 0 when not
    /// measured or outside the index.
    fn qp_iterations_measured(e: &[f64; NX]) -> u32;
    /// Stage cost L(e, u) (per sample).
    fn stage_cost(e: &[f64; NX], u: f64) -> f64;
    /// State after applying `plan[..samples]` from `e`.
    fn predict_plan(e: &[f64; NX], plan: &[f64; K], samples: usize) -> [f64; NX];
    /// State after `duration_s` of constant `u` from `e`.
    fn predict_constant(e: &[f64; NX], u: f64, duration_s: f64) -> [f64; NX];
    /// One capsule over `duration_s` at constant `u`: new (x, v) and the
    /// 2x2 Jacobian d(x, v)/d(x0, v0) (row major), for the estimator.
    fn capsule_transition(i: usize, xv: [f64; 2], u: f64, duration_s: f64) -> ([f64; 2], [f64; 4]);
    /// The refinement rolls plans out with capsule `i`'s gain and drag
    /// scaled by `scales[i]` ([gain, drag]; missing entries read as 1).
    fn set_model_scales(&mut self, scales: &[[f64; 2]]);
    /// As `capsule_transition`, with the capsule's gain and drag scaled.
    fn capsule_transition_scaled(
        i: usize,
        xv: [f64; 2],
        u: f64,
        duration_s: f64,
        scale: [f64; 2],
    ) -> ([f64; 2], [f64; 4]);
    /// Capsule `i`'s magnetic acceleration per gradient (m/s^2 per T/m)
    /// and its drag acceleration at speed `v` (m/s^2), as the model has them.
    fn capsule_gain(i: usize) -> f64;
    fn capsule_drag(i: usize, v: f64) -> f64;
}

impl<
        S: Spec<M, NX>,
        const M: usize,
        const NX: usize,
        const N: usize,
        const K: usize,
        E: QpEngine<N> + Default,
    > PlanSolver<NX, K> for Solver<S, M, NX, N, K, E>
{
    const M: usize = M;
    const N: usize = N;
    const DT_S: f64 = S::DT_S;
    const U_MAX_T_PER_M: f64 = S::U_MAX_T_PER_M;
    const POSITION_BOUND_M: f64 = S::POSITION_BOUND_M;
    const SPEED_BOUND_M_PER_S: f64 = S::SPEED_BOUND_M_PER_S;
    const TRACKING_TIME_S: f64 = S::TRACKING_TIME_S;
    const EXTRA_DELAY_S: f64 = S::EXTRA_DELAY_S;
    const POSITION_NOISE_M: f64 = S::POSITION_NOISE_M;
    const DISTURBANCE_BOUND_SI: f64 = S::DISTURBANCE_BOUND_SI;
    const L_F: f64 = S::L_F;
    const L_L: f64 = S::L_L;
    const L_V: f64 = S::L_V;
    const X_DIAMETER: f64 = S::X_DIAMETER;
    const SWITCHING_SIGMA: f64 = S::SWITCHING_SIGMA;
    const QP_MAX_ITERATIONS: usize = S::QP_MAX_ITERATIONS;
    const TABLE_BYTES: usize = S::TABLES.bytes().len();
    const WORKSPACE_MIN_M: f64 = S::WORKSPACE_MIN_M;
    const WORKSPACE_MAX_M: f64 = S::WORKSPACE_MAX_M;
    const HAS_EXPLICIT_TIER: bool = S::TABLES.explicit_count > 0;
    const EXPLICIT_CERTIFIED_OPS: u64 = explicit_step_ops(N, NX, K, S::QP_MAX_ITERATIONS);

    fn new() -> Self {
        Solver::with_engine(E::default())
    }
    fn verify_tables() -> Result<(), TableError> {
        S::verify_tables()
    }
    fn reset(&mut self) {
        Solver::reset(self)
    }
    fn shift(&mut self, samples: usize) {
        Solver::shift(self, samples)
    }
    fn set_schedule(&mut self, samples_per_phase: usize, coast_s: f64) {
        Solver::set_schedule(self, samples_per_phase, coast_s)
    }
    fn reschedule_shot(&mut self, e: &[f64; NX], samples_per_phase: usize, coast_s: f64) -> bool {
        Solver::reschedule_shot(self, e, samples_per_phase, coast_s)
    }
    fn shoot_through_chain(&mut self, e_leg: &[f64; NX], e_final: &[f64; NX]) -> bool {
        Solver::shoot_through_chain(self, e_leg, e_final)
    }
    fn solve(&mut self, e: &[f64; NX]) -> SolveReport {
        Solver::solve(self, e)
    }
    fn solve_explicit(&mut self, e: &[f64; NX]) -> SolveReport {
        Solver::solve_explicit(self, e)
    }
    fn shot_samples(&self) -> usize {
        Solver::shot_samples(self)
    }
    fn set_shooting(&mut self, on: bool) {
        Solver::set_shooting(self, on)
    }
    fn start_cycle(&mut self) {
        Solver::start_cycle(self)
    }
    fn refinement_fits(&self) -> bool {
        Solver::refinement_fits(self)
    }
    fn set_shot_speed_tolerance(&mut self, tolerance_m_per_s: f64) {
        Solver::set_shot_speed_tolerance(self, tolerance_m_per_s)
    }
    fn set_tail_shots(&mut self, on: bool) {
        Solver::set_tail_shots(self, on)
    }
    fn want_shot(&mut self, samples: usize) {
        Solver::want_shot(self, samples)
    }
    fn set_explicit_similarity(&mut self, on: bool) {
        Solver::set_explicit_similarity(self, on)
    }
    fn adopt_explicit(&mut self) {
        Solver::adopt_explicit(self)
    }
    fn plan(&self) -> &[f64; K] {
        Solver::plan(self)
    }
    fn covers_from_rest(e: &[f64; NX]) -> bool {
        covers_from_rest(&S::TABLES, S::USE_TABLES, e)
    }
    fn first_leg(d: &[f64; NX]) -> Option<Leg<NX>> {
        first_leg(&S::TABLES, S::USE_TABLES, d)
    }
    fn chain_time_s(d: &[f64; NX]) -> f64 {
        chain_time_s(&S::TABLES, S::USE_TABLES, d)
    }
    fn coasted_time_s(d: &[f64; NX]) -> f64 {
        coasted_time_s(&S::TABLES, S::USE_TABLES, d)
    }
    fn qp_iterations_measured(e: &[f64; NX]) -> u32 {
        qp_iterations_measured(&S::TABLES, S::QP_ITERATION_MAP, e)
    }
    fn stage_cost(e: &[f64; NX], u: f64) -> f64 {
        stage_cost::<S, M, NX>(e, u)
    }
    fn predict_plan(e: &[f64; NX], plan: &[f64; K], samples: usize) -> [f64; NX] {
        predict::<S, M, NX, K>(e, plan, samples)
    }
    fn predict_constant(e: &[f64; NX], u: f64, duration_s: f64) -> [f64; NX] {
        predict_constant::<S, M, NX>(e, u, duration_s)
    }
    fn capsule_transition(i: usize, xv: [f64; 2], u: f64, duration_s: f64) -> ([f64; 2], [f64; 4]) {
        capsule_transition::<S, M, NX>(i, xv, u, duration_s)
    }
    fn set_model_scales(&mut self, scales: &[[f64; 2]]) {
        let mut s = [[1.0, 1.0]; M];
        for (d, v) in s.iter_mut().zip(scales) {
            *d = *v;
        }
        Solver::set_model_scales(self, &s);
    }
    fn capsule_transition_scaled(
        i: usize,
        xv: [f64; 2],
        u: f64,
        duration_s: f64,
        scale: [f64; 2],
    ) -> ([f64; 2], [f64; 4]) {
        capsule_transition_scaled::<S, M, NX>(i, xv, u, duration_s, scale)
    }
    fn capsule_gain(i: usize) -> f64 {
        if i < M {
            S::G[i]
        } else {
            0.0
        }
    }
    fn capsule_drag(i: usize, v: f64) -> f64 {
        if i < M {
            S::DRAG[i].accel_and_slope(v).0
        } else {
            0.0
        }
    }
}
