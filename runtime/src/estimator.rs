//! State estimate from position-only measurements: an extended Kalman
//! filter on the capsule model. The capsules are coupled only through the
//! known input, and each is measured separately, so the filter splits into
//! one exact 2-state EKF per capsule (2x2 covariance each).

/// Per-capsule filter state: mean (x, v) and covariance (row major 2x2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CapsuleFilter {
    pub mean: [f64; 2],
    pub cov: [f64; 4],
}

/// Default initial speed uncertainty (standard deviation), m/s: capsules
/// start at rest, but the estimator must not be certain of it.
pub const INITIAL_SPEED_STD_M_PER_S: f64 = 0.01;

/// Speed uncertainty (standard deviation) of a re-acquisition candidate at
/// its first frame, m/s: the capsules may be moving at up to their terminal
/// speed at u_max (0.64 m/s for the faster default capsule). Wide, so that
/// the next frame passes the candidate's gate wherever the capsules went
/// and its update sets the speeds.
pub const REACQUIRE_SPEED_STD_M_PER_S: f64 = 0.5;

impl CapsuleFilter {
    /// At rest at `position_m` (the caller knows the capsule is at rest).
    pub const fn new(position_m: f64, position_std_m: f64) -> CapsuleFilter {
        CapsuleFilter::with_speed_std(position_m, position_std_m, INITIAL_SPEED_STD_M_PER_S)
    }

    /// At `position_m`, speed estimate zero with uncertainty `speed_std_m_per_s`.
    pub const fn with_speed_std(
        position_m: f64,
        position_std_m: f64,
        speed_std_m_per_s: f64,
    ) -> CapsuleFilter {
        CapsuleFilter {
            mean: [position_m, 0.0],
            cov: [
                position_std_m * position_std_m,
                0.0,
                0.0,
                speed_std_m_per_s * speed_std_m_per_s,
            ],
        }
    }

    /// Time update with transition `next` and Jacobian `a` over `duration_s`;
    /// process noise: a random acceleration of spectral density `accel_psd`
    /// ((m/s^2)^2 s) and a random velocity of density `vel_psd` ((m/s)^2 s).
    pub fn predict(
        &mut self,
        next: [f64; 2],
        a: [f64; 4],
        duration_s: f64,
        accel_psd: f64,
        vel_psd: f64,
    ) {
        let p = self.cov;
        // A P A'
        let ap = [
            a[0] * p[0] + a[1] * p[2],
            a[0] * p[1] + a[1] * p[3],
            a[2] * p[0] + a[3] * p[2],
            a[2] * p[1] + a[3] * p[3],
        ];
        let mut n = [
            ap[0] * a[0] + ap[1] * a[1],
            ap[0] * a[2] + ap[1] * a[3],
            ap[2] * a[0] + ap[3] * a[1],
            ap[2] * a[2] + ap[3] * a[3],
        ];
        // Continuous white-noise acceleration model, discretized.
        let t = duration_s;
        n[0] += accel_psd * t * t * t / 3.0 + vel_psd * t;
        n[1] += accel_psd * t * t / 2.0;
        n[2] += accel_psd * t * t / 2.0;
        n[3] += accel_psd * t;
        self.mean = next;
        self.cov = n;
    }

    /// Measurement update with a position `z_m` of variance `r_m2`.
    /// Returns the normalized innovation squared (for gating).
    pub fn update(&mut self, z_m: f64, r_m2: f64) -> f64 {
        let p = self.cov;
        let s = p[0] + r_m2;
        let innovation = z_m - self.mean[0];
        let k = [p[0] / s, p[2] / s];
        self.mean[0] += k[0] * innovation;
        self.mean[1] += k[1] * innovation;
        // Joseph-free form is fine for a scalar update of a 2x2 covariance.
        self.cov = [
            (1.0 - k[0]) * p[0],
            (1.0 - k[0]) * p[1],
            p[2] - k[1] * p[0],
            p[3] - k[1] * p[1],
        ];
        // Keep it symmetric against rounding.
        let off = 0.5 * (self.cov[1] + self.cov[2]);
        self.cov[1] = off;
        self.cov[2] = off;
        innovation * innovation / s
    }

    pub fn position_std_m(&self) -> f64 {
        libm::sqrt(self.cov[0].max(0.0))
    }

    pub fn speed_std_m_per_s(&self) -> f64 {
        libm::sqrt(self.cov[3].max(0.0))
    }
}

