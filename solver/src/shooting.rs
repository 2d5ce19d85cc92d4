//! Minimum-time shooting from any state: the shortest plan whose rollout
//! ends at the target at rest.
//!
//! The stored plans start at rest; the refinement minimizes a quadratic
//! cost, which is not the time to settle. From a moving or off-model state
//! this module searches the plan length `n` directly: for a given `n` it
//! solves `e_n(u) = 0` (every capsule at its target, at rest) over
//! `|u_k| <= u_max` by Gauss-Newton with the minimum-norm step on the
//! `NX` terminal equations (an `NX x NX` solve per pass, the inputs that
//! reach the bound fixed there), and the search keeps the shortest `n` that
//! converges. Re-solved every control step from the estimate with the
//! shifted plan as its start, it is a shrinking-horizon feedback law whose
//! objective is the time of arrival.

use crate::qp::clamp_u;
use crate::rollout::{sample_all, ModelScales, Schedule, StepJacobian};
use crate::spec::Spec;

/// Terminal tolerances of a converged shot: every capsule within this of
/// its target (m) and below this speed (m/s). A tenth of the settle band's
/// 1 mm / 5 mm/s, so that noise and the model's error leave room.
pub const SHOT_POSITION_TOLERANCE_M: f64 = 1e-4;
pub const SHOT_SPEED_TOLERANCE_M_PER_S: f64 = 5e-4;
/// The speed tolerance from an exact state (ideal sampling), m/s: the
/// relative speed a shot leaves is what the hold must stop with the
/// capsules' differential drag alone, which is small near rest (a 20 %
/// lower drag on the small capsule left 0.85 mm/s that the hold could not
/// stop: docs/decisions.md).
pub const SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S: f64 = 2e-4;
/// The speed tolerance from tracked estimates (constant and variable
/// sampling), m/s: tighter still, since there the hold's differential
/// authority is smaller (tracking gaps between its samples) and the
/// estimate's own error (a few tenths of a mm/s) adds to the shot's. On
/// the 1 cm grid, variable sampling, seeds 1-8, 5e-4 -> 1e-4 took the runs
/// above 2x the minimum time from 49 to 38 of 640 (docs/decisions.md).
pub const SHOT_SPEED_TOLERANCE_TRACKED_M_PER_S: f64 = 1e-4;
/// The same for three capsules and more, m/s, where the tighter aim
/// measured slower (`tests/three_capsules.rs`' scanner runs, seeds 1-8,
/// 1e-4 -> 2e-4: medians 1.80 -> 1.56 s constant, 1.74 -> 1.60 s
/// variable, unsettled runs over the 1 cm and 1.5 cm grids 19 -> 14;
/// docs/decisions.md).
pub const SHOT_SPEED_TOLERANCE_TRACKED_MANY_M_PER_S: f64 = 2e-4;

/// The position tolerance a shot in flight falls back to when it no
/// longer converges to `SHOT_POSITION_TOLERANCE_M`, m: inside the hold's
/// entry (0.7 mm), so that the hold takes over at its end.
pub const SHOT_HOLD_POSITION_TOLERANCE_M: f64 = 5e-4;

/// The settle band: within this of the target (m) and below this speed
/// (m/s); the simulator's settle metrics read the same constants.
pub const BAND_POSITION_M: f64 = 1e-3;
pub const BAND_SPEED_M_PER_S: f64 = 5e-3;

/// Plan lengths tried when a shot is first looked for.
pub const SHOT_MAX_LENGTHS: usize = 8;

/// Capsule-samples the shooting may roll out per control cycle (every
/// Gauss-Newton iteration and line-search trial rolls `n` samples of `M`
/// capsules), shared by every solve of the cycle: the bound on its compute
/// time. For two capsules 2 400 samples, 30 rollouts of the whole plan;
/// for three 1 600. Per solve instead, variable sampling's up to N solves
/// a cycle took three capsules to 1.26 ms.
pub const SHOT_CAPSULE_SAMPLE_BUDGET: usize = 4800;

/// What one refinement (the SQP over the whole plan and its window QP)
/// takes from the same budget, in plan lengths: its worst case measured
/// about as long as four rolled-out plans with Jacobians. Variable
/// sampling refines up to N times a cycle; charging the refinements after
/// the first keeps the whole cycle (not only its shots) inside the budget.
pub const REFINE_BUDGET_PLANS: usize = 4;

