//! The capsules' gain and drag factors fitted to a window of frames: a
//! batch (Gauss-Newton) fit of each capsule's start state, two factors and
//! a steady disturbance to every accepted frame since the window's start,
//! with the gradient that was played between them known.
//!
//! Why a window and not a per-frame update: regressed once, linearized
//! where the estimate was then, a frame's innovation goes mostly into the
//! kinematic filter's state; refitted together along one trajectory, a
//! move's frames identify the factors better (docs/decisions.md, "Factors
//! fitted to a window of frames"). The window is fixed-size: when full it
//! restarts from the current estimate with the fit's factors as its prior.

use capsule_mpc_solver::PlanSolver;
use core::marker::PhantomData;

/// Segments (constant-gradient stretches between frames) a window holds.
pub const FIT_SEGMENTS: usize = 96;

/// Frames a window holds.
pub const FIT_FRAMES: usize = 48;

/// Gauss-Newton passes per fit (each warm-started from the last fit).
pub const FIT_PASSES: usize = 2;

/// Smallest variance of the start state's prior (position m^2, speed
/// (m/s)^2): a start known exactly would make the prior singular.
pub const FIT_START_VAR_MIN: [f64; 2] = [1.0e-12, 1.0e-10];

/// How far (prior standard deviations) a window may move a factor from
/// its prior: a disturbance the fit does not model must not drive the
/// factors to their bounds.
pub const FIT_PRIOR_SIGMAS: f64 = 4.0;

/// Smallest variance of the steady disturbance's prior: acceleration
/// ((m/s^2)^2) and position rate ((m/s)^2).
pub const FIT_BIAS_VAR_MIN: [f64; 2] = [1.0e-12, 1.0e-12];

/// Smallest variance of a factor's prior: a factor known exactly (a
/// deviation of 0 trusts the model) stays where it is instead of losing
/// its prior.
pub const FIT_FACTOR_VAR_MIN: f64 = 1.0e-12;

/// Frames beyond the parameters before the frames' scatter may lower
/// their weight (too few residuals say nothing about it).
pub const FIT_INFLATE_MIN_DOF: f64 = 2.0;

/// The fit's parameters per capsule: start position (m), start speed
/// (m/s), gain factor, drag factor, and a steady disturbance (which would
/// otherwise pass for a factor) as a constant acceleration (m/s^2) and a
/// constant position rate (m/s).
const P: usize = 6;

/// Capsule `i`'s model step from (x, v) over a duration at a gradient with
/// factors [gain, drag] and an added constant acceleration `bias`: the
/// next (x, v), its Jacobian in (x, v) (row major 2x2) and its
/// sensitivity to [gain, drag, bias] (row major 2x3).
pub trait FactorStep {
    fn step(
        &self,
        i: usize,
        xv: [f64; 2],
        u: f64,
        duration_s: f64,
        factors: [f64; 2],
        bias_m_per_s2: f64,
    ) -> ([f64; 2], [f64; 4], [f64; 6]);
}

/// What a window starts from, per capsule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitPrior {
    /// The state (x m, v m/s) and its covariance (row major 2x2).
    pub state: [f64; 2],
    pub state_cov: [f64; 4],
    /// The factors [gain, drag] and their covariance.
    pub factors: [f64; 2],
    pub factors_cov: [f64; 4],
    /// The steady disturbance [acceleration m/s^2, position rate m/s] and
    /// its variances.
    pub bias: [f64; 2],
    pub bias_var: [f64; 2],
}

impl FitPrior {
    /// At rest at 0 on the model, nothing known (replaced before a fit).
    pub const MODEL: FitPrior = FitPrior {
        state: [0.0; 2],
        state_cov: [0.0; 4],
        factors: [1.0; 2],
        factors_cov: [0.0; 4],
        bias: [0.0; 2],
        bias_var: [0.0; 2],
    };

