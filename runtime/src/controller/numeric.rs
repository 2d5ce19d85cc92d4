//! Small numeric helpers of the controller.

/// A one-sample plan (rest zero) for single-step prediction.
pub(super) fn single<const K: usize>(u: f64) -> [f64; K] {
    let mut p = [0.0; K];
    if K > 0 {
        p[0] = u;
    }
    p
}

pub(super) fn sq(v: f64) -> f64 {
    v * v
}

/// Samples at the start of `plan` whose gradient is at most `idle_t_per_m`
/// in magnitude (`plan.len()` when all are).
pub(super) fn leading_idle_samples(plan: &[f64], idle_t_per_m: f64) -> usize {
    plan.iter()
        .position(|u| libm::fabs(*u) > idle_t_per_m)
        .unwrap_or(plan.len())
}

/// Samples of `plan` up to and including its last one whose gradient is
/// above `idle_t_per_m` in magnitude (0 when every sample is idle).
pub(super) fn acting_samples(plan: &[f64], idle_t_per_m: f64) -> usize {
    plan.iter()
        .rposition(|u| libm::fabs(*u) > idle_t_per_m)
        .map_or(0, |k| k + 1)
}
