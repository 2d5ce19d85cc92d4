//! The model online: RK4 with exact forward sensitivities, rollouts of a
//! plan under an actuation schedule, their nonlinear cost, and predictions
//! for the estimator. Every function is generic over the module's [`Spec`];
//! the arithmetic is the generator's, in the same order, so the online and
//! offline rollouts agree bit for bit.

use crate::spec::Spec;

/// Per-capsule 2x2 Jacobian (row major) and input column of one sample.
#[derive(Debug, Clone, Copy)]
pub struct StepJacobian<const M: usize> {
    pub a: [[f64; 4]; M],
    pub b: [[f64; 2]; M],
}

impl<const M: usize> StepJacobian<M> {
    pub const ZERO: StepJacobian<M> = StepJacobian {
        a: [[0.0; 4]; M],
        b: [[0.0; 2]; M],
    };
}

/// How the scanner plays the plan: actuation phases of `samples_per_phase`
/// samples back to back, each followed by a zero-gradient coast (tracking
/// and delay). Ideal sampling has no coast. Modelling the gaps makes the
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

/// Upper bound on RK4 sub-steps of one prediction (bounds the compute time
/// whatever duration a caller passes).
pub const MAX_PREDICTION_STEPS: usize = 4096;

impl Schedule {
    /// Every sample back to back, no coast.
    pub const BACK_TO_BACK: Schedule = Schedule {
        samples_per_phase: usize::MAX,
        coast_steps: 0,
        coast_h_s: 0.0,
    };