    /// The parameters' prior mean (x0, v0, gain, drag, acceleration, rate).
    fn mean(&self) -> [f64; P] {
        [
            self.state[0],
            self.state[1],
            self.factors[0],
            self.factors[1],
            self.bias[0],
            self.bias[1],
        ]
    }
}

/// One window of frames and the gradient played between them, and the
/// fit of every capsule (first M entries) to it.
#[derive(Debug, Clone)]
pub struct FactorWindow<const NX: usize> {
    /// Per capsule: what is known at the window's start.
    prior: [FitPrior; NX],
    /// (gradient T/m, duration s) played since the start.
    segments: [[f64; 2]; FIT_SEGMENTS],
    n_segments: usize,
    /// Time the segments cover, s.
    span_s: f64,
    /// (segments before the frame, positions m).
    frame_at: [usize; FIT_FRAMES],
    frames: [[f64; NX]; FIT_FRAMES],
    n_frames: usize,
    /// Per capsule: the fitted (x0, v0, gain, drag, acceleration, rate) and the
    /// factors' covariance.
    pub fitted: [[f64; P]; NX],
    pub fitted_cov: [[f64; 4]; NX],
}

impl<const NX: usize> FactorWindow<NX> {
    pub const fn new() -> Self {
        FactorWindow {
            prior: [FitPrior::MODEL; NX],
            segments: [[0.0; 2]; FIT_SEGMENTS],
            n_segments: 0,
            span_s: 0.0,
            frame_at: [0; FIT_FRAMES],
            frames: [[0.0; NX]; FIT_FRAMES],
            n_frames: 0,
            fitted: [[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]; NX],
            fitted_cov: [[0.0; 4]; NX],
        }
    }

    /// Empties the window (then `start_capsule` for every capsule).
    pub fn clear(&mut self) {
        self.n_segments = 0;
        self.n_frames = 0;
        self.span_s = 0.0;
    }

    /// Starts capsule `i` from `prior` (a factor that is not a finite
    /// number starts at the model's 1).
    pub fn start_capsule(&mut self, i: usize, prior: FitPrior) {
        let mut prior = prior;
        for f in prior.factors.iter_mut().filter(|f| !f.is_finite()) {
            *f = 1.0;
        }
        self.prior[i] = prior;
        self.fitted[i] = prior.mean();
        self.fitted_cov[i] = prior.factors_cov;
    }

    /// Whether another segment or frame would not fit.
    pub fn is_full(&self) -> bool {
        self.n_segments >= FIT_SEGMENTS || self.n_frames >= FIT_FRAMES
    }

    /// Frames in the window.
    pub fn frames(&self) -> usize {
        self.n_frames
    }

    /// Time the window's segments cover, s.
    pub fn span_s(&self) -> f64 {
        self.span_s
    }

    /// Gradient `u` played for `duration_s` (merged with the previous
    /// segment when no frame came between and the gradient is the same).
    /// False when the window is full.
    pub fn record_segment(&mut self, u: f64, duration_s: f64) -> bool {
        if duration_s.is_nan() || duration_s <= 0.0 {
            return true;
        }
        let n = self.n_segments;
        let frame_between = self.n_frames > 0 && self.frame_at[self.n_frames - 1] == n;
        if n > 0 && !frame_between && self.segments[n - 1][0] == u {
            self.segments[n - 1][1] += duration_s;
            self.span_s += duration_s;
            return true;
        }
        if n >= FIT_SEGMENTS {
            return false;
        }
        self.segments[n] = [u, duration_s];
        self.n_segments += 1;
        self.span_s += duration_s;
        true
    }

    /// An accepted frame `z` (first M entries) now. False when full.
    pub fn record_frame(&mut self, z: &[f64]) -> bool {
        if self.n_frames >= FIT_FRAMES {
            return false;
        }
        let k = self.n_frames;
        self.frame_at[k] = self.n_segments;
        for (f, &p) in self.frames[k].iter_mut().zip(z) {
            *f = p;
        }
        self.n_frames += 1;
        true
    }