/// Shorter lengths a shot in flight tries (bisecting down to half its
/// length) once it converged one sample shorter.
pub const SHOT_RESHOOT_SHORTER_LENGTHS: usize = 3;

/// Length of the shot looked for when the refined plan does not settle
/// within its horizon (0.6 s of 20 ms samples).
pub const SHOT_UNSETTLED_SAMPLES: usize = 30;

/// Gauss-Newton iterations per plan length tried.
pub const SHOT_ITERATIONS: usize = 6;

/// Passes of the bound-fixing loop inside one Gauss-Newton step.
const BOUND_PASSES: usize = 4;

/// Halvings of the step tried when the residual does not decrease.
const SHOT_LINE_SEARCH_TRIES: usize = 4;

/// Relative Levenberg term on the normal matrix (keeps it invertible when
/// the free inputs cannot move every terminal coordinate).
const LEVENBERG: f64 = 1e-9;

/// Scratch of the shooting method: created once, reused.
#[derive(Debug, Clone)]
pub struct Shooter<const M: usize, const NX: usize, const K: usize> {
    jac: [StepJacobian<M>; K],
    /// cols[k] = W d e_n / d u_k (weighted terminal sensitivity).
    cols: [[f64; NX]; K],
    trial: [f64; K],
    step: [f64; K],
    fixed: [bool; K],
    /// Plan samples left of this cycle's budget (`BUDGET_SAMPLES`).
    budget_samples: usize,
    /// Refinements this cycle (`charge_refinement`).
    refinements: usize,
    /// Terminal speed tolerance, m/s (`set_speed_tolerance`).
    speed_tolerance_m_per_s: f64,
    /// Terminal position tolerance, m (`set_position_tolerance`).
    position_tolerance_m: f64,
}

impl<const M: usize, const NX: usize, const K: usize> Default for Shooter<M, NX, K> {
    fn default() -> Self {
        Self::new()
    }
}

/// Weight of terminal coordinate `r`: 1 at the tolerance (`tol`: position
/// m, speed m/s).
#[inline(always)]
fn weight(r: usize, tol: [f64; 2]) -> f64 {
    if r.is_multiple_of(2) {
        1.0 / tol[0]
    } else {
        1.0 / tol[1]
    }
}

/// Weighted terminal residual and its squared norm.
fn residual<const NX: usize>(end: &[f64; NX], tol: [f64; 2]) -> ([f64; NX], f64) {
    let mut r = [0.0; NX];
    let mut s = 0.0;
    let mut i = 0;
    while i < NX {
        r[i] = weight(i, tol) * end[i];
        s += r[i] * r[i];
        i += 1;
    }
    if s.is_nan() {
        s = f64::INFINITY;
    }
    (r, s)
}

/// Whether a weighted residual is within the tolerances.
fn converged<const NX: usize>(r: &[f64; NX]) -> bool {
    let mut i = 0;
    while i < NX {
        if !(libm::fabs(r[i]) <= 1.0) {
            return false;
        }
        i += 1;
    }
    true
}

/// Solves `g y = b` for symmetric positive definite `g` (Cholesky, in
/// place); false when `g` is not positive definite.
fn cholesky_solve<const NX: usize>(g: &mut [[f64; NX]; NX], b: &mut [f64; NX]) -> bool {
    let mut j = 0;
    while j < NX {
        let mut d = g[j][j];
        let mut k = 0;
        while k < j {
            d -= g[j][k] * g[j][k];
            k += 1;
        }
        if !(d > 0.0) {
            return false;
        }
        let d = libm::sqrt(d);
        g[j][j] = d;
        let mut i = j + 1;
        while i < NX {
            let mut s = g[i][j];
            let mut k = 0;
            while k < j {
                s -= g[i][k] * g[j][k];
                k += 1;
            }
            g[i][j] = s / d;
            i += 1;
        }
        j += 1;
    }
    // L z = b, then L' y = z.
    let mut i = 0;
    while i < NX {
        let mut s = b[i];
        let mut k = 0;
        while k < i {
            s -= g[i][k] * b[k];
            k += 1;
        }
        b[i] = s / g[i][i];
        i += 1;
    }
    let mut i = NX;
    while i > 0 {
        i -= 1;
        let mut s = b[i];
        let mut k = i + 1;
        while k < NX {
            s -= g[k][i] * b[k];
            k += 1;
        }
        b[i] = s / g[i][i];
    }
    true
}

