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
