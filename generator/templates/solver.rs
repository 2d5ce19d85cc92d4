//! Fixed-size online solver: refines a long plan with Gauss-Newton SQP steps
//! on a window of N inputs, the tail's cost-to-go as terminal cost.
//!
//! Every step: (1) shift the plan by the samples already applied; (2) if a
//! stored plan tail (from the warm-start index) is cheaper from the current
//! state, take it; (3) for a fixed number of SQP iterations: roll the plan out
//! over K samples with exact RK4 Jacobians, run the tail's cost-to-go
//! backwards to step N, condense the window into an N x N box-constrained QP,
//! solve it with a primal active-set method, and accept the step only if the
//! true nonlinear cost decreases. No heap, no recursion, fixed loop bounds.

use super::lookup::*;
use super::qp::*;
use super::spec::*;
use super::tables::*;
use crate::{Leg, PlanSolver, SolveReport, SolveStatus, Tier};

/// Per-capsule 2x2 Jacobian (row major) and input column of one sample.
#[derive(Debug, Clone, Copy)]
struct StepJacobian {
    a: [[f64; 4]; M],
    b: [[f64; 2]; M],
}

const ZERO_JACOBIAN: StepJacobian = StepJacobian {
    a: [[0.0; 4]; M],
    b: [[0.0; 2]; M],
};

/// All memory the solver uses: created once, reused every step.
#[derive(Debug, Clone)]
pub struct Solver {
    /// Current plan: `plan[0]` is the gradient for the coming sample, T/m.
    plan: [f64; K],
    /// Whether `plan` holds anything (false after reset).
    has_plan: bool,
    /// Trajectory of the plan, relative to the target.
    states: [[f64; NX]; K + 1],
    jac: [StepJacobian; K],
    candidate: [f64; K],
    /// Window sensitivities: sens[k][j] = d e_k / d u_j (k = 0..N).
    sens: [[[f64; NX]; N]; N + 1],
    /// Tail cost-to-go at step N: per-capsule 2x2 Hessian and gradient.
    tail_hess: [[f64; 4]; M],
    tail_grad: [f64; NX],
    qp: BoxQp,
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
}

/// How the scanner plays the plan: actuation phases of `samples_per_phase`
/// samples back to back, each followed by a zero-gradient coast (tracking
/// + delay). Ideal sampling has no coast. Modelling the gaps makes the
/// plan match what is played, so re-plans do not fight them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Samples per actuation phase (>= 1).
    samples_per_phase: usize,
    /// RK4 sub-steps of the coast after each phase (0: no coast).
    coast_steps: usize,
    /// Sub-step length, s.
    coast_h_s: f64,
}

/// Longest coast a schedule models after a phase, s: the runtime accepts
/// tracking and extra delay of up to 1 s each.
pub const MAX_COAST_S: f64 = 2.0;

impl Schedule {
    pub const BACK_TO_BACK: Schedule = Schedule {
        samples_per_phase: K,
        coast_steps: 0,
        coast_h_s: 0.0,
    };

    /// Phases of `samples_per_phase` samples (clamped to 1..=K), each
    /// followed by `coast_s` (clamped to 0..=MAX_COAST_S; NaN reads as 0).
    pub fn new(samples_per_phase: usize, coast_s: f64) -> Schedule {
        let c = if coast_s > MAX_COAST_S {
            MAX_COAST_S
        } else if coast_s > 0.0 {
            coast_s
        } else {
            return Schedule::BACK_TO_BACK;
        };
        let max_h = DT_S / RK4_SUBSTEPS as f64;
        let steps = libm::ceil(c / max_h) as usize;
        Schedule {
            samples_per_phase: if samples_per_phase == 0 {
                1
            } else if samples_per_phase > K {
                K
            } else {
                samples_per_phase
            },
            coast_steps: steps,
            coast_h_s: c / steps as f64,
        }
    }

    /// One sample per phase with a coast after it: constant sampling's
    /// schedule, which has tables of its own.
    #[inline]
    fn coasted(&self) -> bool {
        self.coast_steps > 0 && self.samples_per_phase == 1
    }

    /// Whether a coast follows plan sample `k`.
    #[inline]
    fn coasts_after(&self, k: usize) -> bool {
        self.coast_steps > 0 && (k + 1) % self.samples_per_phase == 0
    }
}