/// Per capsule: how it differs from the model, as factors on its magnetic
/// gain and on its drag (1 = the model): their mean and covariance (from
/// the fit of a window of frames, `factor_fit`, or under ideal sampling
/// regressed on each full state's speed), and the sensitivity of the
/// kinematic estimate to them (the kinematic filter stays the model's
/// 2-state EKF; when the factors in use change, the estimate moves by it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleEstimate {
    /// Factors [gain, drag].
    pub mean: [f64; 2],
    /// Their covariance (row major 2x2).
    pub cov: [f64; 4],
    /// d(x, v)/d(factors) of the kinematic estimate (rows x, v; columns
    /// gain, drag).
    pub sens: [f64; 4],
}

/// The best a frame counts for in the factors' fit (`factor_fit`), m.
pub const SCALE_FRAME_STD_M: f64 = 3.0e-4;

/// Full states whose speed innovation the factors' uncertainty does not
/// explain (normalized innovation squared above this, three deviations)
/// count as if it were this far: their noise is widened until it does.
/// A glitch then moves the factors by a bounded step, and a capsule
/// farther off than its told uncertainty is still learned from every step
/// (rejecting them instead left a gain 19 % off unlearned at full gradient,
/// and the shots on the model's factors oscillated about the target:
/// docs/decisions.md).
pub const SCALE_UPDATE_NIS: f64 = 9.0;

/// Random walk of the factors, per second (variance): they are constants
/// of the capsule, but a slow drift (warming, a shell filling) is allowed.
pub const SCALE_DRIFT_PER_S: f64 = 1.0e-5;

impl ScaleEstimate {
    /// The model (factors 1) with standard deviations `gain_std`, `drag_std`.
    pub const fn new(gain_std: f64, drag_std: f64) -> ScaleEstimate {
        ScaleEstimate {
            mean: [1.0, 1.0],
            cov: [gain_std * gain_std, 0.0, 0.0, drag_std * drag_std],
            sens: [0.0; 4],
        }
    }

    /// Time update: the kinematic step had Jacobian `a` (d(x,v)/d(x0,v0))
    /// and `b` (d(x,v)/d(factors) at fixed start, columns gain and drag).
    pub fn predict(&mut self, a: [f64; 4], b: [f64; 4], duration_s: f64) {
        let p = self.sens;
        self.sens = [
            a[0] * p[0] + a[1] * p[2] + b[0],
            a[0] * p[1] + a[1] * p[3] + b[1],
            a[2] * p[0] + a[3] * p[2] + b[2],
            a[2] * p[1] + a[3] * p[3] + b[3],
        ];
        let q = SCALE_DRIFT_PER_S * duration_s.max(0.0);
        self.cov[0] += q;
        self.cov[3] += q;
    }

    /// Update from a full state (ideal sampling): `speed_innovation` is the
    /// speed measured minus the one predicted with factors `used` over one
    /// step whose sensitivity to the factors is `sens` (set by `predict`
    /// from zero), of variance `var` ((m/s)^2: what the disturbance adds
    /// over the step). The position adds nothing a step's speed does not.
    pub fn update_from_speed(&mut self, speed_innovation: f64, var: f64, used: [f64; 2]) {
        let h = [self.sens[2], self.sens[3]];
        self.regress(h, speed_innovation, var, used);
    }

    /// The scalar regression of `innovation` = h . (factors - used) + noise
    /// of variance `noise_var` (the factors' part added here).
    /// Innovations the factors' uncertainty does not explain
    /// (`SCALE_UPDATE_NIS`) count with a widened noise.
    fn regress(&mut self, h: [f64; 2], innovation: f64, noise_var: f64, used: [f64; 2]) {
        let p = self.cov;
        let ph = [p[0] * h[0] + p[1] * h[1], p[2] * h[0] + p[3] * h[1]];
        let explained = noise_var + h[0] * ph[0] + h[1] * ph[1];
        if !explained.is_finite() || explained <= 0.0 {
            return;
        }
        // The prediction used `used`, not the mean: what the mean predicts
        // on top of it is part of the expected innovation.
        let expected = h[0] * (self.mean[0] - used[0]) + h[1] * (self.mean[1] - used[1]);
        let r = innovation - expected;
        if !r.is_finite() {
            return;
        }
        // Farther than the factors' own uncertainty explains: a glitch, a
        // disturbance or a capsule farther off than told. Each such step
        // moves the factors by less the farther it is (k r = ph
        // SCALE_UPDATE_NIS / r), yet always towards it.
        let s = explained.max(r * r / SCALE_UPDATE_NIS);
        let k = [ph[0] / s, ph[1] / s];
        self.mean[0] += k[0] * r;
        self.mean[1] += k[1] * r;
        self.cov = [
            p[0] - k[0] * ph[0],
            p[1] - k[0] * ph[1],
            p[2] - k[1] * ph[0],
            p[3] - k[1] * ph[1],
        ];
        let off = 0.5 * (self.cov[1] + self.cov[2]);
        self.cov[1] = off;
        self.cov[2] = off;
    }

