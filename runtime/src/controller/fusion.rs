//! The measurement side of the estimator: a frame's class, the innovation
//! gate and the update of every capsule's filter with a frame.

use super::numeric::sq;
use super::settings::{MAX_ABS_SPEED_M_PER_S, MEASUREMENT_GATE_NIS};
use crate::estimator::CapsuleFilter;

/// What a finite-length frame is to the estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Measurement {
    Accepted,
    /// Non-finite or beyond the physical range: ignored, not counted.
    Invalid,
    /// Plausible but beyond the innovation gate: ignored, counted toward
    /// re-acquisition.
    GatedOut,
}

/// Whether every position of frame `z` is within the innovation gate
/// (`MEASUREMENT_GATE_NIS`) of `filters` (measurement variance `r_m2`).
pub(super) fn within_gate(filters: &[CapsuleFilter], z: &[f64], r_m2: f64) -> bool {
    filters.iter().zip(z).all(|(f, &zi)| {
        let innovation = zi - f.mean[0];
        innovation * innovation / (f.cov[0] + r_m2) <= MEASUREMENT_GATE_NIS
    })
}

/// As [`within_gate`], with each capsule's gate widened by its model drift
/// `drift_m[i][0]` (m; see `Controller::accumulate_model_drift`), at most
/// `max_drift_m`: a bound on a coherent error, so it adds to the gate's
/// radius, not its variance.
pub(super) fn within_widened_gate(
    filters: &[CapsuleFilter],
    z: &[f64],
    r_m2: f64,
    drift_m: &[[f64; 2]],
    max_drift_m: f64,
) -> bool {
    filters.iter().zip(z).zip(drift_m).all(|((f, &zi), d)| {
        let excess = (libm::fabs(zi - f.mean[0]) - d[0].min(max_drift_m)).max(0.0);
        excess * excess / (f.cov[0] + r_m2) <= MEASUREMENT_GATE_NIS
    })
}

/// Normalized innovation squared of frame `z` against `filters`, summed
/// over the capsules.
pub(super) fn nis(filters: &[CapsuleFilter], z: &[f64], r_m2: f64) -> f64 {
    filters
        .iter()
        .zip(z)
        .map(|(f, &zi)| sq(zi - f.mean[0]) / (f.cov[0] + r_m2))
        .sum()
}

/// Measurement update of every capsule's filter with frame `z`.
pub(super) fn update_filters(filters: &mut [CapsuleFilter], z: &[f64], r_m2: f64) {
    for (f, &zi) in filters.iter_mut().zip(z) {
        f.update(zi, r_m2);
        // Behind a wide gate (a fresh candidate, or a large disturbance
        // bound) one frame can imply any speed; beyond the physical range
        // the model's prediction overflows to NaN.
        f.mean[1] = f.mean[1].clamp(-MAX_ABS_SPEED_M_PER_S, MAX_ABS_SPEED_M_PER_S);
    }
}
