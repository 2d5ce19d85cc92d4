//! Three capsules' third combination in the hold. Near rest one gradient
//! accelerates capsule i by g_i u and the station-keeping dither acts
//! through drag along b_i g_i^2 (see `station`): of three capsules'
//! positions the hold moves two combinations, and the third, orthogonal
//! to both, only drifts. What an arrival leaves in it (the estimate's
//! speed error before the last open-loop phase, a few tenths of a mm/s)
//! and the disturbance walk the capsules out of the band within seconds;
//! only the dither's speed-dependent drag damps it, at about 0.2 /s. A
//! line through the hold's raw frames along that combination tells the
//! walk; where even its optimistic end leaves the band within
//! `HOLD_THIRD_HORIZON_S`, the hold is left, once per target, for a
//! manoeuvre while the capsules are still near their targets; and
//! whenever the walk has carried a capsule to the band's edge, the hold is
//! left for a shot instead of sitting there.

use super::braking::capsule_gain_and_drag;
use super::settings::*;
use super::Controller;
use capsule_mpc_solver::*;

/// Below this sine of the angle between the gradient's and the dither's
/// directions the two do not span a plane (capsules with one drag).
const PARALLEL_SINE: f64 = 1e-6;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Whether the hold is left for the third combination's walk: three
    /// capsules under the scanner cycle (ideal sampling knows the state)
    /// with shots on (the manoeuvre is a shot), judged once per hold when
    /// its frames along the combination span `HOLD_THIRD_FIT_S`, at most
    /// `HOLD_THIRD_EXITS` times per target, once the learned factors
    /// differ from the told ones (on the model a drifting disturbance's
    /// swings, which reverse, set off exits that cost station keeping:
    /// docs/decisions.md). Left when the line through the frames, its rate
    /// taken `HOLD_THIRD_RATE_SIGMAS` deviations nearer zero, ends beyond
    /// `HOLD_THIRD_SPREAD_M` within `HOLD_THIRD_HORIZON_S`.
    pub(super) fn hold_walks_out_third(&mut self) -> bool {
        if self.settings.sampling == Sampling::Ideal
            || self.law.third_direction.iter().all(|&d| d == 0.0)
            || self.sup.third_exits >= HOLD_THIRD_EXITS
            || self.law.third_frames.judged
            || !self.law.third_frames.covers(HOLD_THIRD_FIT_S)
            || !self.shots_on()
            || !self.factors_differ_from_told()
        {
            return false;
        }
        self.law.third_frames.judged = true;
        // A unit direction: the coordinate's noise is a frame's.
        let Some(line) = self.law.third_frames.line(self.settings.position_noise_m) else {
            return false;
        };
        let slack = HOLD_THIRD_RATE_SIGMAS * line.rate_std;
        let rate = libm::copysign((libm::fabs(line.rate) - slack).max(0.0), line.rate);
        let walks_out =
            libm::fabs(line.coordinate + rate * HOLD_THIRD_HORIZON_S) > HOLD_THIRD_SPREAD_M;
        if walks_out {
            self.sup.third_exits += 1;
        }
        walks_out
    }

    /// Whether the hold is left because the third combination has walked
    /// out: three capsules under the scanner cycle with shots on, after
    /// `HOLD_THIRD_RECENT_S` in the hold, when the line through that
    /// latest stretch of frames (or the latest `HOLD_LINE_MIN_FRAMES`,
    /// on longer cycles) puts the capsule with the largest share of
    /// the combination beyond `HOLD_THIRD_OUT_M` by the walk alone. Unlike
    /// the look above it waits for the walk to reach the band's edge, so a
    /// drifting disturbance's swings, which reverse inside the band, do
    /// not set it off, and it is neither gated on the factors nor counted:
    /// station keeping drifts out again and again over a long hold
    /// (docs/known-limits.md, "Three capsules"), and a capsule at the edge is out of the
    /// band whether or not the hold is left.
    pub(super) fn hold_walked_out_third(&self) -> bool {
        if self.settings.sampling == Sampling::Ideal
            || self.law.third_direction.iter().all(|&d| d == 0.0)
            || self.law.station.held_s() < HOLD_THIRD_RECENT_S
            || !self.shots_on()
        {
            return false;
        }
        let from_s = self.law.third_frames.start_of_latest(
            self.law.station.held_s() - HOLD_THIRD_RECENT_S,
            HOLD_LINE_MIN_FRAMES,
        );
        let Some(line) = self
            .law
            .third_frames
            .line_since(from_s, self.settings.position_noise_m)
        else {
            return false;
        };
        let share = self
            .law
            .third_direction
            .iter()
            .take(NX / 2)
            .fold(0.0_f64, |m, d| m.max(libm::fabs(*d)));
        share * libm::fabs(line.coordinate) > HOLD_THIRD_OUT_M
    }

    /// Logs the frame with positions `p` (relative to the targets, m) at
    /// `t_s` since hold entry along the third combination of the factors
    /// now in use; when the factors have turned it by more than
    /// `HOLD_THIRD_DIRECTION_TOLERANCE`, the frames logged along the old
    /// one are dropped first.
    pub(super) fn log_third_frame(&mut self, t_s: f64, p: &[f64]) {
        // Only three capsules have one (a constant test: no work otherwise).
        if NX / 2 != 3 {
            return;
        }
        let direction = self.third_direction_now();
        let turned = direction
            .iter()
            .zip(&self.law.third_direction)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>();
        if turned > HOLD_THIRD_DIRECTION_TOLERANCE * HOLD_THIRD_DIRECTION_TOLERANCE {
            self.law.third_direction = direction;
            self.law.third_frames.clear();
        }
        let zeta = direction
            .iter()
            .zip(p)
            .take(NX / 2)
            .map(|(d, x)| d * x)
            .sum();
        self.law.third_frames.push(t_s, zeta);
    }

    /// At hold entry: the combination with the factors in use, and its
    /// frames forgotten.
    pub(super) fn start_third_frames(&mut self) {
        self.law.third_direction = self.third_direction_now();
        self.law.third_frames.clear();
    }

    /// The third combination with each capsule's gain and drag scaled by
    /// its factors in use.
    fn third_direction_now(&self) -> [f64; NX] {
        let mut gain = [0.0; NX];
        let mut drag = [0.0; NX];
        for i in 0..NX / 2 {
            let (g, b) = capsule_gain_and_drag::<S, NX, K>(i);
            let f = self.est.applied_scales[i];
            gain[i] = g * f[0];
            drag[i] = b * f[1];
        }
        third_direction(&gain, &drag)
    }
}