    /// The kinematic update with gains `k` (position, speed) took part of
    /// the innovation into the estimate: its sensitivity shrinks alike.
    pub fn after_kinematic_update(&mut self, k: [f64; 2]) {
        let p = self.sens;
        self.sens = [
            (1.0 - k[0]) * p[0],
            (1.0 - k[0]) * p[1],
            p[2] - k[1] * p[0],
            p[3] - k[1] * p[1],
        ];
    }

    /// Process noise (acceleration PSD, (m/s^2)^2 s) for the model's error
    /// (`model_error_accel`) read as white over `correlation_s`. Near rest
    /// both accelerations are small and the prediction is nearly exact.
    pub fn model_error_psd(
        &self,
        applied: [f64; 2],
        magnetic_m_per_s2: f64,
        drag_m_per_s2: f64,
        correlation_s: f64,
    ) -> f64 {
        let a = self.model_error_accel(applied, magnetic_m_per_s2, drag_m_per_s2);
        a * a * correlation_s
    }

    /// How far off, m/s^2, the acceleration predicted with factors
    /// `applied` may be at magnetic acceleration `magnetic_m_per_s2` and
    /// drag acceleration `drag_m_per_s2`: each factor may be off by its
    /// distance from the estimate plus one standard deviation.
    pub fn model_error_accel(
        &self,
        applied: [f64; 2],
        magnetic_m_per_s2: f64,
        drag_m_per_s2: f64,
    ) -> f64 {
        let err =
            |k: usize| libm::fabs(self.mean[k] - applied[k]) + libm::sqrt(self.cov[3 * k].max(0.0));
        err(0) * libm::fabs(magnetic_m_per_s2) + err(1) * libm::fabs(drag_m_per_s2)
    }

    /// Whether either factor is more than `sigmas` standard deviations
    /// from `factors`.
    pub fn differs_from(&self, factors: [f64; 2], sigmas: f64) -> bool {
        (0..2).any(|k| self.factor_differs(k, factors[k], sigmas))
    }

    /// The factors to use: each where it differs from the model by more
    /// than `sigmas` standard deviations, else the model's 1.
    pub fn significant(&self, sigmas: f64) -> [f64; 2] {
        let pick = |k: usize| {
            if self.factor_differs(k, 1.0, sigmas) {
                self.mean[k]
            } else {
                1.0
            }
        };
        [pick(0), pick(1)]
    }

    /// Whether factor `k` (0 gain, 1 drag) is more than `sigmas` standard
    /// deviations from `value`.
    fn factor_differs(&self, k: usize, value: f64, sigmas: f64) -> bool {
        libm::fabs(self.mean[k] - value) > sigmas * libm::sqrt(self.cov[3 * k].max(0.0))
    }
}

/// The capsules' common gain factor, pooled over their estimates
/// (weighted by the inverse of their variances), when it differs from the
/// model's 1 by more than `sigmas` of its own deviation and every two
/// capsules' gain estimates agree within `sigmas` deviations of their
/// difference; else None. A capsule's gain is its magnetization over its
/// mass: a material or a gradient calibration that is off moves every
/// capsule's gain alike, and the pooled estimate tells it before each
/// capsule's own does. Capsules whose gains the frames tell apart are not
/// pooled.
pub fn pooled_gain(scales: &[ScaleEstimate], sigmas: f64) -> Option<f64> {
    let variance = |s: &ScaleEstimate| s.cov[0].max(GAIN_VARIANCE_FLOOR);
    let agree = scales.iter().enumerate().all(|(i, a)| {
        scales[i + 1..].iter().all(|b| {
            libm::fabs(a.mean[0] - b.mean[0]) <= sigmas * libm::sqrt(variance(a) + variance(b))
        })
    });
    let weight: f64 = scales.iter().map(|s| 1.0 / variance(s)).sum();
    if !agree || scales.len() < 2 || weight.is_nan() || weight <= 0.0 {
        return None;
    }
    let mean = scales.iter().map(|s| s.mean[0] / variance(s)).sum::<f64>() / weight;
    (libm::fabs(mean - 1.0) > sigmas * libm::sqrt(1.0 / weight)).then_some(mean)
}

