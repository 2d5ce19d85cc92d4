//! Grids of the offline tables: an axis of grid points, flat row-major
//! indices over several axes, the plan stored per grid point, the
//! deterministic starting guesses of the solves and the progress hook.
//! Everything the plan, index and leg builders share, so that none of them
//! imports from `tables`, which assembles them.

use crate::ocp::Plan;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// Grid geometry shared by the plan grid and the index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// Value of the first point.
    pub start: f64,
    pub step: f64,
    pub count: usize,
}

impl Axis {
    pub fn symmetric(half_range: f64, step: f64) -> Axis {
        let half = (half_range / step).round() as usize;
        Axis {
            start: -(half as f64) * step,
            step,
            count: 2 * half + 1,
        }
    }

    pub fn value(&self, i: usize) -> f64 {
        self.start + i as f64 * self.step
    }

    /// Nearest point, or None outside the axis (half a step of margin).
    pub fn nearest(&self, v: f64) -> Option<usize> {
        let f = ((v - self.start) / self.step).round();
        (f >= 0.0 && f < self.count as f64).then_some(f as usize)
    }
}

/// One stored plan, from rest at `e0`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanEntry {
    pub e0: Vec<f64>,
    pub plan: Plan,
    /// Whether a minimum-time plan was found within the plan length.
    pub reached: bool,
    /// Samples of the minimum-time plan, into [`crate::mintime::PLAN_BAND`] (0 when not
    /// reached); zero gradient follows up to the plan length.
    pub arrival_samples: usize,
    /// Minimum rest-to-rest time into the settle band (1 mm, 5 mm/s), s:
    /// the first instant after which the minimum-time plan stays in the
    /// band (infinite when not reached). An upper bound on the true
    /// minimum, as every local method's is.
    pub min_time_s: f64,
}

/// Row-major multi-index of flat index `flat` over `dims`.
pub fn unflatten(mut flat: usize, dims: &[usize]) -> Vec<usize> {
    let mut out = vec![0; dims.len()];
    for (d, &n) in dims.iter().enumerate().rev() {
        out[d] = flat % n;
        flat /= n;
    }
    out
}

pub fn flatten(idx: &[usize], dims: &[usize]) -> usize {
    idx.iter().zip(dims).fold(0, |acc, (&i, &n)| acc * n + i)
}

/// Deterministic starting guesses: zero input plus random piecewise-constant
/// sequences (segments of 2-11 samples, levels in [-u_max, u_max]).
pub fn starting_guesses(seed: u64, starts: usize, steps: usize, u_max: f64) -> Vec<Vec<f64>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut guesses = vec![vec![0.0; steps]];
    while guesses.len() < starts {
        let mut u = vec![0.0; steps];
        let mut i = 0;
        while i < steps {
            let len = rng.gen_range(2..12);
            let level = rng.gen_range(-1.0..1.0) * u_max;
            for v in u.iter_mut().skip(i).take(len) {
                *v = level;
            }
            i += len;
        }
        guesses.push(u);
    }
    guesses
}

/// Progress reporting hook (the CLI shows a progress bar).
pub trait Progress: Sync {
    fn start(&self, phase: &str, total: usize);
    fn tick(&self);
}

/// No progress output.
pub struct Silent;
impl Progress for Silent {
    fn start(&self, _: &str, _: usize) {}
    fn tick(&self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flatten_roundtrip() {
        let dims = [3, 5, 7];
        for f in 0..105 {
            assert_eq!(flatten(&unflatten(f, &dims), &dims), f);
        }
    }
}