impl Default for Solver {
    fn default() -> Self {
        Solver::new()
    }
}

impl Solver {
    pub const fn new() -> Solver {
        Solver {
            plan: [0.0; K],
            has_plan: false,
            states: [[0.0; NX]; K + 1],
            jac: [ZERO_JACOBIAN; K],
            candidate: [0.0; K],
            sens: [[[0.0; NX]; N]; N + 1],
            tail_hess: [[0.0; 4]; M],
            tail_grad: [0.0; NX],
            qp: BoxQp::new(),
            schedule: Schedule::BACK_TO_BACK,
            explicit_plan: [0.0; K],
            explicit_ready: false,
            explicit_slot: usize::MAX,
            explicit_active: [0; N],
            tier: Tier::Refined,
        }
    }

    /// Sets the actuation schedule the plan is refined for.
    pub fn set_schedule(&mut self, samples_per_phase: usize, coast_s: f64) {
        self.schedule = Schedule::new(samples_per_phase, coast_s);
    }

    /// Forgets the plan (new target, or after a fault).
    pub fn reset(&mut self) {
        self.plan = [0.0; K];
        self.has_plan = false;
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
        let warm = if self.explicit_slot == usize::MAX {
            None
        } else {
            Some(&self.explicit_active)
        };
        match super::explicit::explicit_plan(e, coasted, self.explicit_slot, warm, &mut self.qp, &mut self.explicit_plan) {
            Some(out) => {
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
            self.explicit_ready = false;
            self.tier = Tier::Explicit;
        }
    }

    /// The explicit tier's plan of the last `solve_explicit`.
    pub fn explicit_plan(&self) -> &[f64; K] {
        &self.explicit_plan
    }

    /// The current plan (gradient per sample, T/m), `plan()[0]` first.
    pub fn plan(&self) -> &[f64; K] {
        &self.plan
    }

    /// Predicted relative states along the refined plan (valid after a
    /// `solve` whose report names `Tier::Refined`).
    pub fn predicted_states(&self) -> &[[f64; NX]; K + 1] {
        &self.states
    }

    /// Drops the first `samples` inputs (they have been applied) and pads
    /// with zero gradient.
    pub fn shift(&mut self, samples: usize) {
        let s = if samples > K { K } else { samples };
        let mut i = 0;
        while i < K {
            self.plan[i] = if i + s < K { self.plan[i + s] } else { 0.0 };
            i += 1;
        }
        let mut a = 0;
        while a < N {
            self.explicit_active[a] = if a + s < N { self.explicit_active[a + s] } else { 0 };
            a += 1;
        }
    }

    /// Whether a start at rest at relative position `e` (speeds ignored) is
    /// covered by a stored plan that reaches its target.
    pub fn covers_from_rest(e: &[f64; NX]) -> bool {
        if !USE_TABLES {
            return true;
        }
        let mut flat = 0usize;
        let mut i = 0;
        while i < M {
            match axis_nearest(&PLAN_AXIS, e[2 * i]) {
                Some(j) => flat = flat * PLAN_AXIS.count + j,
                None => return false,
            }
            i += 1;
        }
        PLAN_REACHED[flat]
    }

    /// Refines the plan from relative state `e = x - x_target`.
    pub fn solve(&mut self, e: &[f64; NX]) -> SolveReport {
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
            rollout_with_jacobians(e, &self.plan, &self.schedule, &mut self.states, &mut self.jac)
        } else {
            f64::INFINITY
        };
        if USE_TABLES {
            let coasted = self.schedule.coasted();
            // Without a plan, at rest near the target: a fine plan (the
            // main grid's nearest one would be empty).
            let fine = !self.has_plan && lookup_fine(e, &mut self.candidate, coasted).is_some();
            let found = if fine {
                Some(())
            } else {
                lookup_tail_for(e, &mut self.candidate, coasted)
            };
            match found {
                Some(()) => {
                    let c = rollout_cost_below(e, &self.candidate, &self.schedule, cost);
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
            cost = rollout_cost(e, &self.plan, &self.schedule);
            fresh = false;
            self.tier = Tier::Explicit;
            explicit_pending = false;
        }
        self.has_plan = true;
        let mut it = 0;
        while it < SQP_ITERATIONS {
            if !fresh {
                rollout_with_jacobians(e, &self.plan, &self.schedule, &mut self.states, &mut self.jac);
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
            let c = rollout_cost_below(e, &self.explicit_plan, &self.schedule, cost);
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
        let (iters, converged) = self.qp.solve();
        // Backtracking on the true cost; the plan stays feasible (|u| <= u_max).
        let mut step = 1.0;
        let mut tries = 0;
        while tries < LINE_SEARCH_TRIES {
            self.candidate = self.plan;
            let mut j = 0;
            while j < N {
                self.candidate[j] = clamp_u(self.plan[j] + step * self.qp.x[j]);
                j += 1;
            }
            let c = rollout_cost_below(e, &self.candidate, &self.schedule, cost);
            if c < cost {
                self.plan = self.candidate;
                return (c, iters, converged);
            }
            step *= 0.5;
            tries += 1;
        }
        (cost, iters, converged)
    }

    /// Gauss-Newton cost-to-go of the fixed tail, from K back to N:
    /// H_k = W_k + A_k' H_{k+1} A_k, g_k = W_k e_k + A_k' g_{k+1}.
    fn tail_cost_to_go(&mut self) {
        let mut i = 0;
        while i < M {
            let (xi, vi) = (2 * i, 2 * i + 1);
            let mut h = [P[xi], 0.0, 0.0, P[vi]];
            let mut g = [P[xi] * self.states[K][xi], P[vi] * self.states[K][vi]];
            let mut k = K;
            while k > N {
                k -= 1;
                let a = &self.jac[k].a[i];
                // A' H A with A = [a0 a1; a2 a3], H symmetric [h0 h1; h1 h3].
                let t0 = h[0] * a[0] + h[1] * a[2];
                let t1 = h[0] * a[1] + h[1] * a[3];
                let t2 = h[1] * a[0] + h[3] * a[2];
                let t3 = h[1] * a[1] + h[3] * a[3];
                let n0 = a[0] * t0 + a[2] * t2 + Q[xi];
                let n1 = a[0] * t1 + a[2] * t3;
                let n3 = a[1] * t1 + a[3] * t3 + Q[vi];
                h = [n0, n1, n1, n3];
                let g0 = a[0] * g[0] + a[2] * g[1] + Q[xi] * self.states[k][xi];
                let g1 = a[1] * g[0] + a[3] * g[1] + Q[vi] * self.states[k][vi];
                g = [g0, g1];
            }
            self.tail_hess[i] = h;
            self.tail_grad[xi] = g[0];
            self.tail_grad[vi] = g[1];
            i += 1;
        }
    }

    /// sens[k][j] = d e_k / d u_j for k <= N, j < k.
    fn window_sensitivities(&mut self) {
        let mut k = 0;
        while k < N {
            let mut i = 0;
            while i < M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                let a = &self.jac[k].a[i];
                let mut j = 0;
                while j < k {
                    let (s0, s1) = (self.sens[k][j][xi], self.sens[k][j][vi]);
                    self.sens[k + 1][j][xi] = a[0] * s0 + a[1] * s1;
                    self.sens[k + 1][j][vi] = a[2] * s0 + a[3] * s1;
                    j += 1;
                }
                self.sens[k + 1][k][xi] = self.jac[k].b[i][0];
                self.sens[k + 1][k][vi] = self.jac[k].b[i][1];
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
            let mut g = R * self.plan[a];
            let mut b = a;
            while b < N {
                qp.h[a][b] = if a == b { R } else { 0.0 };
                b += 1;
            }
            // Stage terms k = a+1 .. N-1.
            let mut k = a + 1;
            while k < N {
                let sa = &self.sens[k][a];
                let mut r = 0;
                while r < NX {
                    g += sa[r] * Q[r] * self.states[k][r];
                    r += 1;
                }
                let mut b = a;
                while b < k {
                    let sb = &self.sens[k][b];
                    let mut acc = 0.0;
                    let mut r = 0;
                    while r < NX {
                        acc += sa[r] * Q[r] * sb[r];
                        r += 1;
                    }
                    qp.h[a][b] += acc;
                    b += 1;
                }
                k += 1;
            }
            // Terminal (tail cost-to-go) at N.
            let sa = &self.sens[N][a];
            let mut i = 0;
            while i < M {
                let (xi, vi) = (2 * i, 2 * i + 1);
                g += sa[xi] * self.tail_grad[xi] + sa[vi] * self.tail_grad[vi];
                let hh = &self.tail_hess[i];
                let mut b = a;
                while b < N {
                    let sb = &self.sens[N][b];
                    qp.h[a][b] += sa[xi] * (hh[0] * sb[xi] + hh[1] * sb[vi])
                        + sa[vi] * (hh[2] * sb[xi] + hh[3] * sb[vi]);
                    b += 1;
                }
                i += 1;
            }
            qp.g[a] = g;
            qp.lo[a] = -U_MAX_T_PER_M - self.plan[a];
            qp.hi[a] = U_MAX_T_PER_M - self.plan[a];
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

/// One RK4 step of capsule `i` with forward sensitivities over `h` seconds.
#[inline(always)]
fn rk4_capsule(i: usize, x: f64, v: f64, u: f64, h: f64) -> ([f64; 2], [f64; 4], [f64; 2]) {
    const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
    const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];
    let mut k_prev_v = 0.0;
    let mut dk_prev = [0.0f64; 2]; // d k_prev[v] / d (x0, v0)
    let mut dku_prev = 0.0;
    let mut next = [x, v];
    let mut a = [1.0, 0.0, 0.0, 1.0];
    let mut b = [0.0, 0.0];
    let mut stage = 0;
    while stage < 4 {
        let ch = C[stage] * h;
        let vs = v + ch * k_prev_v;
        let dv = [ch * dk_prev[0], 1.0 + ch * dk_prev[1]];
        let dvu = ch * dku_prev;
        let (acc, slope) = drag(i, vs);
        let kv = acc + G[i] * u;
        let wh = W[stage] * h / 6.0;
        next[0] += wh * vs;
        next[1] += wh * kv;
        a[0] += wh * dv[0];
        a[1] += wh * dv[1];
        a[2] += wh * slope * dv[0];
        a[3] += wh * slope * dv[1];
        b[0] += wh * dvu;
        b[1] += wh * (slope * dvu + G[i]);
        k_prev_v = kv;
        dk_prev = [slope * dv[0], slope * dv[1]];
        dku_prev = slope * dvu + G[i];
        stage += 1;
    }
    (next, a, b)
}

/// 2x2 product p q (row major): chains sub-step Jacobians.
#[inline(always)]
fn mat2_mul(p: &[f64; 4], q: &[f64; 4]) -> [f64; 4] {
    [
        p[0] * q[0] + p[1] * q[2],
        p[0] * q[1] + p[1] * q[3],
        p[2] * q[0] + p[3] * q[2],
        p[2] * q[1] + p[3] * q[3],
    ]
}

/// Plan sample `k` (RK4_SUBSTEPS sub-steps) of every capsule and the
/// schedule's coast after it, if any; with `JAC`, also the sample's
/// per-capsule Jacobians into `jac`.
///
/// Why all capsules at once: a rollout is latency-bound (each RK4 stage
/// waits on the last), and the capsules' chains are independent. Stepping
/// them side by side, sub-step by sub-step, lets the CPU overlap them. Per
/// capsule the arithmetic is unchanged, bit for bit.
#[inline(always)]
fn sample_all<const JAC: bool>(e: &mut [f64; NX], u: f64, k: usize, schedule: &Schedule, jac: &mut StepJacobian) {
    let h = DT_S / RK4_SUBSTEPS as f64;
    if JAC {
        *jac = StepJacobian {
            a: [[1.0, 0.0, 0.0, 1.0]; M],
            b: [[0.0, 0.0]; M],
        };
    }
    let mut n = 0;
    while n < RK4_SUBSTEPS {
        let mut i = 0;
        while i < M {
            let (next, sa, sb) = rk4_capsule(i, e[2 * i], e[2 * i + 1], u, h);
            if JAC {
                let b = jac.b[i];
                jac.a[i] = mat2_mul(&sa, &jac.a[i]);
                jac.b[i] = [
                    sa[0] * b[0] + sa[1] * b[1] + sb[0],
                    sa[2] * b[0] + sa[3] * b[1] + sb[1],
                ];
            }
            e[2 * i] = next[0];
            e[2 * i + 1] = next[1];
            i += 1;
        }
        n += 1;
    }
    let coast_steps = if schedule.coasts_after(k) {
        schedule.coast_steps
    } else {
        0
    };
    let mut n = 0;
    while n < coast_steps {
        let mut i = 0;
        while i < M {
            let (next, sa, _) = rk4_capsule(i, e[2 * i], e[2 * i + 1], 0.0, schedule.coast_h_s);
            if JAC {
                let b = jac.b[i];
                jac.a[i] = mat2_mul(&sa, &jac.a[i]);
                jac.b[i] = [sa[0] * b[0] + sa[1] * b[1], sa[2] * b[0] + sa[3] * b[1]];
            }
            e[2 * i] = next[0];
            e[2 * i + 1] = next[1];
            i += 1;
        }
        n += 1;
    }
}

fn stage_cost(e: &[f64; NX], u: f64) -> f64 {
    let mut c = R * u * u;
    let mut r = 0;
    while r < NX {
        c += Q[r] * e[r] * e[r];
        r += 1;
    }
    c
}

fn terminal_cost(e: &[f64; NX]) -> f64 {
    let mut c = 0.0;
    let mut r = 0;
    while r < NX {
        c += P[r] * e[r] * e[r];
        r += 1;
    }
    c
}

/// Nonlinear cost of `plan` from `e0` over K samples (no Jacobians).
pub fn rollout_cost(e0: &[f64; NX], plan: &[f64; K], schedule: &Schedule) -> f64 {
    rollout_cost_below(e0, plan, schedule, f64::INFINITY)
}

/// Like [`rollout_cost`], but gives up with infinity as soon as the partial
/// cost reaches `bound`: every term is non-negative, so the total could no
/// longer come out below it. Rejected candidates then cost a fraction of a
/// rollout, and the accept decision `cost < bound` is unchanged.
pub fn rollout_cost_below(e0: &[f64; NX], plan: &[f64; K], schedule: &Schedule, bound: f64) -> f64 {
    let mut e = *e0;
    let mut unused = ZERO_JACOBIAN;
    let mut cost = 0.0;
    let mut k = 0;
    while k < K {
        cost += stage_cost(&e, plan[k]);
        if cost >= bound {
            return f64::INFINITY;
        }
        sample_all::<false>(&mut e, plan[k], k, schedule, &mut unused);
        k += 1;
    }
    let total = cost + terminal_cost(&e);
    if total.is_nan() {
        f64::INFINITY
    } else {
        total
    }
}

/// Rolls `plan` out with per-sample Jacobians; returns its nonlinear cost
/// (the same sum, in the same order, as [`rollout_cost`]).
fn rollout_with_jacobians(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
    states: &mut [[f64; NX]; K + 1],
    jac: &mut [StepJacobian; K],
) -> f64 {
    states[0] = *e0;
    let mut cost = 0.0;
    let mut k = 0;
    while k < K {
        cost += stage_cost(&states[k], plan[k]);
        let mut e = states[k];
        sample_all::<true>(&mut e, plan[k], k, schedule, &mut jac[k]);
        states[k + 1] = e;
        k += 1;
    }
    let total = cost + terminal_cost(&states[K]);
    if total.is_nan() {
        f64::INFINITY
    } else {
        total
    }
}

/// Predicted relative state after applying `plan[..samples]` from `e0`.
pub fn predict(e0: &[f64; NX], plan: &[f64; K], samples: usize) -> [f64; NX] {
    let mut e = *e0;
    let mut unused = ZERO_JACOBIAN;
    let mut k = 0;
    while k < samples && k < K {
        sample_all::<false>(&mut e, plan[k], k, &Schedule::BACK_TO_BACK, &mut unused);
        k += 1;
    }
    e
}

/// One capsule over `duration_s` at constant `u` with its 2x2 Jacobian.
pub fn capsule_transition(i: usize, xv: [f64; 2], u: f64, duration_s: f64) -> ([f64; 2], [f64; 4]) {
    let mut s = xv;
    let mut a = [1.0, 0.0, 0.0, 1.0];
    if !(duration_s > 0.0) || i >= M {
        return (s, a);
    }
    let max_h = DT_S / RK4_SUBSTEPS as f64;
    let mut steps = libm::ceil(duration_s / max_h) as usize;
    if steps > MAX_PREDICTION_STEPS {
        steps = MAX_PREDICTION_STEPS;
    }
    let h = duration_s / steps as f64;
    let mut n = 0;
    while n < steps {
        let (next, sa, _) = rk4_capsule(i, s[0], s[1], u, h);
        a = mat2_mul(&sa, &a);
        s = next;
        n += 1;
    }
    (s, a)
}

/// Upper bound on RK4 sub-steps of one prediction (bounds the compute time
/// whatever duration a caller passes).
pub const MAX_PREDICTION_STEPS: usize = 4096;

impl PlanSolver<NX, K> for Solver {
    const M: usize = M;
    const N: usize = N;
    const DT_S: f64 = DT_S;
    const U_MAX_T_PER_M: f64 = U_MAX_T_PER_M;
    const POSITION_BOUND_M: f64 = POSITION_BOUND_M;
    const SPEED_BOUND_M_PER_S: f64 = SPEED_BOUND_M_PER_S;
    const TRACKING_TIME_S: f64 = TRACKING_TIME_S;
    const EXTRA_DELAY_S: f64 = EXTRA_DELAY_S;
    const POSITION_NOISE_M: f64 = POSITION_NOISE_M;
    const L_F: f64 = L_F;
    const L_L: f64 = L_L;
    const L_V: f64 = L_V;
    const X_DIAMETER: f64 = X_DIAMETER;
    const SWITCHING_SIGMA: f64 = SWITCHING_SIGMA;
    const QP_MAX_ITERATIONS: usize = QP_MAX_ITERATIONS;
    const TABLE_BYTES: usize = TABLE_BYTES;
    const WORKSPACE_MIN_M: f64 = WORKSPACE_MIN_M;
    const WORKSPACE_MAX_M: f64 = WORKSPACE_MAX_M;
    const HAS_EXPLICIT_TIER: bool = super::explicit_tables::EXPLICIT_COUNT > 0;
    const EXPLICIT_CERTIFIED_OPS: u64 = super::explicit_tables::EXPLICIT_CERTIFIED_OPS;

    fn new() -> Self {
        Solver::new()
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
    fn solve(&mut self, e: &[f64; NX]) -> SolveReport {
        Solver::solve(self, e)
    }
    fn solve_explicit(&mut self, e: &[f64; NX]) -> SolveReport {
        Solver::solve_explicit(self, e)
    }
    fn adopt_explicit(&mut self) {
        Solver::adopt_explicit(self)
    }
    fn plan(&self) -> &[f64; K] {
        Solver::plan(self)
    }
    fn qp_iterations_measured(e: &[f64; NX]) -> u32 {
        qp_iterations_measured(e)
    }
    fn covers_from_rest(e: &[f64; NX]) -> bool {
        Solver::covers_from_rest(e)
    }
    fn first_leg(d: &[f64; NX]) -> Option<Leg<NX>> {
        first_leg(d)
    }
    fn chain_time_s(d: &[f64; NX]) -> f64 {
        chain_time_s(d)
    }
    fn stage_cost(e: &[f64; NX], u: f64) -> f64 {
        stage_cost(e, u)
    }
    fn predict_plan(e: &[f64; NX], plan: &[f64; K], samples: usize) -> [f64; NX] {
        predict(e, plan, samples)
    }
    fn predict_constant(e: &[f64; NX], u: f64, duration_s: f64) -> [f64; NX] {
        let mut out = *e;
        let mut i = 0;
        while i < M {
            let (next, _) = capsule_transition(i, [e[2 * i], e[2 * i + 1]], u, duration_s);
            out[2 * i] = next[0];
            out[2 * i + 1] = next[1];
            i += 1;
        }
        out
    }
    fn capsule_transition(i: usize, xv: [f64; 2], u: f64, duration_s: f64) -> ([f64; 2], [f64; 4]) {
        capsule_transition(i, xv, u, duration_s)
    }
}
