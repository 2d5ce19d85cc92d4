//! Measurements and time: time-stamped cycles, the innovation gate,
//! glitches and re-acquisition, and the estimator's prediction through
//! the real gaps.

use super::checks::*;
use super::fusion::*;
use super::numeric::*;
use super::settings::*;
use super::status::*;
use super::{Controller, Mode};
use crate::estimator::*;
use crate::factor_fit::*;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// One scanner cycle on the host's clock. `measured_positions_m` (None:
    /// lost) were measured at `t_measured_s`, at the start of the tracking
    /// phase that just ended; the actuation starts at
    /// `t_actuation_start_s`. The estimate is predicted at zero gradient
    /// from the end of the previous actuation phase to the measurement and
    /// on to the actuation start, and the plans model the gap between
    /// actuation phases these time stamps show (smoothed over cycles,
    /// `GAP_SMOOTHING`), so tracking phases of any length, fixed or
    /// varying, are handled.
    ///
    /// Refused, changing nothing: with `BadTime` naming the argument, a
    /// measurement before the previous actuation ended (more than
    /// `TIME_TOLERANCE_S`: time going backwards) or an actuation start
    /// before the measurement; with `GapBeyondProven`, more than
    /// [`MAX_GAP_S`](Self::MAX_GAP_S) (+ `TIME_TOLERANCE_S`) from the
    /// previous actuation end (or from the measurement, on the first timed
    /// cycle) to the actuation start. After a longer pause, `reset`.
    pub fn cycle_at(
        &mut self,
        measured_positions_m: Option<&[f64]>,
        t_measured_s: f64,
        t_actuation_start_s: f64,
    ) -> Result<CycleOutput<K>, RuntimeError> {
        check_frame_length::<NX>(measured_positions_m)?;
        let (before_s, wait_s, gap_s) = self.check_times(t_measured_s, t_actuation_start_s)?;
        let first = self.est.actuation_end_s.is_none();
        let out = self.step(measured_positions_m, before_s, wait_s, (gap_s, first));
        self.est.actuation_end_s =
            Some(t_actuation_start_s + out.actuation_samples as f64 * S::DT_S);
        Ok(out)
    }

    /// End of the last actuation phase on the host's clock (the instant
    /// `estimate()` describes after a `cycle_at`), s.
    pub fn actuation_end_s(&self) -> Option<f64> {
        self.est.actuation_end_s
    }

    /// The longest tracking + delay per cycle this controller accepts, s:
    /// the proven range ([`max_proven_gap_s`] of the generated gap).
    pub const MAX_GAP_S: f64 = max_proven_gap_s(S::TRACKING_TIME_S + S::EXTRA_DELAY_S, NX / 2);

    /// Checks a measurement time against the end of the previous actuation
    /// phase: `BadTime("t_measured_s")` when it goes backwards,
    /// `GapBeyondProven` beyond [`MAX_GAP_S`](Self::MAX_GAP_S), otherwise
    /// the zero-gradient time from the previous actuation end to it, s.
    pub fn check_measurement_time(&self, t_measured_s: f64) -> Result<f64, RuntimeError> {
        if !t_measured_s.is_finite() {
            return Err(RuntimeError::NonFinite("t_measured_s"));
        }
        match self.est.actuation_end_s {
            None => Ok(0.0),
            Some(end_s) => {
                if t_measured_s < end_s - TIME_TOLERANCE_S {
                    return Err(RuntimeError::BadTime("t_measured_s"));
                }
                self.check_gap(t_measured_s - end_s)?;
                Ok((t_measured_s - end_s).max(0.0))
            }
        }
    }

    /// (previous actuation end -> measurement, measurement -> actuation
    /// start, previous actuation end -> actuation start), s, or the error.
    pub(super) fn check_times(
        &self,
        t_measured_s: f64,
        t_actuation_start_s: f64,
    ) -> Result<(f64, f64, f64), RuntimeError> {
        let before_s = self.check_measurement_time(t_measured_s)?;
        if !t_actuation_start_s.is_finite() {
            return Err(RuntimeError::NonFinite("t_actuation_start_s"));
        }
        let wait_s = t_actuation_start_s - t_measured_s;
        if wait_s < 0.0 {
            return Err(RuntimeError::BadTime("t_actuation_start_s"));
        }
        self.check_gap(before_s + wait_s)?;
        Ok((before_s, wait_s, before_s + wait_s))
    }

    /// `GapBeyondProven` when `gap_s` exceeds the proven range.
    fn check_gap(&self, gap_s: f64) -> Result<(), RuntimeError> {
        let max_s = Self::MAX_GAP_S;
        if gap_s > max_s + TIME_TOLERANCE_S {
            return Err(RuntimeError::GapBeyondProven { gap_s, max_s });
        }
        Ok(())
    }

    /// The cycle after argument checks: predict `before_s` at zero gradient
    /// to the measurement, fuse it, predict `wait_s` to the actuation
    /// start, fold `gap.0` (the gap between the last actuation phase and
    /// this one; `gap.1`: the first of a time base) into the gap the plans
    /// model, plan.
    pub(super) fn step(
        &mut self,
        measured_positions_m: Option<&[f64]>,
        before_s: f64,
        wait_s: f64,
        gap: (f64, bool),
    ) -> CycleOutput<K> {
        self.est.at_start = false;
        if before_s > 0.0 {
            self.predict_filters(0.0, before_s);
        }
        let status = match measured_positions_m {
            None => RuntimeStatus::MeasurementLost,
            Some(z) => self.fuse(z),
        };
        self.note_gap(gap.0, gap.1);
        // Tracking + delay pass with u = 0 before the next actuation.
        let measured = self.estimate();
        self.predict_filters(0.0, wait_s);
        let x_start = if self.settings.compensate_delay {
            self.estimate()
        } else {
            measured
        };
        let n_max = match self.settings.sampling {
            Sampling::Ideal | Sampling::Constant => 1,
            Sampling::Variable => self.settings.max_actuation_samples,
        };
        let mut out = self.plan_from(&x_start, status, n_max);
        if status == RuntimeStatus::Reacquired {
            // The host must learn that the estimate jumped, even when the
            // plan is the fallback or there is no target.
            out.status = RuntimeStatus::Reacquired;
        }
        // The estimator follows the actuation that will be played.
        for k in 0..out.actuation_samples {
            self.predict_filters(out.gradients_t_per_m[k], S::DT_S);
        }
        out
    }

    /// Folds a measured gap between actuation phases into the running
    /// estimate the plans model (`GAP_SMOOTHING`; the first cycle of a time
    /// base takes its gap as is).
    pub(super) fn note_gap(&mut self, gap_s: f64, first: bool) {
        let next = if first {
            gap_s
        } else {
            self.est.gap_s + GAP_SMOOTHING * (gap_s - self.est.gap_s)
        };
        if next != self.est.gap_s {
            self.est.gap_s = next;
            self.update_schedule();
        }
    }

    /// Fuses frame `z` (length checked): accepted, rejected as invalid,
    /// gated out (counted towards re-acquisition), or re-acquired.
    pub(super) fn fuse(&mut self, z: &[f64]) -> RuntimeStatus {
        let r = sq(self.settings.position_noise_m.max(1e-6));
        let mut class = self.classify_measurement(z);
        if class == Measurement::Accepted && self.continues_candidate(z, r) {
            // The estimate's gate has widened while it predicted through
            // the gated-out frames; a frame that carries on their sequence
            // belongs to it, not to the estimate.
            class = Measurement::GatedOut;
        }
        match class {
            Measurement::Invalid => RuntimeStatus::MeasurementRejected,
            Measurement::Accepted => {
                self.settle_model_drift();
                self.est.gated_rejections = 0;
                self.est.candidate_frames = 0;
                self.est.confirmed_frames = self.est.confirmed_frames.saturating_add(1);
                let m = NX / 2;
                if !self.est.has_replaced && nis(&self.est.filters[..m], z, r) > REPLACED_TRACK_NIS
                {
                    // A frame that pulls the estimate far (behind a gate
                    // widened by long open-loop phases) may be the first of
                    // a glitch: keep the estimate it pulls away from.
                    self.est.replaced = self.est.filters;
                    self.est.has_replaced = true;
                }
                self.shrink_factor_sensitivity(r);
                update_filters(&mut self.est.filters[..m], z, r);
                if self.sup.mode == Mode::Hold {
                    self.log_hold_frame(z);
                }
                self.fit_factors(z, r);
                self.refresh_applied_scales();
                RuntimeStatus::Ok
            }
            Measurement::GatedOut => {
                if self.est.has_replaced
                    && nis(&self.est.replaced[..NX / 2], z, r) <= REPLACED_TRACK_NIS
                {
                    // The frames are back on the track the last
                    // re-acquisition replaced: that one was a glitch.
                    self.est.filters = self.est.replaced;
                    self.est.has_replaced = false;
                    update_filters(&mut self.est.filters[..NX / 2], z, r);
                    self.after_reacquisition();
                    self.est.confirmed_frames = 1;
                    return RuntimeStatus::Reacquired;
                }
                self.est.gated_rejections = self.est.gated_rejections.saturating_add(1);
                self.track_candidate(z, r);
                let after = self.settings.reacquire_after_rejections;
                let needed = if self.est.confirmed_frames < ESTABLISHED_AFTER_FRAMES {
                    after
                } else if self.est.candidate_continues_track || self.candidate_speed_departs() {
                    after.min(MODEL_ERROR_FOLLOW_FRAMES)
                } else {
                    after.max(self.settings.glitch_frames.saturating_add(1))
                };
                if after != 0 && self.est.candidate_frames >= needed {
                    self.est.replaced = self.est.filters;
                    self.est.has_replaced = true;
                    self.est.filters = self.est.candidate;
                    self.after_reacquisition();
                    RuntimeStatus::Reacquired
                } else {
                    RuntimeStatus::MeasurementRejected
                }
            }
        }
    }

    /// Whether frame `z` carries on the run of gated-out frames: the
    /// candidate has seen at least two (so it knows their speed) and `z`
    /// fits it better than the estimate.
    pub(super) fn continues_candidate(&self, z: &[f64], r: f64) -> bool {
        let m = NX / 2;
        self.est.candidate_frames >= 2
            && within_gate(&self.est.candidate[..m], z, r)
            && nis(&self.est.candidate[..m], z, r) < nis(&self.est.filters[..m], z, r)
    }

    /// Whether the run of gated-out frames is a capsule farther off the
    /// model than told: it started near the estimate
    /// (`candidate_starts_near`), and after `MODEL_ERROR_FOLLOW_FRAMES`
    /// some capsule's speed in it departs from the estimate's by more than
    /// `MODEL_ERROR_SPEED_SIGMAS`. The drift bound at its first frame
    /// counts the told uncertainty only; a capsule 15-20 % off arrives
    /// beyond it after a long phase at full gradient, and the estimate,
    /// holding a target the capsule has left, rejected 20 true frames.
    pub(super) fn candidate_speed_departs(&self) -> bool {
        if !self.est.candidate_starts_near || self.est.candidate_frames < MODEL_ERROR_FOLLOW_FRAMES
        {
            return false;
        }
        self.est.candidate[..NX / 2]
            .iter()
            .zip(&self.est.filters[..NX / 2])
            .any(|(c, f)| {
                let dv = c.mean[1] - f.mean[1];
                dv * dv > sq(MODEL_ERROR_SPEED_SIGMAS) * (c.cov[3] + f.cov[3])
            })
    }

    /// Feeds a gated-out frame to the re-acquisition candidate: fused when
    /// it agrees with the frames before it, else the candidate restarts at
    /// it (position at the frame, speed zero with a wide uncertainty, so
    /// that the next frame sets the speed).
    pub(super) fn track_candidate(&mut self, z: &[f64], r: f64) {
        let m = NX / 2;
        if self.est.candidate_frames > 0 && within_gate(&self.est.candidate[..m], z, r) {
            update_filters(&mut self.est.candidate[..m], z, r);
            self.est.candidate_frames += 1;
        } else {
            // A capsule off the model leaves the prediction smoothly: its
            // first gated-out frame is still within what the model's
            // uncertainty allows since the last accepted frame (the drift
            // bound, uncapped). A glitch jumps beyond it.
            self.est.candidate_continues_track = within_widened_gate(
                &self.est.filters[..m],
                z,
                r,
                &self.est.model_drift[..m],
                f64::INFINITY,
            );
            self.est.candidate_starts_near = self.est.filters[..m]
                .iter()
                .zip(z)
                .all(|(f, &p)| libm::fabs(p - f.mean[0]) <= MODEL_DRIFT_MAX_M);
            let std = self.settings.position_noise_m.max(1e-6);
            for (c, &p) in self.est.candidate.iter_mut().zip(z) {
                *c = CapsuleFilter::with_speed_std(p, std, REACQUIRE_SPEED_STD_M_PER_S);
            }
            self.est.candidate_frames = 1;
        }
    }

    /// The estimate jumped (re-acquired): forget the counters and the plan.
    pub(super) fn after_reacquisition(&mut self) {
        self.restart_factor_window();
        self.est.model_drift = [[0.0; 2]; NX];
        self.est.gated_rejections = 0;
        self.est.candidate_frames = 0;
        self.est.confirmed_frames = 0;
        // A leg chosen from the old estimate means nothing now.
        if self.sup.has_target {
            let x = self.estimate();
            self.replan_legs(&x);
        }
        self.restart_plan();
    }

    /// How far the capsules may have drifted from the prediction because
    /// the model is not the plant: the capsule's gain and drag are known to
    /// 10-20 % at best (`model_gain_uncertainty`, `model_drag_uncertainty`),
    /// so the predicted acceleration may be off by that fraction of its
    /// magnetic and drag parts, coherently, over the whole time since the
    /// last accepted frame. The gate widens by it (the filter itself is
    /// not told: its estimate on the model stays as sharp as before), so
    /// that true frames of a capsule off the model are not taken for a
    /// glitch after a long actuation phase.
    pub(super) fn accumulate_model_drift(&mut self, u: f64, duration_s: f64) {
        let (gain_err, drag_err) = (
            self.settings.model_gain_uncertainty,
            self.settings.model_drag_uncertainty,
        );
        let t = duration_s;
        for i in 0..NX / 2 {
            let v = self.est.filters[i].mean[1];
            let accel_err = gain_err * libm::fabs(S::capsule_gain(i) * u)
                + drag_err * libm::fabs(S::capsule_drag(i, v));
            let d = &mut self.est.model_drift[i];
            // Not capped here: the gate caps it (`MODEL_DRIFT_MAX_M`), the
            // continuity test of a run of gated-out frames does not.
            d[0] += d[1] * t + 0.5 * accel_err * t * t;
            d[1] += accel_err * t;
        }
    }

    /// The kinematic update of an accepted frame takes part of the
    /// innovation into the estimate: the factors' sensitivity (which moves
    /// the estimate when the factors in use change) shrinks alike.
    pub(super) fn shrink_factor_sensitivity(&mut self, r: f64) {
        for i in 0..NX / 2 {
            let f = self.est.filters[i];
            let s = f.cov[0] + r;
            self.est.scales[i].after_kinematic_update([f.cov[0] / s, f.cov[2] / s]);
        }
    }

    /// Starts a new factor window at the current estimate, the factors'
    /// estimate its prior.
    pub(super) fn restart_factor_window(&mut self) {
        self.est.window.clear();
        let gamma = self.settings.disturbance_bound;
        // The steady disturbance is at most the disturbance bound, and a
        // position rate at most what it adds in FIT_RATE_PRIOR_TIME_S.
        let bias_var = [sq(gamma), sq(gamma * FIT_RATE_PRIOR_TIME_S)];
        for i in 0..NX / 2 {
            let (f, s) = (self.est.filters[i], self.est.scales[i]);
            let fitted = self.est.window.fitted[i];
            let prior = FitPrior {
                state: f.mean,
                state_cov: f.cov,
                factors: s.mean,
                factors_cov: s.cov,
                // The steady disturbance carries over.
                bias: [fitted[4], fitted[5]],
                bias_var,
            };
            self.est.window.start_capsule(i, prior);
        }
    }

    /// Adds accepted frame `z` to the window and refits every capsule's
    /// factors to the window's frames; the fit becomes the factors'
    /// estimate. A full window starts again from the current estimate.
    pub(super) fn fit_factors(&mut self, z: &[f64], r: f64) {
        if !self.est.window.record_frame(z) {
            // Not reached: a window is restarted as soon as it is full.
            self.restart_factor_window();
            return;
        }
        let gamma = self.settings.disturbance_bound;
        let noise = FitNoise {
            // Each frame counts as if measured to SCALE_FRAME_STD_M at
            // best: a few frames of a tracking glitch cannot set the
            // factors.
            r_m2: r + SCALE_FRAME_STD_M * SCALE_FRAME_STD_M,
            accel_psd: gamma * gamma * S::DT_S,
        };
        for i in 0..NX / 2 {
            self.est.window.fit_capsule(
                i,
                &ModelStep::<S, NX, K>::new(),
                noise,
                [MODEL_FACTOR_MIN, MODEL_FACTOR_MAX],
            );
            let p = self.est.window.fitted[i];
            // The fit holds the factors constant over the window; their
            // allowed drift (SCALE_DRIFT_PER_S) over it adds on top.
            let drift = SCALE_DRIFT_PER_S * self.est.window.span_s();
            let mut cov = self.est.window.fitted_cov[i];
            cov[0] += drift;
            cov[3] += drift;
            self.est.scales[i].mean = [p[2], p[3]];
            self.est.scales[i].cov = cov;
        }
        // The next frame goes into a new window (this one's frames are in
        // the estimate it starts from).
        if self.est.window.is_full() {
            self.restart_factor_window();
        }
    }

    /// Ideal sampling: the factors from the full state `x`, against the
    /// model's step at gradient `u` from the previous full state (still
    /// the filters' means). Each step's speed change regresses them; the
    /// disturbance over the step is the noise.
    pub(super) fn learn_from_full_state(&mut self, x: &[f64; NX], u: f64) {
        let gamma = self.settings.disturbance_bound;
        let var = sq(FULL_STATE_SPEED_STD_M_PER_S) + sq(gamma * S::DT_S);
        for i in 0..NX / 2 {
            let used = self.est.applied_scales[i];
            let (next, a, b) =
                factor_step::<S, NX, K>(i, self.est.filters[i].mean, u, S::DT_S, used);
            let scale = &mut self.est.scales[i];
            // The previous state was exact: the sensitivity is this step's.
            scale.sens = [0.0; 4];
            scale.predict(a, b, S::DT_S);
            scale.update_from_speed(x[2 * i + 1] - next[1], var, used);
        }
        self.refresh_applied_scales();
    }

    /// Takes up the factors that differ significantly from the model
    /// (`SCALE_SIGNIFICANCE` standard deviations): the estimate is moved
    /// by what the change of factors implies, and the refinement rolls
    /// out on them. Under the scanner cycle a capsule whose own gain is not
    /// yet significant takes the capsules' pooled gain where that is
    /// (`estimator::pooled_gain`); ideal sampling tells each capsule's
    /// gain from full states within a few samples.
    pub(super) fn refresh_applied_scales(&mut self) {
        let mut changed = false;
        let pooled = if self.settings.sampling == Sampling::Ideal {
            None
        } else {
            pooled_gain(&self.est.scales[..NX / 2], SCALE_SIGNIFICANCE)
        };
        for i in 0..NX / 2 {
            let mut new = self.est.scales[i].significant(SCALE_SIGNIFICANCE);
            if let Some(gain) = pooled.filter(|_| new[0] == 1.0) {
                new[0] = gain;
            }
            let old = self.est.applied_scales[i];
            if new != old {
                let sens = self.est.scales[i].sens;
                let d = [new[0] - old[0], new[1] - old[1]];
                self.est.filters[i].mean[0] += sens[0] * d[0] + sens[1] * d[1];
                self.est.filters[i].mean[1] += sens[2] * d[0] + sens[3] * d[1];
                self.est.applied_scales[i] = new;
                changed = true;
            }
        }
        if changed {
            self.solver
                .set_model_scales(&self.est.applied_scales[..NX / 2]);
        }
    }

    /// An accepted frame corrects the position drift at once and the speed
    /// drift over a few frames (`MODEL_DRIFT_SPEED_KEPT`).
    pub(super) fn settle_model_drift(&mut self) {
        for d in self.est.model_drift[..NX / 2].iter_mut() {
            d[0] = 0.0;
            d[1] *= MODEL_DRIFT_SPEED_KEPT;
        }
    }

    /// Invalid when any position is non-finite or beyond
    /// `MAX_ABS_POSITION_M` (bad data, says nothing about the estimate);
    /// else gated out when any innovation exceeds the gate.
    pub(super) fn classify_measurement(&self, z: &[f64]) -> Measurement {
        if z.iter()
            .any(|zi| !zi.is_finite() || libm::fabs(*zi) > MAX_ABS_POSITION_M)
        {
            return Measurement::Invalid;
        }
        let r = sq(self.settings.position_noise_m.max(1e-6));
        if within_widened_gate(
            &self.est.filters[..NX / 2],
            z,
            r,
            &self.est.model_drift[..NX / 2],
            MODEL_DRIFT_MAX_M,
        ) {
            Measurement::Accepted
        } else {
            Measurement::GatedOut
        }
    }

    /// Predicts the estimate (and the re-acquisition candidate and the
    /// replaced track, while they exist) over `duration_s` at gradient `u`.
    pub(super) fn predict_filters(&mut self, u: f64, duration_s: f64) {
        let gamma = self.settings.disturbance_bound;
        // A disturbance of bound gamma, read as white noise over one sample.
        let disturbance_psd = gamma * gamma * S::DT_S;
        // The re-acquisition candidate and the replaced track know nothing
        // of the factors: the most the model's error adds.
        let accel_psd = disturbance_psd.max(MODEL_ERROR_MAX_ACCEL_PSD);
        let vel_psd = disturbance_psd;
        let applied = self.est.applied_scales;
        let predict = |filters: &mut [CapsuleFilter]| {
            for (i, f) in filters.iter_mut().enumerate() {
                let (next, a) = S::capsule_transition_scaled(i, f.mean, u, duration_s, applied[i]);
                f.predict(next, a, duration_s, accel_psd, vel_psd);
            }
        };
        let m = NX / 2;
        if !self.est.window.record_segment(u, duration_s) {
            self.restart_factor_window();
            self.est.window.record_segment(u, duration_s);
        }
        self.accumulate_model_drift(u, duration_s);
        for (i, &s) in applied.iter().enumerate().take(m) {
            let (_, a, b) = factor_step::<S, NX, K>(i, self.est.filters[i].mean, u, duration_s, s);
            self.est.scales[i].predict(a, b, duration_s);
        }
        for (i, &scale) in applied.iter().enumerate().take(m) {
            let f = &mut self.est.filters[i];
            let (next, a) = S::capsule_transition_scaled(i, f.mean, u, duration_s, scale);
            let psd = self.est.scales[i].model_error_psd(
                scale,
                S::capsule_gain(i) * u,
                S::capsule_drag(i, f.mean[1]),
                S::DT_S,
            );
            let psd = psd
                .clamp(REST_ACCEL_PSD, MODEL_ERROR_MAX_ACCEL_PSD)
                .max(disturbance_psd);
            f.predict(next, a, duration_s, psd, vel_psd);
        }
        if self.est.candidate_frames > 0 {
            predict(&mut self.est.candidate[..m]);
        }
        if self.est.has_replaced {
            predict(&mut self.est.replaced[..m]);
            self.est.has_replaced = self.est.replaced[..m]
                .iter()
                .all(|f| f.position_std_m() <= REPLACED_TRACK_MAX_STD_M);
        }
    }
}