    /// Refits capsule `i` (`FIT_PASSES` Gauss-Newton passes from the last
    /// fit) with frame variance `noise.r_m2`; the disturbance of
    /// acceleration PSD `noise.accel_psd` widens later frames' variance.
    /// Each factor stays within `FIT_PRIOR_SIGMAS` prior standard
    /// deviations of its prior and within `bounds`.
    pub fn fit_capsule<F: FactorStep>(
        &mut self,
        i: usize,
        model: &F,
        noise: FitNoise,
        bounds: [f64; 2],
    ) {
        let reach = |k: usize| {
            let std = libm::sqrt(self.prior[i].factors_cov[3 * k].max(0.0));
            let m = self.prior[i].factors[k].clamp(bounds[0], bounds[1]);
            let lo = (m - FIT_PRIOR_SIGMAS * std).max(bounds[0]);
            let hi = (m + FIT_PRIOR_SIGMAS * std).min(bounds[1]);
            // A prior that is not a number leaves only the bounds.
            if lo.is_nan() || hi.is_nan() {
                bounds
            } else {
                [lo, hi.max(lo)]
            }
        };
        let (gain_range, drag_range) = (reach(0), reach(1));
        let prior_info = self.prior_information(i);
        let prior_mean = self.prior[i].mean();
        let mut p = self.fitted[i];
        for _ in 0..FIT_PASSES {
            let Some(data) = self.frames_information(i, model, &p, noise) else {
                return;
            };
            let mut h = prior_info;
            let mut g = data.gradient;
            for a in 0..P {
                for b in 0..P {
                    h[a * P + b] += data.information[a * P + b];
                    g[a] += prior_info[a * P + b] * (prior_mean[b] - p[b]);
                }
            }
            let Some(l) = cholesky(&h) else {
                return;
            };
            let d = cholesky_solve(&l, &g);
            for k in 0..P {
                p[k] += d[k];
            }
            p[2] = p[2].clamp(gain_range[0], gain_range[1]);
            p[3] = p[3].clamp(drag_range[0], drag_range[1]);
            if !p.iter().all(|v| v.is_finite()) {
                return;
            }
        }
        let Some(data) = self.frames_information(i, model, &p, noise) else {
            return;
        };
        // The frames count for less when they scatter more than their
        // noise says (a disturbance the fit does not model); the prior
        // (a calibration, or the last window) keeps its weight.
        let dof = self.n_frames as f64 - P as f64;
        let inflate = if dof > FIT_INFLATE_MIN_DOF {
            (data.chi2 / dof).max(1.0)
        } else {
            1.0
        };
        let mut h = prior_info;
        for (hk, dk) in h.iter_mut().zip(&data.information) {
            *hk += dk / inflate;
        }
        let Some(l) = cholesky(&h) else {
            return;
        };
        let c0 = cholesky_solve(&l, &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        let c1 = cholesky_solve(&l, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        let cov = [c0[2], c1[2], c0[3], c1[3]];
        if !(cov.iter().all(|v| v.is_finite()) && cov[0] > 0.0 && cov[3] > 0.0) {
            return;
        }
        self.fitted[i] = p;
        self.fitted_cov[i] = cov;
    }

    /// The prior's information matrix (6x6, row major): block diagonal in
    /// the start state, the factors and the steady disturbance.
    fn prior_information(&self, i: usize) -> [f64; P * P] {
        let s = self.prior[i].state_cov;
        let s = [
            s[0].max(FIT_START_VAR_MIN[0]),
            s[1],
            s[2],
            s[3].max(FIT_START_VAR_MIN[1]),
        ];
        let a = inverse2(s);
        let f = self.prior[i].factors_cov;
        let b = inverse2([
            f[0].max(FIT_FACTOR_VAR_MIN),
            f[1],
            f[2],
            f[3].max(FIT_FACTOR_VAR_MIN),
        ]);
        let mut h = [0.0; P * P];
        h[0] = a[0];
        h[1] = a[1];
        h[P] = a[2];
        h[P + 1] = a[3];
        h[2 * P + 2] = b[0];
        h[2 * P + 3] = b[1];
        h[3 * P + 2] = b[2];
        h[3 * P + 3] = b[3];
        h[4 * P + 4] = 1.0 / self.prior[i].bias_var[0].max(FIT_BIAS_VAR_MIN[0]);
        h[5 * P + 5] = 1.0 / self.prior[i].bias_var[1].max(FIT_BIAS_VAR_MIN[1]);
        h
    }

    /// What the frames say about capsule `i`'s parameters, linearized at
    /// `p`: one rollout with its sensitivity.
    fn frames_information<F: FactorStep>(
        &self,
        i: usize,
        model: &F,
        p: &[f64; P],
        noise: FitNoise,
    ) -> Option<FramesInformation> {
        let mut t_s = 0.0;
        let mut out = FramesInformation {
            information: [0.0; P * P],
            gradient: [0.0; P],
            chi2: 0.0,
        };
        // The trajectory's (x, v) so far.
        let mut xv = [p[0], p[1]];
        // d(x, v)/d(x0, v0, gain, drag, bias), rows x and v.
        let mut sens = [
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        ];
        let mut f = 0;
        for seg in 0..=self.n_segments {
            while f < self.n_frames && self.frame_at[f] == seg {
                // What the disturbance adds since the start, as if white.
                let w = 1.0 / (noise.r_m2 + noise.accel_psd * t_s * t_s * t_s / 3.0);
                let r = self.frames[f][i] - xv[0];
                out.chi2 += r * r * w;
                for a in 0..P {
                    out.gradient[a] += sens[0][a] * w * r;
                    for b in 0..P {
                        out.information[a * P + b] += sens[0][a] * w * sens[0][b];
                    }
                }
                f += 1;
            }
            if seg == self.n_segments {
                break;
            }
            let [u, dt] = self.segments[seg];
            let (next, a, b) = model.step(i, xv, u, dt, [p[2], p[3]], p[4]);
            let old = sens;
            for c in 0..P {
                sens[0][c] = a[0] * old[0][c] + a[1] * old[1][c];
                sens[1][c] = a[2] * old[0][c] + a[3] * old[1][c];
            }
            for c in 0..3 {
                sens[0][2 + c] += b[c];
                sens[1][2 + c] += b[3 + c];
            }
            sens[0][5] += dt;
            xv = [next[0] + p[5] * dt, next[1]];
            t_s += dt;
        }
        let finite = out
            .information
            .iter()
            .chain(&out.gradient)
            .all(|v| v.is_finite())
            && out.chi2.is_finite();
        finite.then_some(out)
    }
}

/// What the frames' residuals are made of.
#[derive(Debug, Clone, Copy)]
pub struct FitNoise {
    /// A frame's variance, m^2.
    pub r_m2: f64,
    /// The disturbance's acceleration PSD, (m/s^2)^2 s.
    pub accel_psd: f64,
}

/// The frames' part of a fit's normal equations.
struct FramesInformation {
    /// J' W J (row major) and J' W r.
    information: [f64; P * P],
    gradient: [f64; P],
    /// Sum of squared residuals over their variance.
    chi2: f64,
}

/// The generated model's step (`PlanSolver::capsule_transition_scaled`)
/// with its sensitivities by differences of the same step.
pub struct ModelStep<S, const NX: usize, const K: usize>(PhantomData<S>);

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> ModelStep<S, NX, K> {
    pub const fn new() -> Self {
        ModelStep(PhantomData)
    }
}

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Default for ModelStep<S, NX, K> {
    fn default() -> Self {
        Self::new()
    }
}

/// Step of the constant acceleration in its difference quotient, m/s^2.
pub const BIAS_STEP_M_PER_S2: f64 = 1.0e-4;

/// Step of the factors in their difference quotients.
pub const FACTOR_STEP: f64 = 1.0e-3;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> FactorStep for ModelStep<S, NX, K> {
    fn step(
        &self,
        i: usize,
        xv: [f64; 2],
        u: f64,
        duration_s: f64,
        factors: [f64; 2],
        bias_m_per_s2: f64,
    ) -> ([f64; 2], [f64; 4], [f64; 6]) {
        // A constant acceleration on capsule i alone is a gradient offset
        // in its own step.
        let per_gradient = factors[0] * S::capsule_gain(i);
        if per_gradient == 0.0 || per_gradient.is_nan() {
            let (base, a, b) = factor_step::<S, NX, K>(i, xv, u, duration_s, factors);
            return (base, a, [b[0], b[1], 0.0, b[2], b[3], 0.0]);
        }
        let u_bias = u + bias_m_per_s2 / per_gradient;
        let (base, a, b) = factor_step::<S, NX, K>(i, xv, u_bias, duration_s, factors);
        let du = BIAS_STEP_M_PER_S2 / per_gradient;
        let (c, _) = S::capsule_transition_scaled(i, xv, u_bias + du, duration_s, factors);
        let dc = [
            (c[0] - base[0]) / BIAS_STEP_M_PER_S2,
            (c[1] - base[1]) / BIAS_STEP_M_PER_S2,
        ];
        // The gain's column is taken at a fixed gradient offset, so it
        // carries bias / gain of the bias's column too; the exact partial
        // at a fixed bias lets glitch frames the gate accepted move the
        // factors further (docs/decisions.md, "Factors fitted to a window").
        (base, a, [b[0], b[1], dc[0], b[2], b[3], dc[1]])
    }
}

/// Capsule `i`'s model step from `mean` over `duration_s` at gradient `u`
/// with factors `scale`: the next (x, v), its Jacobian in (x, v) and its
/// sensitivity to the factors (row major; columns gain, drag), by
/// differences of the same step.
pub fn factor_step<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    i: usize,
    mean: [f64; 2],
    u: f64,
    duration_s: f64,
    scale: [f64; 2],
) -> ([f64; 2], [f64; 4], [f64; 4]) {
    let (base, a) = S::capsule_transition_scaled(i, mean, u, duration_s, scale);
    let (g, _) =
        S::capsule_transition_scaled(i, mean, u, duration_s, [scale[0] + FACTOR_STEP, scale[1]]);
    let (d, _) =
        S::capsule_transition_scaled(i, mean, u, duration_s, [scale[0], scale[1] + FACTOR_STEP]);
    let b = [
        (g[0] - base[0]) / FACTOR_STEP,
        (d[0] - base[0]) / FACTOR_STEP,
        (g[1] - base[1]) / FACTOR_STEP,
        (d[1] - base[1]) / FACTOR_STEP,
    ];
    (base, a, b)
}

impl<const NX: usize> Default for FactorWindow<NX> {
    fn default() -> Self {
        Self::new()
    }
}

/// Inverse of a symmetric 2x2 (row major); zero when singular.
fn inverse2(m: [f64; 4]) -> [f64; 4] {
    let det = m[0] * m[3] - m[1] * m[2];
    if det.is_nan() || det <= 0.0 || det.is_infinite() {
        return [0.0; 4];
    }
    [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det]
}

/// Lower Cholesky factor of a P x P (row major); None unless positive
/// definite.
fn cholesky(h: &[f64; P * P]) -> Option<[f64; P * P]> {
    let mut l = [0.0; P * P];
    for r in 0..P {
        for c in 0..=r {
            let mut s = h[r * P + c];
            for k in 0..c {
                s -= l[r * P + k] * l[c * P + k];
            }
            if r == c {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                l[r * P + c] = libm::sqrt(s);
            } else {
                l[r * P + c] = s / l[c * P + c];
            }
        }
    }
    Some(l)
}

/// Solves L L' x = b.
fn cholesky_solve(l: &[f64; P * P], b: &[f64; P]) -> [f64; P] {
    let mut y = [0.0; P];
    for r in 0..P {
        let mut s = b[r];
        for k in 0..r {
            s -= l[r * P + k] * y[k];
        }
        y[r] = s / l[r * P + r];
    }
    let mut x = [0.0; P];
    for r in (0..P).rev() {
        let mut s = y[r];
        for k in r + 1..P {
            s -= l[k * P + r] * x[k];
        }
        x[r] = s / l[r * P + r];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x'' = GAIN fg u - DRAG fd v|v| + bias, by RK4 in 1 ms substeps;
    /// sensitivities by differences.
    struct Toy;
    const GAIN: f64 = 2.0;
    const DRAG: f64 = 40.0;

    fn roll(xv: [f64; 2], u: f64, dt: f64, f: [f64; 2], c: f64) -> [f64; 2] {
        let acc = |v: f64| GAIN * f[0] * u - DRAG * f[1] * v * libm::fabs(v) + c;
        let n = libm::ceil(dt / 1e-3) as usize;
        let h = dt / n as f64;
        let (mut x, mut v) = (xv[0], xv[1]);
        for _ in 0..n {
            let (k1x, k1v) = (v, acc(v));
            let (k2x, k2v) = (v + 0.5 * h * k1v, acc(v + 0.5 * h * k1v));
            let (k3x, k3v) = (v + 0.5 * h * k2v, acc(v + 0.5 * h * k2v));
            let (k4x, k4v) = (v + h * k3v, acc(v + h * k3v));
            x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        }
        [x, v]
    }

    impl FactorStep for Toy {
        fn step(
            &self,
            _i: usize,
            xv: [f64; 2],
            u: f64,
            dt: f64,
            f: [f64; 2],
            c: f64,
        ) -> ([f64; 2], [f64; 4], [f64; 6]) {
            let base = roll(xv, u, dt, f, c);
            let e = 1e-6;
            let d = |n: [f64; 2], s: f64| [(n[0] - base[0]) / s, (n[1] - base[1]) / s];
            let dx = d(roll([xv[0] + e, xv[1]], u, dt, f, c), e);
            let dv = d(roll([xv[0], xv[1] + e], u, dt, f, c), e);
            let dg = d(roll(xv, u, dt, [f[0] + e, f[1]], c), e);
            let dd = d(roll(xv, u, dt, [f[0], f[1] + e], c), e);
            let dc = d(roll(xv, u, dt, f, c + e), e);
            (
                base,
                [dx[0], dv[0], dx[1], dv[1]],
                [dg[0], dd[0], dc[0], dg[1], dd[1], dc[1]],
            )
        }
    }

    /// Bang-bang moves out and back, 0.8 s each in 20 ms samples, a frame
    /// after every fourth sample.
    fn observe(truth: [f64; 2], bias: f64, window: &mut FactorWindow<2>) {
        let mut xv = [0.0, 0.0];
        for k in 0..80 {
            let u = if (20..60).contains(&k) { -0.04 } else { 0.04 };
            xv = roll(xv, u, 0.02, truth, bias);
            window.record_segment(u, 0.02);
            if k % 4 == 3 {
                window.record_frame(&[xv[0], 0.0]);
            }
        }
    }

    /// Frames exact, no disturbance.
    const EXACT: FitNoise = FitNoise {
        r_m2: 1e-10,
        accel_psd: 0.0,
    };

    /// The runtime's factor bounds.
    const BOUNDS: [f64; 2] = [0.25, 4.0];

    /// At rest at 0 (known to 0.1 mm and 0.1 mm/s), with these factors.
    fn at_rest(factors: [f64; 2], factors_cov: [f64; 4], bias_var: f64) -> FitPrior {
        FitPrior {
            state: [0.0, 0.0],
            state_cov: [1e-8, 0.0, 0.0, 1e-8],
            factors,
            factors_cov,
            bias: [0.0; 2],
            bias_var: [bias_var; 2],
        }
    }

    /// Capsule 0 started from `prior`, the out-and-back move on a plant
    /// with `truth` and `bias` observed, then refitted `fits` times.
    fn fit_from(prior: FitPrior, truth: [f64; 2], bias: f64, fits: usize) -> FactorWindow<2> {
        let mut w = FactorWindow::<2>::new();
        w.start_capsule(0, prior);
        observe(truth, bias, &mut w);
        for _ in 0..fits {
            w.fit_capsule(0, &Toy, EXACT, BOUNDS);
        }
        w
    }

    /// The model's prior (1 +- 0.1 and 1 +- 0.2), fitted 4 times.
    fn fitted(truth: [f64; 2], bias: f64, bias_std: f64) -> [f64; P] {
        let prior = at_rest([1.0, 1.0], [0.01, 0.0, 0.0, 0.04], bias_std * bias_std);
        fit_from(prior, truth, bias, 4).fitted[0]
    }

    #[test]
    fn recovers_the_factors_of_a_move_off_the_model() {
        for truth in [[1.1, 1.0], [1.0, 1.2], [0.9, 0.8], [1.1, 1.2]] {
            let p = fitted(truth, 0.0, 1e-5);
            assert!(libm::fabs(p[2] - truth[0]) < 2e-3, "{truth:?}: {p:?}");
            assert!(libm::fabs(p[3] - truth[1]) < 5e-3, "{truth:?}: {p:?}");
        }
    }

    /// Out and back, drag and a steady push differ (one move one way
    /// alone hardly tells them apart: both bend its path alike).
    #[test]
    fn tells_a_constant_acceleration_from_the_factors() {
        for truth in [[1.0, 1.0], [1.1, 1.2]] {
            let p = fitted(truth, 5e-4, 5e-4);
            assert!(libm::fabs(p[2] - truth[0]) < 2e-3, "{p:?}");
            assert!(libm::fabs(p[3] - truth[1]) < 5e-3, "{p:?}");
            // Part of it may pass for a position rate, which is allowed.
            assert!(libm::fabs(p[4] - 5e-4) < 1.5e-4, "{p:?}");
        }
    }

    /// A factor whose prior deviation is 0 (the model trusted) stays at
    /// its prior, and the other is still learned.
    #[test]
    fn a_factor_known_exactly_stays() {
        let prior = at_rest([1.0, 1.0], [0.0, 0.0, 0.0, 0.04], 1e-10);
        let w = fit_from(prior, [1.0, 1.2], 0.0, 4);
        let p = w.fitted[0];
        assert!(libm::fabs(p[2] - 1.0) < 1e-6, "{p:?}");
        assert!(libm::fabs(p[3] - 1.2) < 5e-3, "{p:?}");
        assert!(w.fitted_cov[0][0] < 1e-9, "{:?}", w.fitted_cov[0]);
    }

    /// Priors beyond the bounds or not numbers leave finite factors within
    /// the bounds (and no panic).
    #[test]
    fn a_prior_outside_the_bounds_stays_within_them() {
        for factors in [
            [10.0, 0.1],
            [f64::NAN, 1.0],
            [f64::INFINITY, f64::NEG_INFINITY],
        ] {
            let prior = at_rest(factors, [0.01, 0.0, 0.0, 0.04], 1e-10);
            let p = fit_from(prior, [1.0, 1.0], 0.0, 1).fitted[0];
            for k in [2, 3] {
                assert!(
                    (BOUNDS[0]..=BOUNDS[1]).contains(&p[k]),
                    "{factors:?}: {p:?}"
                );
            }
        }
    }
}