/// The third combination's unit direction for three capsules with gains
/// `gain` and drag coefficients `drag` (first three entries): orthogonal
/// to the gradient's `g_i` and the dither's `b_i g_i^2`. Zero for any
/// other number of capsules, or where the two do not span a plane.
pub fn third_direction<const NX: usize>(gain: &[f64; NX], drag: &[f64; NX]) -> [f64; NX] {
    let mut out = [0.0; NX];
    if NX / 2 != 3 {
        return out;
    }
    let a = [gain[0], gain[1], gain[2]];
    let b: [f64; 3] = core::array::from_fn(|i| drag[i] * gain[i] * gain[i]);
    let c = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    let norm = norm3(&c);
    // |a x b| = |a| |b| sin(angle).
    if !(norm.is_finite() && norm > PARALLEL_SINE * norm3(&a) * norm3(&b)) {
        return out;
    }
    for (o, x) in out.iter_mut().zip(c) {
        *o = x / norm;
    }
    out
}

fn norm3(v: &[f64; 3]) -> f64 {
    libm::sqrt(v.iter().map(|x| x * x).sum::<f64>())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_third_direction_is_what_neither_the_gradient_nor_the_dither_moves() {
        let gain = [173.0, 160.0, 180.0, 0.0, 0.0, 0.0];
        let drag = [135.0, 43.0, 17.0, 0.0, 0.0, 0.0];
        let c = third_direction(&gain, &drag);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).take(3).map(|(x, y)| x * y).sum::<f64>();
        let dither: [f64; 3] = core::array::from_fn(|i| drag[i] * gain[i] * gain[i]);
        assert!(dot(&c, &gain).abs() < 1e-9 * 173.0);
        assert!(dot(&c, &dither).abs() < 1e-9 * 135.0 * 173.0 * 173.0);
        assert!((dot(&c, &c) - 1.0).abs() < 1e-12);
        // One gain and one drag for all: the dither's direction is the
        // gradient's.
        assert_eq!(third_direction(&[173.0; 6], &[40.0; 6]), [0.0; 6]);
        // Two capsules have no third combination.
        assert_eq!(
            third_direction(&[1.0, 2.0, 0.0, 0.0], &[3.0, 1.0, 0.0, 0.0]),
            [0.0; 4]
        );
        // Non-finite factors give none either.
        assert_eq!(
            third_direction(&[f64::NAN, 160.0, 180.0, 0.0, 0.0, 0.0], &drag),
            [0.0; 6]
        );
    }
}