impl<const M: usize, const NX: usize, const K: usize> Shooter<M, NX, K> {
    pub const fn new() -> Self {
        Shooter {
            jac: [StepJacobian::ZERO; K],
            cols: [[0.0; NX]; K],
            trial: [0.0; K],
            step: [0.0; K],
            fixed: [false; K],
            budget_samples: Self::BUDGET_SAMPLES,
            refinements: 0,
            speed_tolerance_m_per_s: SHOT_SPEED_TOLERANCE_M_PER_S,
            position_tolerance_m: SHOT_POSITION_TOLERANCE_M,
        }
    }

    /// The terminal speed tolerance, m/s (default
    /// [`SHOT_SPEED_TOLERANCE_M_PER_S`]; from exact states
    /// [`SHOT_SPEED_TOLERANCE_FULL_STATE_M_PER_S`]).
    pub fn set_speed_tolerance(&mut self, tolerance_m_per_s: f64) {
        self.speed_tolerance_m_per_s = tolerance_m_per_s;
    }

    /// The terminal position tolerance, m (default
    /// [`SHOT_POSITION_TOLERANCE_M`]).
    pub fn set_position_tolerance(&mut self, tolerance_m: f64) {
        self.position_tolerance_m = tolerance_m;
    }

    /// The terminal position tolerance, m.
    pub fn position_tolerance_m(&self) -> f64 {
        self.position_tolerance_m
    }

    fn tolerances(&self) -> [f64; 2] {
        [self.position_tolerance_m, self.speed_tolerance_m_per_s]
    }

    /// Plan samples per cycle ([`SHOT_CAPSULE_SAMPLE_BUDGET`] over `M`).
    pub const BUDGET_SAMPLES: usize = SHOT_CAPSULE_SAMPLE_BUDGET / M;

    /// Restores the sample budget (once per control cycle).
    pub fn start_budget(&mut self) {
        self.budget_samples = Self::BUDGET_SAMPLES;
        self.refinements = 0;
    }

    /// Samples of this cycle's budget not yet spent.
    pub fn budget_left(&self) -> usize {
        self.budget_samples
    }

    /// Counts a refinement: the cycle's first is outside the budget (one
    /// solve a cycle, as under ideal and constant sampling, keeps the whole
    /// budget for its shots); each further one takes its share
    /// (`REFINE_BUDGET_PLANS` plan lengths, or what is left).
    pub fn charge_refinement(&mut self) {
        if self.refinements > 0 {
            self.budget_samples = self.budget_samples.saturating_sub(REFINE_BUDGET_PLANS * K);
        }
        self.refinements += 1;
    }

    /// Whether another refinement fits this cycle's budget.
    pub fn refinement_fits(&self) -> bool {
        self.budget_samples >= REFINE_BUDGET_PLANS * K
    }

    /// Whether `n` more samples fit the budget; takes them if so.
    fn spend(&mut self, n: usize) -> bool {
        if n > self.budget_samples {
            self.budget_samples = 0;
            return false;
        }
        self.budget_samples -= n;
        true
    }

    /// End state of `plan[..n]` from `e0` (samples from `n` on are zero and
    /// not rolled out); with `JAC`, the per-sample Jacobians too.
    fn roll<S: Spec<M, NX>, const JAC: bool>(
        &mut self,
        e0: &[f64; NX],
        plan: &[f64; K],
        n: usize,
        schedule: &Schedule,
        scales: &ModelScales<M>,
    ) -> [f64; NX] {
        let mut e = *e0;
        let mut scratch = StepJacobian::ZERO;
        let mut k = 0;
        while k < n {
            if JAC {
                sample_all::<S, M, NX, true>(
                    &mut e,
                    plan[k],
                    k,
                    schedule,
                    scales,
                    &mut self.jac[k],
                );
            } else {
                sample_all::<S, M, NX, false>(&mut e, plan[k], k, schedule, scales, &mut scratch);
            }
            k += 1;
        }
        e
    }