    /// Phases of `samples_per_phase` samples (clamped to 1..=plan_steps),
    /// each followed by `coast_s` (clamped to 0..=MAX_COAST_S; NaN reads
    /// as 0), integrated in RK4 sub-steps of at most `substep_s`.
    pub fn new(
        samples_per_phase: usize,
        coast_s: f64,
        plan_steps: usize,
        substep_s: f64,
    ) -> Schedule {
        let c = if coast_s > MAX_COAST_S {
            MAX_COAST_S
        } else if coast_s > 0.0 {
            coast_s
        } else {
            return Schedule::BACK_TO_BACK;
        };
        let steps = libm::ceil(c / substep_s) as usize;
        Schedule {
            samples_per_phase: if samples_per_phase == 0 {
                1
            } else if samples_per_phase > plan_steps {
                plan_steps
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
    pub fn coasted(&self) -> bool {
        self.coast_steps > 0 && self.samples_per_phase == 1
    }

    /// Time from the start of sample 0 to the end of sample `n - 1`, s:
    /// `n` samples of `dt_s` and the coasts between them.
    pub fn duration_s(&self, n: usize, dt_s: f64) -> f64 {
        let coasts = if self.coast_steps > 0 && n > 0 {
            (n - 1) / self.samples_per_phase
        } else {
            0
        };
        n as f64 * dt_s + coasts as f64 * self.coast_steps as f64 * self.coast_h_s
    }

    /// Whether a coast follows plan sample `k`.
    #[inline]
    fn coasts_after(&self, k: usize) -> bool {
        self.coast_steps > 0 && (k + 1).is_multiple_of(self.samples_per_phase)
    }
}

/// Per capsule: factors on the model's magnetic gain and drag (the
/// runtime's estimate of how the capsules differ from the model; 1 is the
/// model itself, and then every result is bit for bit the model's).
pub type ModelScales<const M: usize> = [[f64; 2]; M];

/// The model itself.
pub const fn nominal_scales<const M: usize>() -> ModelScales<M> {
    [[1.0, 1.0]; M]
}

/// The RK4 sub-step of a plan sample, s.
#[inline(always)]
pub fn substep_s<S: Spec<M, NX>, const M: usize, const NX: usize>() -> f64 {
    S::DT_S / S::RK4_SUBSTEPS as f64
}

/// One RK4 step of capsule `i` with forward sensitivities over `h` seconds:
/// the new (x, v), d(x, v)/d(x0, v0) and d(x, v)/du.
#[inline(always)]
pub fn rk4_capsule<S: Spec<M, NX>, const M: usize, const NX: usize>(
    i: usize,
    x: f64,
    v: f64,
    u: f64,
    h: f64,
    scale: [f64; 2],
) -> ([f64; 2], [f64; 4], [f64; 2]) {
    const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
    const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];
    // The factors fold into the coefficients once per step, off the
    // latency-bound stage chain.
    let g = S::G[i] * scale[0];
    let drag = S::DRAG[i].scaled(scale[1]);
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
        let (acc, slope) = drag.accel_and_slope(vs);
        let kv = acc + g * u;
        let wh = W[stage] * h / 6.0;
        next[0] += wh * vs;
        next[1] += wh * kv;
        a[0] += wh * dv[0];
        a[1] += wh * dv[1];
        a[2] += wh * slope * dv[0];
        a[3] += wh * slope * dv[1];
        b[0] += wh * dvu;
        b[1] += wh * (slope * dvu + g);
        k_prev_v = kv;
        dk_prev = [slope * dv[0], slope * dv[1]];
        dku_prev = slope * dvu + g;
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
pub(crate) fn sample_all<S: Spec<M, NX>, const M: usize, const NX: usize, const JAC: bool>(
    e: &mut [f64; NX],
    u: f64,
    k: usize,
    schedule: &Schedule,
    scales: &ModelScales<M>,
    jac: &mut StepJacobian<M>,
) {
    let h = substep_s::<S, M, NX>();
    if JAC {
        *jac = StepJacobian {
            a: [[1.0, 0.0, 0.0, 1.0]; M],
            b: [[0.0, 0.0]; M],
        };
    }
    let mut n = 0;
    while n < S::RK4_SUBSTEPS {
        let mut i = 0;
        while i < M {
            let (next, sa, sb) =
                rk4_capsule::<S, M, NX>(i, e[2 * i], e[2 * i + 1], u, h, scales[i]);
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
            let (next, sa, _) = rk4_capsule::<S, M, NX>(
                i,
                e[2 * i],
                e[2 * i + 1],
                0.0,
                schedule.coast_h_s,
                scales[i],
            );
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

/// Stage cost L(e, u) (per sample).
pub fn stage_cost<S: Spec<M, NX>, const M: usize, const NX: usize>(e: &[f64; NX], u: f64) -> f64 {
    let mut c = S::R * u * u;
    let mut r = 0;
    while r < NX {
        c += S::Q[r] * e[r] * e[r];
        r += 1;
    }
    c
}

/// Terminal cost e'Pe.
pub fn terminal_cost<S: Spec<M, NX>, const M: usize, const NX: usize>(e: &[f64; NX]) -> f64 {
    let mut c = 0.0;
    let mut r = 0;
    while r < NX {
        c += S::P[r] * e[r] * e[r];
        r += 1;
    }
    c
}

/// Nonlinear cost of `plan` from `e0` over K samples (no Jacobians).
pub fn rollout_cost<S: Spec<M, NX>, const M: usize, const NX: usize, const K: usize>(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
) -> f64 {
    rollout_cost_below::<S, M, NX, K>(e0, plan, schedule, f64::INFINITY)
}

/// Like [`rollout_cost`], but gives up with infinity as soon as the partial
/// cost reaches `bound`: every term is non-negative, so the total could no
/// longer come out below it. Rejected candidates then cost a fraction of a
/// rollout, and the accept decision `cost < bound` is unchanged.
pub fn rollout_cost_below<S: Spec<M, NX>, const M: usize, const NX: usize, const K: usize>(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
    bound: f64,
) -> f64 {
    rollout_cost_below_scaled::<S, M, NX, K>(e0, plan, schedule, &nominal_scales(), bound)
}

/// [`rollout_cost_below`] on the model with `scales` applied.
pub fn rollout_cost_below_scaled<
    S: Spec<M, NX>,
    const M: usize,
    const NX: usize,
    const K: usize,
>(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
    scales: &ModelScales<M>,
    bound: f64,
) -> f64 {
    let mut e = *e0;
    let mut unused = StepJacobian::ZERO;
    let mut cost = 0.0;
    let mut k = 0;
    while k < K {
        cost += stage_cost::<S, M, NX>(&e, plan[k]);
        if cost >= bound {
            return f64::INFINITY;
        }
        sample_all::<S, M, NX, false>(&mut e, plan[k], k, schedule, scales, &mut unused);
        k += 1;
    }
    let total = cost + terminal_cost::<S, M, NX>(&e);
    if total.is_nan() {
        f64::INFINITY
    } else {
        total
    }
}

/// Rolls `plan` out with per-sample Jacobians into `states` (e_0..e_{K-1}),
/// `end` (e_K) and `jac`; returns its nonlinear cost (the same sum, in the
/// same order, as [`rollout_cost`]).
pub fn rollout_with_jacobians<S: Spec<M, NX>, const M: usize, const NX: usize, const K: usize>(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
    states: &mut [[f64; NX]; K],
    end: &mut [f64; NX],
    jac: &mut [StepJacobian<M>; K],
) -> f64 {
    rollout_with_jacobians_scaled::<S, M, NX, K>(
        e0,
        plan,
        schedule,
        &nominal_scales(),
        states,
        end,
        jac,
    )
}

/// [`rollout_with_jacobians`] on the model with `scales` applied.
pub fn rollout_with_jacobians_scaled<
    S: Spec<M, NX>,
    const M: usize,
    const NX: usize,
    const K: usize,
>(
    e0: &[f64; NX],
    plan: &[f64; K],
    schedule: &Schedule,
    scales: &ModelScales<M>,
    states: &mut [[f64; NX]; K],
    end: &mut [f64; NX],
    jac: &mut [StepJacobian<M>; K],
) -> f64 {
    let mut e = *e0;
    let mut cost = 0.0;
    let mut k = 0;
    while k < K {
        states[k] = e;
        cost += stage_cost::<S, M, NX>(&e, plan[k]);
        sample_all::<S, M, NX, true>(&mut e, plan[k], k, schedule, scales, &mut jac[k]);
        k += 1;
    }
    *end = e;
    let total = cost + terminal_cost::<S, M, NX>(end);
    if total.is_nan() {
        f64::INFINITY
    } else {
        total
    }
}

/// Predicted relative state after applying `plan[..samples]` from `e0`
/// back to back.
pub fn predict<S: Spec<M, NX>, const M: usize, const NX: usize, const K: usize>(
    e0: &[f64; NX],
    plan: &[f64; K],
    samples: usize,
) -> [f64; NX] {
    let mut e = *e0;
    let mut unused = StepJacobian::ZERO;
    let mut k = 0;
    while k < samples && k < K {
        sample_all::<S, M, NX, false>(
            &mut e,
            plan[k],
            k,
            &Schedule::BACK_TO_BACK,
            &nominal_scales(),
            &mut unused,
        );
        k += 1;
    }
    e
}

/// One capsule over `duration_s` at constant `u` with its 2x2 Jacobian.
pub fn capsule_transition<S: Spec<M, NX>, const M: usize, const NX: usize>(
    i: usize,
    xv: [f64; 2],
    u: f64,
    duration_s: f64,
) -> ([f64; 2], [f64; 4]) {
    capsule_transition_scaled::<S, M, NX>(i, xv, u, duration_s, [1.0, 1.0])
}

/// [`capsule_transition`] with the capsule's gain and drag scaled by `scale`.
pub fn capsule_transition_scaled<S: Spec<M, NX>, const M: usize, const NX: usize>(
    i: usize,
    xv: [f64; 2],
    u: f64,
    duration_s: f64,
    scale: [f64; 2],
) -> ([f64; 2], [f64; 4]) {
    let mut s = xv;
    let mut a = [1.0, 0.0, 0.0, 1.0];
    if !(duration_s > 0.0) || i >= M {
        return (s, a);
    }
    let max_h = substep_s::<S, M, NX>();
    let mut steps = libm::ceil(duration_s / max_h) as usize;
    if steps > MAX_PREDICTION_STEPS {
        steps = MAX_PREDICTION_STEPS;
    }
    let h = duration_s / steps as f64;
    let mut n = 0;
    while n < steps {
        let (next, sa, _) = rk4_capsule::<S, M, NX>(i, s[0], s[1], u, h, scale);
        a = mat2_mul(&sa, &a);
        s = next;
        n += 1;
    }
    (s, a)
}

/// Every capsule over `duration_s` at constant `u`.
pub fn predict_constant<S: Spec<M, NX>, const M: usize, const NX: usize>(
    e: &[f64; NX],
    u: f64,
    duration_s: f64,
) -> [f64; NX] {
    let mut out = *e;
    let mut i = 0;
    while i < M {
        let (next, _) = capsule_transition::<S, M, NX>(i, [e[2 * i], e[2 * i + 1]], u, duration_s);
        out[2 * i] = next[0];
        out[2 * i + 1] = next[1];
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `duration_s` counts the coasts between phases, none after the last
    /// sample: the time at which a shot of `n` samples arrives.
    #[test]
    fn duration_counts_the_coasts_between_phases() {
        let dt = 0.02;
        assert_eq!(Schedule::BACK_TO_BACK.duration_s(5, dt), 5.0 * dt);
        let one = Schedule::new(1, 0.02, 80, 0.005);
        assert!((one.duration_s(1, dt) - 0.02).abs() < 1e-12);
        assert!((one.duration_s(3, dt) - (0.06 + 2.0 * 0.02)).abs() < 1e-12);
        let three = Schedule::new(3, 0.03, 80, 0.005);
        assert!((three.duration_s(3, dt) - 0.06).abs() < 1e-12);
        assert!((three.duration_s(4, dt) - (0.08 + 0.03)).abs() < 1e-12);
        assert!((three.duration_s(7, dt) - (0.14 + 0.06)).abs() < 1e-12);
        assert_eq!(three.duration_s(0, dt), 0.0);
    }
}
