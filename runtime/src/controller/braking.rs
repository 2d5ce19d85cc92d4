//! The fallback outside the tables (a braking law that leaves the least
//! distance to coast) and the capsules' common mode near rest (means,
//! the group's centre and spread, the mean gradient gain) that the hold
//! law uses.

use super::settings::*;
use super::status::K2;
use capsule_mpc_solver::*;

/// Fallback outside the tables: one braking sample, bounded by u_max,
/// never an extrapolated table value. One gradient changes every capsule's
/// speed alike, so braking the mean speed can leave the capsules moving
/// apart (e.g. 86 and 231 mm/s braked on the mean: -72 and +73 mm/s), and a
/// low-drag capsule then coasts far (drag ~ v^2: 73 mm/s coasts 12 cm in
/// 5 s for the large default capsule). The law minimizes instead the
/// distance the capsules would coast after this sample,
/// sum_i ln(1 + b_i |v_i'| T) / b_i over `BRAKING_HORIZON_S` with b_i
/// measured from the model: that sum is concave in each |v_i'|, so its
/// minimum over the gradient lies where one capsule stops or at +-u_max.
/// At rest (every speed within `REST_SPEED_M_PER_S`) it is zero.
pub fn braking_gradient<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    x: &[f64; NX],
) -> f64 {
    let m = NX / 2;
    if at_rest(x) {
        return 0.0;
    }
    let u_max = S::U_MAX_T_PER_M;
    // Speed change per unit gradient over one sample, and drag per capsule.
    let mut gain = [0.0; K2];
    let mut drag = [0.0; K2];
    for i in 0..m {
        (gain[i], drag[i]) = capsule_gain_and_drag::<S, NX, K>(i);
        if gain[i].is_nan() || gain[i] <= 0.0 || !x[2 * i + 1].is_finite() {
            return 0.0;
        }
    }
    let coast_m = |u: f64| -> f64 {
        let mut d = 0.0;
        for i in 0..m {
            let v = libm::fabs(x[2 * i + 1] + gain[i] * u);
            d += if drag[i] > 0.0 {
                libm::log1p(drag[i] * v * BRAKING_HORIZON_S) / drag[i]
            } else {
                v * BRAKING_HORIZON_S
            };
        }
        d
    };
    let mut best_u = 0.0;
    let mut best = coast_m(0.0);
    let mut consider = |u: f64| {
        let u = u.clamp(-u_max, u_max);
        let d = coast_m(u);
        if d < best {
            best = d;
            best_u = u;
        }
    };
    consider(-u_max);
    consider(u_max);
    for i in 0..m {
        consider(-x[2 * i + 1] / gain[i]);
    }
    best_u
}

/// (speed change per unit gradient over one sample at rest, (m/s)/(T/m);
/// drag coefficient b_i, 1/m) of capsule `i`, from one-sample predictions
/// of the model (no second copy of g_i or b_i).
pub(super) fn capsule_gain_and_drag<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    i: usize,
) -> (f64, f64) {
    let du = 1.0e-3;
    let (pushed, _) = S::capsule_transition(i, [0.0, 0.0], du, S::DT_S);
    let gain = pushed[1] / du;
    // Coasting from v0: v' = -b v^2 gives 1/v(T) - 1/v0 = b T.
    let v0 = 0.1;
    let (coasted, _) = S::capsule_transition(i, [0.0, v0], 0.0, S::DT_S);
    let drag = if coasted[1] > 0.0 {
        (1.0 / coasted[1] - 1.0 / v0) / S::DT_S
    } else {
        0.0
    };
    (gain, drag.max(0.0))
}

/// Drag coefficient b_i of every capsule, 1/m (zero beyond the capsules).
pub(super) fn capsule_drags<S: PlanSolver<NX, K>, const NX: usize, const K: usize>() -> [f64; NX] {
    let mut drag = [0.0; NX];
    for (i, d) in drag.iter_mut().take(NX / 2).enumerate() {
        *d = capsule_gain_and_drag::<S, NX, K>(i).1;
    }
    drag
}

/// Near rest one gradient moves every capsule alike: it sets where the
/// group stands but not how the capsules stand relative to each other.
/// The smallest and largest position error, m, each capsule's motion
/// relative to the mean speed extrapolated over `horizon_s` (0: now).
fn position_extent_m<const NX: usize>(e: &[f64; NX], horizon_s: f64) -> (f64, f64) {
    let (_, mean_v) = capsule_means(e);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..NX / 2 {
        let q = e[2 * i] + (e[2 * i + 1] - mean_v) * horizon_s;
        lo = lo.min(q);
        hi = hi.max(q);
    }
    (lo, hi)
}

/// Half the spread of the position errors about their midpoint (see
/// `position_extent_m`), m: what no hold gradient can shrink.
pub(super) fn half_spread_m<const NX: usize>(e: &[f64; NX], horizon_s: f64) -> f64 {
    let (lo, hi) = position_extent_m(e, horizon_s);
    0.5 * (hi - lo)
}

/// The group's centre: the midpoint of the smallest and the largest
/// position error, m. Bringing it to zero leaves every capsule within the
/// half spread of its target, the best one gradient can do near rest.
pub(super) fn capsule_centre_m<const NX: usize>(e: &[f64; NX]) -> f64 {
    let (lo, hi) = position_extent_m(e, 0.0);
    0.5 * (hi + lo)
}

/// Mean position and mean speed over the capsules of `[x1, v1, x2, v2, ...]`.
pub(super) fn capsule_means<const NX: usize>(x: &[f64; NX]) -> (f64, f64) {
    let m = NX / 2;
    let (mut mean_x, mut mean_v) = (0.0, 0.0);
    for i in 0..m {
        mean_x += x[2 * i] / m as f64;
        mean_v += x[2 * i + 1] / m as f64;
    }
    (mean_x, mean_v)
}

/// The capsules' mean acceleration per unit gradient near rest,
/// (m/s^2)/(T/m), from one-sample predictions of the model (no second copy
/// of g_i).
pub(super) fn mean_gradient_gain<S: PlanSolver<NX, K>, const NX: usize, const K: usize>() -> f64 {
    let m = NX / 2;
    let mut mean_g = 0.0;
    for i in 0..m {
        let (next, _) = S::capsule_transition(i, [0.0, 0.0], 1.0e-3, S::DT_S);
        mean_g += next[1] / (1.0e-3 * S::DT_S) / m as f64;
    }
    mean_g
}

/// Every capsule's speed within `REST_SPEED_M_PER_S`.
pub(super) fn at_rest<const NX: usize>(x: &[f64; NX]) -> bool {
    (0..NX / 2).all(|i| libm::fabs(x[2 * i + 1]) <= REST_SPEED_M_PER_S)
}