    /// cols[k] = W d e_n / d u_k from the Jacobians of the last `roll`.
    fn terminal_sensitivities(&mut self, n: usize) {
        let tol = self.tolerances();
        let mut i = 0;
        while i < M {
            // p = d e_n / d e_{k+1} for capsule i, running backwards.
            let mut p = [1.0, 0.0, 0.0, 1.0];
            let mut k = n;
            while k > 0 {
                k -= 1;
                let a = &self.jac[k].a[i];
                let b = &self.jac[k].b[i];
                self.cols[k][2 * i] = weight(2 * i, tol) * (p[0] * b[0] + p[1] * b[1]);
                self.cols[k][2 * i + 1] = weight(2 * i + 1, tol) * (p[2] * b[0] + p[3] * b[1]);
                p = [
                    p[0] * a[0] + p[1] * a[2],
                    p[0] * a[1] + p[1] * a[3],
                    p[2] * a[0] + p[3] * a[2],
                    p[2] * a[1] + p[3] * a[3],
                ];
            }
            i += 1;
        }
    }

    /// The minimum-norm Gauss-Newton step for `r + C du = 0` within the
    /// input bounds, into `self.step[..n]`.
    fn gauss_newton_step(&mut self, plan: &[f64; K], n: usize, r: &[f64; NX], u_max: f64) {
        let mut k = 0;
        while k < n {
            self.fixed[k] = false;
            self.step[k] = 0.0;
            k += 1;
        }
        let mut pass = 0;
        while pass < BOUND_PASSES {
            // Residual left for the free inputs once the fixed ones moved.
            let mut rf = *r;
            let mut g = [[0.0; NX]; NX];
            let mut k = 0;
            while k < n {
                let c = &self.cols[k];
                if self.fixed[k] {
                    let mut a = 0;
                    while a < NX {
                        rf[a] += c[a] * self.step[k];
                        a += 1;
                    }
                } else {
                    let mut a = 0;
                    while a < NX {
                        let mut b = 0;
                        while b <= a {
                            g[a][b] += c[a] * c[b];
                            b += 1;
                        }
                        a += 1;
                    }
                }
                k += 1;
            }
            let mut trace = 0.0;
            let mut a = 0;
            while a < NX {
                trace += g[a][a];
                a += 1;
            }
            let mu = LEVENBERG * trace / NX as f64 + 1e-300;
            let mut a = 0;
            while a < NX {
                g[a][a] += mu;
                let mut b = 0;
                while b < a {
                    g[b][a] = g[a][b];
                    b += 1;
                }
                a += 1;
            }
            let mut y = [0.0; NX];
            let mut a = 0;
            while a < NX {
                y[a] = -rf[a];
                a += 1;
            }
            if !cholesky_solve(&mut g, &mut y) {
                return;
            }
            let mut newly_fixed = false;
            let mut k = 0;
            while k < n {
                if !self.fixed[k] {
                    let c = &self.cols[k];
                    let mut d = 0.0;
                    let mut a = 0;
                    while a < NX {
                        d += c[a] * y[a];
                        a += 1;
                    }
                    let lo = -u_max - plan[k];
                    let hi = u_max - plan[k];
                    if d > hi {
                        d = hi;
                        self.fixed[k] = true;
                        newly_fixed = true;
                    } else if d < lo {
                        d = lo;
                        self.fixed[k] = true;
                        newly_fixed = true;
                    }
                    self.step[k] = d;
                }
                k += 1;
            }
            if !newly_fixed {
                return;
            }
            pass += 1;
        }
    }