/// Least variance a gain estimate counts with in the pool (a deviation of
/// 1e-6: far below any the frames reach, it only keeps the weights finite).
const GAIN_VARIANCE_FLOOR: f64 = 1e-12;

#[cfg(test)]
mod tests {
    use super::*;

    fn gain_estimate(mean: f64, std: f64) -> ScaleEstimate {
        ScaleEstimate {
            mean: [mean, 1.0],
            cov: [std * std, 0.0, 0.0, 0.04],
            sens: [0.0; 4],
        }
    }

    /// Two capsules each 1.5 deviations below the model are together more
    /// than two below; one capsule, capsules that disagree, or a pool
    /// within two deviations of 1 give nothing.
    #[test]
    fn the_pooled_gain_tells_a_common_error_before_each_capsule_does() {
        let low = [gain_estimate(0.955, 0.03), gain_estimate(0.955, 0.03)];
        assert!(low.iter().all(|s| s.significant(2.0)[0] == 1.0));
        let pooled = pooled_gain(&low, 2.0).expect("significant together");
        assert!((pooled - 0.955).abs() < 1e-12);
        // The sharper estimate weighs more.
        let mixed = [gain_estimate(0.95, 0.01), gain_estimate(0.97, 0.03)];
        assert!((pooled_gain(&mixed, 2.0).unwrap() - 0.952).abs() < 1e-9);
        assert_eq!(pooled_gain(&low[..1], 2.0), None);
        let apart = [gain_estimate(1.0, 0.02), gain_estimate(1.2, 0.02)];
        assert_eq!(pooled_gain(&apart, 2.0), None);
        let near = [gain_estimate(0.98, 0.03), gain_estimate(0.99, 0.03)];
        assert_eq!(pooled_gain(&near, 2.0), None);
    }

    /// Deterministic pseudo-noise in [-1, 1] (no std, no rand).
    fn noise(k: u64) -> f64 {
        let mut z = k.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 27;
        (z % 2_000_001) as f64 / 1_000_000.0 - 1.0
    }

    /// A capsule coasting at 0.1 m/s on a known line, measured every 40 ms
    /// with +-0.2 mm noise: the speed, never measured, is recovered within
    /// 2 mm/s and the position error stays below the noise.
    #[test]
    fn recovers_speed_on_a_known_trajectory() {
        let (speed, r_m, dt) = (0.1, 2e-4, 0.04);
        let mut f = CapsuleFilter::new(0.0, r_m);
        let a = [1.0, dt, 0.0, 1.0];
        let mut worst_late = [0.0f64; 2];
        for k in 1..=100u64 {
            let next = [f.mean[0] + dt * f.mean[1], f.mean[1]];
            f.predict(next, a, dt, 1e-6, 0.0);
            let truth = speed * dt * k as f64;
            f.update(truth + r_m * noise(k), r_m * r_m);
            if k > 50 {
                worst_late[0] = worst_late[0].max((f.mean[0] - truth).abs());
                worst_late[1] = worst_late[1].max((f.mean[1] - speed).abs());
            }
        }
        assert!(worst_late[0] < r_m, "position error {}", worst_late[0]);
        assert!(worst_late[1] < 2e-3, "speed error {}", worst_late[1]);
        // The filter's own speed uncertainty is honest: the error lies
        // within 3 sigma.
        assert!(worst_late[1] < 3.0 * f.speed_std_m_per_s() + 1e-4);
    }

