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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idle_samples_are_counted_from_either_end() {
        let plan = [0.0, 1e-6, 0.02, -0.01, 0.0, 1e-6, 0.0];
        assert_eq!(leading_idle_samples(&plan, 1e-5), 2);
        // Up to and including the last acting sample (index 3).
        assert_eq!(acting_samples(&plan, 1e-5), 4);
        assert_eq!(acting_samples(&[0.0; 5], 1e-5), 0);
        assert_eq!(leading_idle_samples(&[0.0; 5], 1e-5), 5);
        assert_eq!(acting_samples(&[-0.04], 1e-5), 1);
    }
}