    /// Solves for a plan of `n` samples from `e0` that ends at the target
    /// at rest, starting from `plan` (its samples from `n` on are set to
    /// zero). On success `plan` holds the shot and the call returns true;
    /// on failure `plan` holds the best iterate.
    #[allow(clippy::too_many_arguments)]
    pub fn shoot<S: Spec<M, NX>>(
        &mut self,
        e0: &[f64; NX],
        plan: &mut [f64; K],
        n: usize,
        iterations: usize,
        schedule: &Schedule,
        scales: &ModelScales<M>,
    ) -> bool {
        if n == 0 || n > K {
            return false;
        }
        let mut k = n;
        while k < K {
            plan[k] = 0.0;
            k += 1;
        }
        if !self.spend(n) {
            return false;
        }
        let end = self.roll::<S, true>(e0, plan, n, schedule, scales);
        let (mut r, mut norm) = residual(&end, self.tolerances());
        let mut it = 0;
        while it < iterations {
            if converged(&r) {
                return true;
            }
            self.terminal_sensitivities(n);
            self.gauss_newton_step(plan, n, &r, S::U_MAX_T_PER_M);
            let mut alpha = 1.0;
            let mut tries = 0;
            let mut accepted = false;
            while tries < SHOT_LINE_SEARCH_TRIES {
                if !self.spend(n) {
                    return false;
                }
                self.trial = *plan;
                let mut k = 0;
                while k < n {
                    self.trial[k] = clamp_u(plan[k] + alpha * self.step[k], S::U_MAX_T_PER_M);
                    k += 1;
                }
                let trial = self.trial;
                let end = self.roll::<S, true>(e0, &trial, n, schedule, scales);
                let (rt, nt) = residual(&end, self.tolerances());
                if nt < norm {
                    *plan = trial;
                    r = rt;
                    norm = nt;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
                tries += 1;
            }
            if !accepted {
                // The Jacobians of `self.jac` belong to the last trial;
                // nothing better in this direction.
                return converged(&r);
            }
            it += 1;
        }
        converged(&r)
    }

    /// The sample from which `plan`'s rollout from `e0` stays in the settle
    /// band to the plan's end (0: from the start; K + 1: not at the end).
    pub fn settle_sample<S: Spec<M, NX>>(
        &mut self,
        e0: &[f64; NX],
        plan: &[f64; K],
        schedule: &Schedule,
        scales: &ModelScales<M>,
    ) -> usize {
        let mut e = *e0;
        let mut scratch = StepJacobian::ZERO;
        let mut last_out = None;
        let mut k = 0;
        while k <= K {
            if !in_band(&e) {
                last_out = Some(k);
            }
            if k < K {
                sample_all::<S, M, NX, false>(&mut e, plan[k], k, schedule, scales, &mut scratch);
            }
            k += 1;
        }
        match last_out {
            None => 0,
            Some(k) => k + 1,
        }
    }
}

/// Whether every capsule is inside the settle band.
fn in_band<const NX: usize>(e: &[f64; NX]) -> bool {
    let mut i = 0;
    while i < NX {
        let bound = if i.is_multiple_of(2) {
            BAND_POSITION_M
        } else {
            BAND_SPEED_M_PER_S
        };
        if !(libm::fabs(e[i]) <= bound) {
            return false;
        }
        i += 1;
    }
    true
}

/// `to[..n]` = `from[..m]` stretched or compressed in time (nearest
/// sample), zero after: a start for a shot of another length.
pub fn resample<const K: usize>(from: &[f64; K], m: usize, to: &mut [f64; K], n: usize) {
    let mut k = 0;
    while k < K {
        to[k] = if k < n && m > 0 {
            let j = (k * m + m / 2) / n;
            from[if j < m { j } else { m - 1 }]
        } else {
            0.0
        };
        k += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One cycle's budget covers its shots and every refinement after the
    /// first: the first is free (one solve a cycle keeps the whole budget
    /// for its shots), the next ones take their share until none fits.
    #[test]
    fn refinements_after_the_first_spend_the_cycle_budget() {
        const K: usize = 80;
        let mut s = Shooter::<2, 4, K>::new();
        s.start_budget();
        let full = Shooter::<2, 4, K>::BUDGET_SAMPLES;
        s.charge_refinement();
        assert_eq!(s.budget_left(), full);
        let mut refinements = 1;
        while s.refinement_fits() {
            s.charge_refinement();
            refinements += 1;
        }
        assert_eq!(refinements, 1 + full / (REFINE_BUDGET_PLANS * K));
        assert!(s.budget_left() < REFINE_BUDGET_PLANS * K);
        // Shots spend the same budget.
        s.start_budget();
        assert!(s.spend(full - REFINE_BUDGET_PLANS * K + 1));
        s.charge_refinement();
        assert!(!s.refinement_fits());
        s.charge_refinement();
        assert_eq!(s.budget_left(), 0);
    }
}
