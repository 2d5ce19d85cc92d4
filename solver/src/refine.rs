//! The online solver: refines a long plan with Gauss-Newton SQP steps on a
//! window of N inputs, the tail's cost-to-go as terminal cost.
//!
//! Every step: (1) shift the plan by the samples already applied; (2) if a
//! stored plan tail (from the warm-start index) is cheaper from the current
//! state, take it; (3) for a fixed number of SQP iterations: roll the plan out
//! over K samples with exact RK4 Jacobians, run the tail's cost-to-go
//! backwards to step N, condense the window into an N x N box-constrained QP,
//! solve it with a primal active-set method, and accept the step only if the
//! true nonlinear cost decreases. No heap, no recursion, fixed loop bounds.
//! The explicit tier (`explicit`) gives a first answer without a rollout.

use crate::explicit::explicit_plan;
use crate::lookup::{chain_plan, lookup_fine, lookup_tail_for};
use crate::qp::{clamp_u, ActiveSet, BoxQp, QpEngine};
use crate::report::{SolveReport, SolveStatus, Tier};
use crate::rollout::{
    nominal_scales, rollout_cost_below_scaled, rollout_with_jacobians_scaled, substep_s,
    ModelScales, Schedule, StepJacobian,
};
use crate::shooting::{
    resample, Shooter, SHOT_HOLD_POSITION_TOLERANCE_M, SHOT_ITERATIONS, SHOT_MAX_LENGTHS,
    SHOT_RESHOOT_SHORTER_LENGTHS, SHOT_UNSETTLED_SAMPLES,
};
use crate::spec::Spec;
use core::marker::PhantomData;

mod flight;

/// All memory the solver uses: created once, reused every step. `S` the
/// module's constants, `M` capsules, `NX = 2 M` states, window `N`, plan
/// length `K`; `E` the refinement's QP engine.
#[derive(Debug, Clone)]
pub struct Solver<S, const M: usize, const NX: usize, const N: usize, const K: usize, E = ActiveSet>
{
    /// Current plan: `plan[0]` is the gradient for the coming sample, T/m.
    plan: [f64; K],
    /// Whether `plan` holds anything (false after reset).
    has_plan: bool,
    /// Trajectory of the plan, relative to the target: e_0..e_{K-1}, and e_K.
    states: [[f64; NX]; K],
    end_state: [f64; NX],
    jac: [StepJacobian<M>; K],
    candidate: [f64; K],
    /// Window sensitivities: sens[k - 1][j] = d e_k / d u_j (k = 1..=N).
    sens: [[[f64; NX]; N]; N],
    /// Tail cost-to-go at step N: per-capsule 2x2 Hessian and gradient.
    tail_hess: [[f64; 4]; M],
    tail_grad: [f64; NX],
    qp: BoxQp<N>,
    /// The actuation schedule the plan is refined for.
    schedule: Schedule,
    /// The explicit tier's plan of this step (see `solve_explicit`), a
    /// candidate for `plan` until the next `solve` or `adopt_explicit`.
    explicit_plan: [f64; K],
    explicit_ready: bool,
    /// Slot of the explicit tier's last stored sample (usize::MAX: none).
    explicit_slot: usize,
    /// The explicit QP's last active set, shifted with the plan: the next
    /// explicit QP's warm start (consecutive windows overlap in N - 1
    /// inputs, so their active sets mostly agree; the stored sample's set,
    /// the solution at zero deviation, took 9 iterations at the median).
    explicit_active: [i8; N],
    /// Which tier produced `plan`.
    tier: Tier,
    /// The refinement's window QP solver.
    engine: E,
    /// The model the refinement rolls plans out on: factors on each
    /// capsule's gain and drag (1: the model; see `set_model_scales`).
    scales: ModelScales<M>,
    /// Scratch of the minimum-time shooting (see `shooting`).
    shooter: Shooter<M, NX, K>,
    /// Length of the current plan when it is a converged shot (it ends at
    /// the target at rest after `shot_samples` samples); 0: not a shot.
    shot_samples: usize,
    /// Whether `solve` shoots.
    shooting: bool,
    /// Whether the explicit tier answers from the model state similar to
    /// the capsules' (see `Similarity`).
    explicit_similar: bool,
    /// The similarity for `scales`, computed when they change.
    similarity: Similarity<M>,
    /// Whether a refined plan that does not settle within the horizon
    /// looks first for a shot from the stored plan tail, as long as the
    /// tail takes to settle (see `acquire_shot`).
    tail_shots: bool,
    /// Shot length the next `solve` searches down from (`want_shot`; 0:
    /// only where the refined plan leaves the band).
    shot_wanted_samples: usize,
    spec: PhantomData<S>,
}