    /// The model's error as process noise: zero acceleration, zero noise
    /// (the floor is the caller's); it grows with the magnetic and drag
    /// accelerations and with the factors' uncertainty, and counts a factor
    /// estimated away from the one predicted with.
    #[test]
    fn model_error_psd_follows_the_accelerations_and_the_factors() {
        let s = ScaleEstimate::new(0.1, 0.2);
        assert_eq!(s.model_error_psd([1.0, 1.0], 0.0, 0.0, 0.02), 0.0);
        // 0.1 x 7 m/s^2 (gain x u_max) + 0.2 x 0.5 m/s^2 of drag, over 20 ms.
        let moving = s.model_error_psd([1.0, 1.0], 7.0, 0.5, 0.02);
        assert!((moving - 0.8f64.powi(2) * 0.02).abs() < 1e-12, "{moving}");
        let near_rest = s.model_error_psd([1.0, 1.0], 0.02, 3e-3, 0.02);
        assert!(near_rest < 1e-4 * moving, "{near_rest} vs {moving}");
        let mut learned = s;
        learned.cov = [1e-4, 0.0, 0.0, 1e-4];
        assert!(learned.model_error_psd([1.0, 1.0], 7.0, 0.5, 0.02) < 0.01 * moving);
        learned.mean = [1.0, 0.8];
        let off = learned.model_error_psd([1.0, 1.0], 0.0, 0.5, 0.02);
        assert!(
            (off - (0.21f64 * 0.5).powi(2) * 0.02).abs() < 1e-12,
            "{off}"
        );
    }

    /// Full states (ideal sampling) at full gradient: a capsule whose gain
    /// is 20 % off, twice its told deviation, is learned within 1 % in
    /// 2 s of steps, and a glitch of 1 m/s moves the factors by less than
    /// a fifth of their deviation.
    #[test]
    fn full_states_learn_a_capsule_beyond_its_told_deviation_and_bound_a_glitch() {
        // The default small capsule: dv/dgain = g u dt, dv/ddrag = -b v|v| dt.
        let (g, b, u, dt) = (173.0, 135.0, 0.04, 0.02);
        let step = |s: &mut ScaleEstimate, k: usize, truth: [f64; 2], glitch: f64| {
            let sign = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
            let v = 0.02 + 0.01 * (k % 7) as f64;
            let dv = [sign * g * u * dt, -b * v * v * dt];
            s.sens = [0.0; 4];
            s.predict([1.0, 0.0, 0.0, 1.0], [0.0, 0.0, dv[0], dv[1]], dt);
            let innovation = dv[0] * (truth[0] - 1.0) + dv[1] * (truth[1] - 1.0) + glitch;
            s.update_from_speed(innovation, 1e-8, [1.0, 1.0]);
        };
        let mut s = ScaleEstimate::new(0.1, 0.2);
        for k in 0..100 {
            step(&mut s, k, [0.8, 1.0], 0.0);
        }
        assert!((s.mean[0] - 0.8).abs() < 0.01, "gain {:?}", s.mean);
        assert!((s.mean[1] - 1.0).abs() < 0.05, "drag {:?}", s.mean);

        let mut s = ScaleEstimate::new(0.1, 0.2);
        step(&mut s, 0, [1.0, 1.0], 1.0);
        assert!((s.mean[0] - 1.0).abs() < 0.02, "a glitch: {:?}", s.mean);
        assert!(s.cov[0] > 0.9 * 0.01, "a glitch tells little: {:?}", s.cov);
    }

    /// Which capsules the switching rule treats as off the factors the
    /// loop was given: a factor more than the asked deviations from the
    /// told value (the model's 1 or a calibration), either way.
    #[test]
    fn differs_from_counts_deviations_from_the_told_factors() {
        let mut s = ScaleEstimate::new(0.1, 0.2);
        s.cov = [0.01 * 0.01, 0.0, 0.0, 0.02 * 0.02];
        s.mean = [1.0, 0.95];
        // The drag 2.5 deviations below the model's 1.
        assert!(s.differs_from([1.0, 1.0], 2.0));
        assert!(!s.differs_from([1.0, 1.0], 3.0));
        // Told 0.96: half a deviation off, not significant.
        assert!(!s.differs_from([1.0, 0.96], 2.0));
        s.mean = [1.025, 0.96];
        assert!(s.differs_from([1.0, 0.96], 2.0), "the gain, upwards");
    }

    /// A lost measurement: predict only, the uncertainty widens, the next
    /// measurement shrinks it again.
    #[test]
    fn a_lost_measurement_widens_then_recovers() {
        let mut f = CapsuleFilter::new(0.0, 2e-4);
        let a = [1.0, 0.04, 0.0, 1.0];
        for _ in 0..20 {
            f.predict(f.mean, a, 0.04, 1e-6, 0.0);
            f.update(0.0, 4e-8);
        }
        let settled = f.position_std_m();
        f.predict(f.mean, a, 0.04, 1e-6, 0.0);
        let lost = f.position_std_m();
        assert!(lost > settled);
        f.predict(f.mean, a, 0.04, 1e-6, 0.0);
        f.update(0.0, 4e-8);
        assert!(f.position_std_m() < lost);
    }
}