impl<
        S: Spec<M, NX>,
        const M: usize,
        const NX: usize,
        const N: usize,
        const K: usize,
        E: QpEngine<N> + Default,
    > Default for Solver<S, M, NX, N, K, E>
{
    fn default() -> Self {
        Self::with_engine(E::default())
    }
}

impl<S: Spec<M, NX>, const M: usize, const NX: usize, const N: usize, const K: usize>
    Solver<S, M, NX, N, K>
{
    /// A solver with no plan and the active-set engine.
    pub const fn new() -> Self {
        Self::with_engine(ActiveSet)
    }
}

impl<
        S: Spec<M, NX>,
        const M: usize,
        const NX: usize,
        const N: usize,
        const K: usize,
        E: QpEngine<N>,
    > Solver<S, M, NX, N, K, E>
{
    /// A solver with no plan whose refinement solves its window QPs with `engine`.
    pub const fn with_engine(engine: E) -> Self {
        const { assert!(NX == 2 * M && N >= 1 && N <= K) };
        Solver {
            plan: [0.0; K],
            has_plan: false,
            states: [[0.0; NX]; K],
            end_state: [0.0; NX],
            jac: [StepJacobian::ZERO; K],
            candidate: [0.0; K],
            sens: [[[0.0; NX]; N]; N],
            tail_hess: [[0.0; 4]; M],
            tail_grad: [0.0; NX],
            qp: BoxQp::new(S::QP_MAX_ITERATIONS, S::QP_MULTIPLIER_TOLERANCE),
            schedule: Schedule::BACK_TO_BACK,
            explicit_plan: [0.0; K],
            explicit_ready: false,
            explicit_slot: usize::MAX,
            explicit_active: [0; N],
            tier: Tier::Refined,
            engine,
            scales: nominal_scales(),
            shooter: Shooter::new(),
            shot_samples: 0,
            shooting: false,
            explicit_similar: false,
            similarity: Similarity::IDENTITY,
            tail_shots: false,
            shot_wanted_samples: 0,
            spec: PhantomData,
        }
    }

    /// Rolls plans out on the model with each capsule's gain and drag
    /// scaled by `scales[i]` (the runtime's estimate of the real capsules;
    /// stored plans stay the model's, and the explicit tier too unless
    /// `set_explicit_similarity`).
    pub fn set_model_scales(&mut self, scales: &ModelScales<M>) {
        self.scales = *scales;
        self.similarity = Similarity::of(scales);
    }

    /// The refinement's QP engine.
    pub fn engine(&self) -> &E {
        &self.engine
    }

    /// The window QP of the last refinement iteration (H, g, box, answer).
    pub fn window_qp(&self) -> &BoxQp<N> {
        &self.qp
    }

    /// The schedule of `samples_per_phase` samples per phase, each followed
    /// by `coast_s` of zero gradient, for this module's plan length and RK4 step.
    pub fn schedule_for(samples_per_phase: usize, coast_s: f64) -> Schedule {
        Schedule::new(samples_per_phase, coast_s, K, substep_s::<S, M, NX>())
    }

    /// Sets the actuation schedule the plan is refined for.
    pub fn set_schedule(&mut self, samples_per_phase: usize, coast_s: f64) {
        self.schedule = Self::schedule_for(samples_per_phase, coast_s);
    }

    /// The schedule the plan is refined for.
    pub fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    /// Forgets the plan (new target, or after a fault).
    pub fn reset(&mut self) {
        self.plan = [0.0; K];
        self.has_plan = false;
        self.shot_samples = 0;
        self.explicit_ready = false;
        self.explicit_slot = usize::MAX;
        self.explicit_active = [0; N];
    }

    /// The explicit tier from `e` (see the `explicit` module): the stored
    /// sample's window QP at the deviation, no rollout. The plan becomes a
    /// candidate: `adopt_explicit` makes it the plan, or the next `solve`
    /// weighs it by its true cost. `cost` in the report is the
    /// Gauss-Newton model's prediction, not a rollout.
    pub fn solve_explicit(&mut self, e: &[f64; NX]) -> SolveReport {
        let mut report = SolveReport {
            status: SolveStatus::Refined,
            cost: 0.0,
            took_table_plan: true,
            qp_iterations: 0,
            max_qp_iterations: 0,
            tier: Tier::Explicit,
        };
        let coasted = self.schedule.coasted();
        let (e, input_scale) = if self.explicit_similar {
            self.similarity.model_state(e)
        } else {
            (*e, 1.0)
        };
        let e = &e;
        // The stored plans keep every position error within the state
        // bound; beyond it no sample's linearization holds (followed out
        // there, a capsule went 150 mm off): out of range, the fallback.
        let beyond_bound = (0..NX / 2).any(|i| !(libm::fabs(e[2 * i]) <= S::POSITION_BOUND_M));
        let warm = if self.explicit_slot == usize::MAX {
            None
        } else {
            Some(&self.explicit_active)
        };
        let tables = &S::TABLES;
        let found = if beyond_bound {
            None
        } else {
            explicit_plan(
                tables,
                S::U_MAX_T_PER_M,
                e,
                coasted,
                self.explicit_slot,
                warm,
                &mut self.qp,
                &mut self.explicit_plan,
            )
        };
        match found {
            Some(out) => {
                for u in self.explicit_plan.iter_mut() {
                    *u = clamp_u(*u * input_scale, S::U_MAX_T_PER_M);
                }
                self.explicit_ready = true;
                self.explicit_slot = out.slot;
                self.explicit_active = self.qp.active;
                report.cost = out.predicted_cost;
                report.qp_iterations = out.qp_iterations;
                report.max_qp_iterations = out.qp_iterations;
                if !out.converged {
                    report.status = SolveStatus::IterationLimit;
                }
            }
            None => {
                self.explicit_ready = false;
                self.explicit_slot = usize::MAX;
                report.status = SolveStatus::OutOfRange;
                report.cost = f64::INFINITY;
                report.took_table_plan = false;
            }
        }
        report
    }

    /// Makes the explicit tier's plan (from `solve_explicit`) the plan.
    pub fn adopt_explicit(&mut self) {
        if self.explicit_ready {
            self.plan = self.explicit_plan;
            self.has_plan = true;
            self.shot_samples = 0;
            self.explicit_ready = false;
            self.tier = Tier::Explicit;
        }
    }

    /// The explicit tier's plan of the last `solve_explicit`.
    pub fn explicit_plan(&self) -> &[f64; K] {
        &self.explicit_plan
    }

    /// Starts a control cycle: the shooting's compute budget is restored
    /// (every solve until the next call shares it).
    pub fn start_cycle(&mut self) {
        self.shooter.start_budget();
    }

    /// Whether another refinement fits this cycle's compute budget (each
    /// `solve` takes a refinement's share, its shots what they roll out).
    pub fn refinement_fits(&self) -> bool {
        self.shooter.refinement_fits()
    }

    /// A converged shot's terminal speed tolerance, m/s.
    pub fn set_shot_speed_tolerance(&mut self, tolerance_m_per_s: f64) {
        self.shooter.set_speed_tolerance(tolerance_m_per_s);
    }

    /// Whether a refined plan that does not settle within the horizon
    /// looks first for a shot seeded from the stored plan tail, as long as
    /// the tail's stored settle sample (else only the short shot of
    /// `SHOT_UNSETTLED_SAMPLES` from the refined plan).
    pub fn set_tail_shots(&mut self, on: bool) {
        self.tail_shots = on;
    }

    /// Whether the explicit tier answers capsules off the model (the
    /// factors of `set_model_scales`) from the model state similar to
    /// theirs, its gradient rescaled; off: the model's answer for their
    /// state. For the law alone: under the refinement, which rolls out
    /// on the factors, it let a glitch's biased factors hold a capsule
    /// 0.5 mm off (docs/decisions.md).
    pub fn set_explicit_similarity(&mut self, on: bool) {
        self.explicit_similar = on;
    }

    /// Asks the next `solve` for a shot searched from `samples` down (the
    /// shortest that converges) even where the refined plan stays in the
    /// settle band; 0 withdraws the request:
    /// inside the band the refinement's plans barely move the capsules, and
    /// three capsules' third combination needs a manoeuvre out of it.
    pub fn want_shot(&mut self, samples: usize) {
        self.shot_wanted_samples = samples.min(K);
    }

    /// Whether `solve` looks for minimum-time shots; off drops the shot.
    pub fn set_shooting(&mut self, on: bool) {
        self.shooting = on;
        if !on {
            self.shot_samples = 0;
        }
    }

    /// Samples left of the current shot (0: the plan is not a shot).
    pub fn shot_samples(&self) -> usize {
        self.shot_samples
    }

    /// The current plan (gradient per sample, T/m), `plan()[0]` first.
    pub fn plan(&self) -> &[f64; K] {
        &self.plan
    }

    /// Drops the first `samples` inputs (they have been applied) and pads
    /// with zero gradient.
    pub fn shift(&mut self, samples: usize) {
        let s = if samples > K { K } else { samples };
        self.shot_samples = self.shot_samples.saturating_sub(s);
        let mut i = 0;
        while i < K {
            self.plan[i] = if i + s < K { self.plan[i + s] } else { 0.0 };
            i += 1;
        }
        let mut a = 0;
        while a < N {
            self.explicit_active[a] = if a + s < N {
                self.explicit_active[a + s]
            } else {
                0
            };
            a += 1;
        }
    }

    /// Rolls the current plan out from `e` into `states`, `end_state` and `jac`.
    fn roll_out(&mut self, e: &[f64; NX]) -> f64 {
        rollout_with_jacobians_scaled::<S, M, NX, K>(
            e,
            &self.plan,
            &self.schedule,
            &self.scales,
            &mut self.states,
            &mut self.end_state,
            &mut self.jac,
        )
    }

    /// Refines the plan from relative state `e = x - x_target`.
    pub fn solve(&mut self, e: &[f64; NX]) -> SolveReport {
        let shooting = self.shooting;
        let wanted_samples = core::mem::take(&mut self.shot_wanted_samples);
        if shooting && self.has_plan && self.shot_samples > 0 {
            if let Some(report) = self.reshoot(e) {
                return report;
            }
        }
        let mut report = self.solve_refined(e);
        self.shooter.charge_refinement();
        if shooting && report.status != SolveStatus::OutOfRange {
            self.acquire_shot(e, &mut report, wanted_samples);
        }
        report
    }

    /// The refinement proper (see the module docs).
    fn solve_refined(&mut self, e: &[f64; NX]) -> SolveReport {
        self.shot_samples = 0;
        let mut report = SolveReport {
            status: SolveStatus::Refined,
            cost: 0.0,
            took_table_plan: false,
            qp_iterations: 0,
            max_qp_iterations: 0,
            tier: self.tier,
        };
        // `fresh`: `states` and `jac` belong to the current `plan`, so the
        // first SQP iteration need not roll it out again.
        let mut fresh = false;
        let mut cost = if self.has_plan {
            fresh = true;
            self.roll_out(e)
        } else {
            f64::INFINITY
        };
        if S::USE_TABLES {
            let tables = &S::TABLES;
            let coasted = self.schedule.coasted();
            // Without a plan, at rest near the target: a fine plan (the
            // main grid's nearest one would be empty).
            let fine =
                !self.has_plan && lookup_fine(tables, e, &mut self.candidate, coasted).is_some();
            let found = if fine {
                Some(())
            } else {
                lookup_tail_for(tables, e, &mut self.candidate, coasted).map(|_| ())
            };
            match found {
                Some(()) => {
                    let c = rollout_cost_below_scaled::<S, M, NX, K>(
                        e,
                        &self.candidate,
                        &self.schedule,
                        &self.scales,
                        cost,
                    );
                    if c < cost {
                        self.plan = self.candidate;
                        cost = c;
                        fresh = false;
                        report.took_table_plan = true;
                        self.tier = Tier::Refined;
                    }
                }
                None if !self.has_plan && !self.explicit_ready => {
                    report.status = SolveStatus::OutOfRange;
                    report.cost = f64::INFINITY;
                    return report;
                }
                None => {}
            }
        }
        // Whatever plan the refinement starts from (the shifted one or a
        // stored tail) is its choice; the explicit plan of this step, if
        // any, competes with the refined plan at the end, on its true cost.
        // Why at the end and not as the SQP's start: started from the
        // explicit plan (cheaper on the quadratic cost at times), the
        // closed loop settled later (A ideal 0.84 s against 0.52 s).
        self.tier = Tier::Refined;
        let mut explicit_pending = self.explicit_ready;
        self.explicit_ready = false;
        if explicit_pending && cost == f64::INFINITY {
            // No plan and no stored tail: the explicit plan is the start.
            self.plan = self.explicit_plan;
            cost = rollout_cost_below_scaled::<S, M, NX, K>(
                e,
                &self.plan,
                &self.schedule,
                &self.scales,
                f64::INFINITY,
            );
            fresh = false;
            self.tier = Tier::Explicit;
            explicit_pending = false;
        }
        self.has_plan = true;
        let mut it = 0;
        while it < S::SQP_ITERATIONS {
            if !fresh {
                self.roll_out(e);
            }
            let (new_cost, qp_iters, converged) = self.sqp_iteration(e, cost);
            // The plan changed only if the line search lowered the cost.
            fresh = !(new_cost < cost);
            if new_cost < cost {
                self.tier = Tier::Refined;
            }
            cost = new_cost;
            report.qp_iterations += qp_iters;
            if qp_iters > report.max_qp_iterations {
                report.max_qp_iterations = qp_iters;
            }
            if !converged {
                report.status = SolveStatus::IterationLimit;
            }
            it += 1;
        }
        if explicit_pending {
            let c = rollout_cost_below_scaled::<S, M, NX, K>(
                e,
                &self.explicit_plan,
                &self.schedule,
                &self.scales,
                cost,
            );
            if c < cost {
                // `states` and `jac` still describe the refined plan; the
                // next solve rolls the plan out again (`fresh` is per call).
                self.plan = self.explicit_plan;
                cost = c;
                self.tier = Tier::Explicit;
            }
        }
        report.cost = cost;
        report.tier = self.tier;
        report
    }

    /// One SQP iteration from the rolled-out `states` and `jac` of `plan`;
    /// returns (cost after, QP iterations, QP converged).
    fn sqp_iteration(&mut self, e: &[f64; NX], cost: f64) -> (f64, u32, bool) {
        self.tail_cost_to_go();
        self.window_sensitivities();
        self.condense();
        let (iters, converged) = self.engine.solve(&mut self.qp);
        // Backtracking on the true cost; the plan stays feasible (|u| <= u_max).
        let mut step = 1.0;
        let mut tries = 0;
        while tries < S::LINE_SEARCH_TRIES {
            self.candidate = self.plan;
            let mut j = 0;
            while j < N {
                self.candidate[j] = clamp_u(self.plan[j] + step * self.qp.x[j], S::U_MAX_T_PER_M);
                j += 1;
            }
            let c = rollout_cost_below_scaled::<S, M, NX, K>(
                e,
                &self.candidate,
                &self.schedule,
                &self.scales,
                cost,
            );
            if c < cost {
                self.plan = self.candidate;
                return (c, iters, converged);
            }
            step *= 0.5;
            tries += 1;
        }
        (cost, iters, converged)
    }

    /// The rolled-out state e_k (k = 0..=K).
    #[inline(always)]
    fn state(&self, k: usize) -> &[f64; NX] {
        if k < K {
            &self.states[k]
        } else {
            &self.end_state
        }
    }

    /// Gauss-Newton cost-to-go of the fixed tail, from K back to N:
    /// H_k = W_k + A_k' H_{k+1} A_k, g_k = W_k e_k + A_k' g_{k+1}.
    fn tail_cost_to_go(&mut self) {
        let mut i = 0;
        while i < M {
            let (xi, vi) = (2 * i, 2 * i + 1);
            let end = self.state(K);
            let mut h = [S::P[xi], 0.0, 0.0, S::P[vi]];
            let mut g = [S::P[xi] * end[xi], S::P[vi] * end[vi]];
            let mut k = K;
            while k > N {
                k -= 1;
                let a = &self.jac[k].a[i];
                // A' H A with A = [a0 a1; a2 a3], H symmetric [h0 h1; h1 h3].
                let t0 = h[0] * a[0] + h[1] * a[2];
                let t1 = h[0] * a[1] + h[1] * a[3];
                let t2 = h[1] * a[0] + h[3] * a[2];
                let t3 = h[1] * a[1] + h[3] * a[3];
                let n0 = a[0] * t0 + a[2] * t2 + S::Q[xi];
                let n1 = a[0] * t1 + a[2] * t3;
                let n3 = a[1] * t1 + a[3] * t3 + S::Q[vi];
                h = [n0, n1, n1, n3];
                let g0 = a[0] * g[0] + a[2] * g[1] + S::Q[xi] * self.states[k][xi];
                let g1 = a[1] * g[0] + a[3] * g[1] + S::Q[vi] * self.states[k][vi];
                g = [g0, g1];
            }
            self.tail_hess[i] = h;
            self.tail_grad[xi] = g[0];
            self.tail_grad[vi] = g[1];
            i += 1;
        }
    }

    /// sens[k - 1][j] = d e_k / d u_j for 1 <= k <= N, j < k.
    fn window_sensitivities(&mut self) {
        let mut k = 0;
        while k < N {
            let mut i = 0;
            while i < M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                let a = self.jac[k].a[i];
                let mut j = 0;
                while j < k {
                    // d e_k / d u_j is sens[k - 1][j] (k >= 1 here since j < k).
                    let (s0, s1) = (self.sens[k - 1][j][xi], self.sens[k - 1][j][vi]);
                    self.sens[k][j][xi] = a[0] * s0 + a[1] * s1;
                    self.sens[k][j][vi] = a[2] * s0 + a[3] * s1;
                    j += 1;
                }
                self.sens[k][k][xi] = self.jac[k].b[i][0];
                self.sens[k][k][vi] = self.jac[k].b[i][1];
                i += 1;
            }
            k += 1;
        }
    }

    /// Builds the window QP: H = sum S'QS + S_N' H_N S_N + R I, g likewise.
    fn condense(&mut self) {
        let qp = &mut self.qp;
        let mut a = 0;
        while a < N {
            let mut g = S::R * self.plan[a];
            let mut b = a;
            while b < N {
                qp.h[a][b] = if a == b { S::R } else { 0.0 };
                b += 1;
            }
            // Stage terms k = a+1 .. N-1.
            let mut k = a + 1;
            while k < N {
                let sa = &self.sens[k - 1][a];
                let mut r = 0;
                while r < NX {
                    g += sa[r] * S::Q[r] * self.states[k][r];
                    r += 1;
                }
                let mut b = a;
                while b < k {
                    let sb = &self.sens[k - 1][b];
                    let mut acc = 0.0;
                    let mut r = 0;
                    while r < NX {
                        acc += sa[r] * S::Q[r] * sb[r];
                        r += 1;
                    }
                    qp.h[a][b] += acc;
                    b += 1;
                }
                k += 1;
            }
            // Terminal (tail cost-to-go) at N.
            let sa = &self.sens[N - 1][a];
            let mut i = 0;
            while i < M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                g += sa[xi] * self.tail_grad[xi] + sa[vi] * self.tail_grad[vi];
                let hh = &self.tail_hess[i];
                let mut b = a;
                while b < N {
                    let sb = &self.sens[N - 1][b];
                    qp.h[a][b] += sa[xi] * (hh[0] * sb[xi] + hh[1] * sb[vi])
                        + sa[vi] * (hh[2] * sb[xi] + hh[3] * sb[vi]);
                    b += 1;
                }
                i += 1;
            }
            qp.g[a] = g;
            qp.lo[a] = -S::U_MAX_T_PER_M - self.plan[a];
            qp.hi[a] = S::U_MAX_T_PER_M - self.plan[a];
            a += 1;
        }
        // Mirror the upper triangle.
        let mut a = 0;
        while a < N {
            let mut b = 0;
            while b < a {
                qp.h[a][b] = qp.h[b][a];
                b += 1;
            }
            a += 1;
        }
    }
}

/// The model's states similar to capsules whose gain and drag are
/// `scales[i]` times the model's. A capsule `x'' = s_g g u - s_b b x'|x'|`
/// at `x` moves as the model's capsule at `s_b x` under `s_g s_b u`. The
/// capsules share the gradient: it is divided by the geometric mean `p`
/// of their products `s_g s_b`, and each capsule's error and speed are
/// scaled by `p / s_g`, so that every capsule's gain is the model's and
/// only the spread of the products is left, as drag (exact when the
/// products agree). The identity on the model.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Similarity<const M: usize> {
    /// Per capsule, the factor on its error and speed.
    state_scale: [f64; M],
    /// The factor on the model's answer, the gradient.
    input_scale: f64,
}

impl<const M: usize> Similarity<M> {
    const IDENTITY: Self = Similarity {
        state_scale: [1.0; M],
        input_scale: 1.0,
    };

    fn of(scales: &ModelScales<M>) -> Self {
        let product: f64 = scales.iter().map(|s| s[0] * s[1]).product();
        let mean_product = libm::pow(product, 1.0 / M as f64);
        let mut state_scale = [1.0; M];
        for (k, s) in state_scale.iter_mut().zip(scales) {
            *k = mean_product / s[0];
        }
        Similarity {
            state_scale,
            input_scale: 1.0 / mean_product,
        }
    }

    /// The model's state similar to `e`, and the factor on its answer.
    fn model_state<const NX: usize>(&self, e: &[f64; NX]) -> ([f64; NX], f64) {
        let mut model = *e;
        for (i, k) in self.state_scale.iter().enumerate() {
            model[2 * i] *= k;
            model[2 * i + 1] *= k;
        }
        (model, self.input_scale)
    }
}
