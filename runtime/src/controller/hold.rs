//! The terminal hold: when the capsules enter and leave it, and its law
//! (the centre's PD about the station-keeping dither).

use super::braking::*;
use super::numeric::sq;
use super::settings::*;
use super::station::STATION_SPEED_BUDGET_M_PER_S;
use super::Controller;
use super::Mode;
use capsule_mpc_solver::*;

impl<S: PlanSolver<NX, K>, const NX: usize, const K: usize> Controller<S, NX, K> {
    /// Enters or leaves the terminal hold (with hysteresis); true inside.
    ///
    /// The hold is the local controller of a dual-mode MPC, so its region
    /// is where that law works: the capsules nearly at rest, their spread
    /// about the group's centre (drift included) within the position
    /// tolerance, and the centre itself within 2 mm, which the hold law
    /// (10 rad/s, critically damped) corrects at under 8 mm/s. Requiring every capsule within the
    /// tolerance of its own target instead refused arrivals such as
    /// (+0.98, -0.56) mm, which the hold centres to +-0.77 mm, and sent them
    /// back to the tables for a 0.4 s differential swing out of the band.
    pub(super) fn update_hold(&mut self, e: &[f64; NX]) -> bool {
        self.update_station_gains();
        let s = &self.settings;
        let slow = |speed: f64| (0..NX / 2).all(|i| libm::fabs(e[2 * i + 1]) <= speed);
        let centre_m = libm::fabs(capsule_centre_m(e));
        let was = self.sup.mode == Mode::Hold;
        let spread_m = half_spread_m(e, 0.0);
        let outside = (0..NX / 2).any(|i| libm::fabs(e[2 * i]) > s.hold_release_position_m);
        // The dither's authority with the learned drag factors, never more
        // than the model's (a larger one would admit arrivals on a guess).
        let authority = self
            .law
            .station
            .drag_authority(&self.est.applied_scales)
            .min(1.0);
        // Ideal sampling knows the state exactly and acts every sample:
        // there the centre law adds differential drag of its own (about
        // twice the dither's authority measured) and the test would refuse
        // arrivals the hold keeps, unless shots can take a refused arrival
        // on to rest (off the model the hold, skipping the test, kept
        // 0.85 mm/s of relative speed for 0.3 s and left the band:
        // docs/decisions.md).
        let shots = self.shots_on();
        // Tracked capsules' relative speed is known to about 1 mm/s (0.2 mm
        // frames tens of ms apart), the size of the speeds the test is
        // about: an arrival is admitted when a relative rate within
        // `HOLD_ENTRY_RATE_SIGMAS` of the estimate stops inside (refusing
        // on the estimate alone sent arrivals 0.3 mm/s apart back to the
        // tables for a 0.5 s swing out of the band: docs/decisions.md).
        // The confirmation while settling, on frames every sample, catches
        // the entries the true rate does not allow.
        let rate_std = if s.sampling == Sampling::Ideal {
            0.0
        } else {
            let mut speed_std = [0.0; NX];
            for (sd, f) in speed_std.iter_mut().zip(&self.est.filters) {
                *sd = f.speed_std_m_per_s();
            }
            HOLD_ENTRY_RATE_SIGMAS * self.law.station.rate_std(&speed_std[..NX / 2])
        };
        let can_stop = |spread_m: f64, rate_std: f64| {
            (s.sampling == Sampling::Ideal && !shots)
                || self.law.station.can_stop(
                    e,
                    S::DT_S,
                    self.hold_gap_s(),
                    spread_m,
                    authority,
                    rate_std,
                )
        };
        let settling = self.law.station.held_s() < HOLD_SETTLING_S;
        let holding = if was {
            slow(self.hold_speeds_m_per_s().1)
                && spread_m <= s.hold_release_position_m
                && !(NX / 2 <= HOLD_EARLY_EXIT_MAX_CAPSULES
                    && outside
                    && spread_m > HOLD_SPREAD_EXIT_M
                    && !settling)
                && centre_m <= HOLD_CENTRE_RELEASE_M
                // The frames after entry tell the relative speed better
                // than the one the entry was decided on.
                && (!settling || can_stop(self.hold_confirm_spread_m(), 0.0))
        } else {
            slow(self.hold_speeds_m_per_s().0)
                && half_spread_m(e, 0.0) <= s.hold_release_position_m
                && half_spread_m(e, HOLD_DRIFT_HORIZON_S) <= s.hold_enter_position_m
                && centre_m <= HOLD_CENTRE_ENTER_M
                && self.centre_stops_near(e)
                && can_stop(HOLD_STOP_SPREAD_M, rate_std)
        };
        let drifts = was && holding && self.hold_drifts_out();
        let walks = was
            && holding
            && !drifts
            && (self.hold_walks_out_third() || self.hold_walked_out_third());
        let holding = holding && !drifts && !walks;
        if !was && holding {
            self.law.station.start();
            self.law.hold_frames.clear();
            self.start_third_frames();
            // The end game's progress restarts when the hold ends.
            self.forget_stall();
        }
        if was && !holding {
            // Only the settling confirm's exits count against its budget.
            if settling && !walks && self.hold_confirm_spread_m() < HOLD_CONFIRM_SPREAD_M {
                self.sup.off_model_confirm_exits += 1;
            }
            // Re-plan from the tables, not from the plan before the hold.
            self.solver.reset();
            if walks {
                // Inside the band the refinement's plans barely move the
                // third combination: a shot does (searched from the plan's
                // length down).
                self.solver.want_shot(K);
            }
            self.law.planned_phase_samples = self.settings.max_actuation_samples;
            self.update_schedule();
        }
        holding
    }

    /// The hold law: critically damped PD on the group's centre (position)
    /// and mean speed (the one mode a single gradient controls near rest),
    /// about the station-keeping dither (see `station`), which holds the
    /// capsules' relative position through drag; the PD part is scaled by
    /// the duty of the schedule and the sum bounded by a fraction of u_max.
    pub(super) fn hold_gradient(&mut self, e: &[f64; NX]) -> f64 {
        let (_, mean_v) = capsule_means(e);
        let centre_m = capsule_centre_m(e);
        let mean_g = self.law.mean_gain;
        if mean_g.is_nan() || mean_g <= 0.0 {
            return 0.0;
        }
        let w = HOLD_NATURAL_FREQUENCY_RAD_PER_S;
        let gap_s = self.hold_gap_s();
        let (dither_m, dither_m_per_s) = self.law.station.common(S::DT_S, gap_s);
        let mut fastest_m_per_s: f64 = 0.0;
        for i in 0..NX / 2 {
            fastest_m_per_s = fastest_m_per_s.max(libm::fabs(e[2 * i + 1] - dither_m_per_s));
        }
        let speed_room_m_per_s =
            STATION_SPEED_BUDGET_M_PER_S - fastest_m_per_s - w * libm::fabs(centre_m - dither_m);
        let dither_accel =
            self.law
                .station
                .next_acceleration(e, S::DT_S, gap_s, speed_room_m_per_s);
        let centre_accel = -(w * w * (centre_m - dither_m) + 2.0 * w * (mean_v - dither_m_per_s))
            * (S::DT_S + gap_s)
            / S::DT_S;
        let bound = HOLD_MAX_GRADIENT_FRACTION * S::U_MAX_T_PER_M;
        ((centre_accel + dither_accel) / mean_g).clamp(-bound, bound)
    }

    /// How far apart the capsules may stop for a settling hold to go on,
    /// m: `HOLD_CONFIRM_SPREAD_M`, except under the scanner cycle off the
    /// model `HOLD_CONFIRM_SPREAD_OFF_MODEL_M` for the first
    /// `HOLD_CONFIRM_OFF_MODEL_EXITS` holds left so per target (factors
    /// learned from frames that were wrong would otherwise leave every
    /// hold), and only while shots are on: without them the hold would be
    /// left for the model's plans, not for a shot on the learned factors.
    fn hold_confirm_spread_m(&self) -> f64 {
        if self.settings.sampling != Sampling::Ideal
            && self.shots_on()
            && self.sup.off_model_confirm_exits < HOLD_CONFIRM_OFF_MODEL_EXITS
            && self.factors_differ_from_told()
            && self.learned_gains_agree()
        {
            HOLD_CONFIRM_SPREAD_OFF_MODEL_M
        } else {
            HOLD_CONFIRM_SPREAD_M
        }
    }

    /// Tells the station keeper the capsules' gains in use once their
    /// learned factors differ from one another by more than
    /// `STATION_GAIN_DIFFERENCE_SIGMAS` (see `StationKeeper::set_gains`);
    /// until then, or on the model, the drag direction as it is (the
    /// factors' noise would only turn it).
    fn update_station_gains(&mut self) {
        let m = NX / 2;
        let scales = &self.est.scales;
        let differ = (0..m).any(|i| {
            (i + 1..m).any(|j| {
                let d = scales[i].mean[0] - scales[j].mean[0];
                d * d > sq(STATION_GAIN_DIFFERENCE_SIGMAS) * (scales[i].cov[0] + scales[j].cov[0])
            })
        });
        if !differ {
            self.law.station.set_gains(None);
            return;
        }
        let mut gains = [0.0; NX];
        for (i, g) in gains.iter_mut().enumerate().take(m) {
            *g = capsule_gain_and_drag::<S, NX, K>(i).0 * self.est.applied_scales[i][0];
        }
        self.law.station.set_gains(Some(&gains[..m]));
    }

    /// Whether the capsules' learned gain factors agree within
    /// `HOLD_CONFIRM_GAIN_AGREEMENT`: the stopping test assumes the centre
    /// law's common gradient accelerates them alike.
    fn learned_gains_agree(&self) -> bool {
        let gains = self.est.applied_scales.iter().take(NX / 2).map(|f| f[0]);
        let (lo, hi) = gains.fold((f64::INFINITY, 0.0_f64), |(lo, hi), g| {
            (lo.min(g), hi.max(g))
        });
        hi <= lo * (1.0 + HOLD_CONFIRM_GAIN_AGREEMENT)
    }

    /// Whether the hold is entered at the explicit law's wider speeds: the
    /// law alone (`EXPLICIT_HOLD_ENTER_SPEED_M_PER_S`).
    fn explicit_hold_entry(&self) -> bool {
        self.settings.refine == Refine::None
    }

    /// Whether the centre law brings the group's centre to rest within
    /// `HOLD_CENTRE_RELEASE_M` (first order: the centre plus its speed over
    /// the law's natural frequency). At the band's entry speed (5 mm/s,
    /// 0.5 mm) from within `HOLD_CENTRE_ENTER_M` it always does; it
    /// decides at the explicit law's wider speeds.
    fn centre_stops_near(&self, e: &[f64; NX]) -> bool {
        let (_, mean_v) = capsule_means(e);
        let stop_m = capsule_centre_m(e) + mean_v / HOLD_NATURAL_FREQUENCY_RAD_PER_S;
        libm::fabs(stop_m) <= HOLD_CENTRE_RELEASE_M
    }

    /// The speeds below which the hold is entered and kept, m/s.
    fn hold_speeds_m_per_s(&self) -> (f64, f64) {
        let s = &self.settings;
        if self.explicit_hold_entry() {
            (
                s.hold_enter_speed_m_per_s
                    .max(EXPLICIT_HOLD_ENTER_SPEED_M_PER_S),
                s.hold_release_speed_m_per_s
                    .max(EXPLICIT_HOLD_RELEASE_SPEED_M_PER_S),
            )
        } else {
            (s.hold_enter_speed_m_per_s, s.hold_release_speed_m_per_s)
        }
    }

    /// The zero-gradient gap after each hold sample, s.
    pub(super) fn hold_gap_s(&self) -> f64 {
        match self.settings.sampling {
            Sampling::Ideal => 0.0,
            Sampling::Constant | Sampling::Variable => self.est.gap_s,
        }
    }

    /// Logs accepted frame `z` (absolute positions, m) while holding.
    pub(super) fn log_hold_frame(&mut self, z: &[f64]) {
        let mut p = [0.0; NX];
        for (i, pi) in p.iter_mut().enumerate().take(NX / 2) {
            *pi = z[i] - self.sup.target[2 * i];
        }
        let xi = self.law.station.along_direction(&p[..NX / 2]);
        let t_s = self.law.station.held_s();
        self.law.hold_frames.push(t_s, xi);
        self.log_third_frame(t_s, &p[..NX / 2]);
    }

    /// Whether the hold is left for the relative drift its frames show:
    /// judged once per hold, after `HOLD_DRIFT_FIT_S` in it, at most
    /// `HOLD_DRIFT_EXITS` times per target, for two capsules under the
    /// scanner cycle (ideal sampling knows the state; three capsules' third
    /// combination is not the drag direction's), once the learned factors
    /// differ from the told ones (on the model arrivals keep less relative
    /// speed, and a constant bias's drift, which a manoeuvre does not
    /// remove, set off the exit) and while the learned gains agree (else
    /// the centre law itself moves the capsules apart or together, which
    /// the stopping test does not count). Left when no rate within
    /// `HOLD_DRIFT_RATE_SIGMAS` of the line's stops the capsules within
    /// `HOLD_DRIFT_SPREAD_M`. A hold kept only on that allowance (the
    /// line's own rate would not stop inside) is judged once more at
    /// `HOLD_DRIFT_RECHECK_S`, on the frames since: 0.8 s of frames know
    /// the rate to about 0.3 mm/s, and a 0.7 mm/s drift kept so stopped
    /// at the band's edge (docs/decisions.md).
    pub(super) fn hold_drifts_out(&mut self) -> bool {
        if self.settings.sampling == Sampling::Ideal
            || NX / 2 > HOLD_EARLY_EXIT_MAX_CAPSULES
            || self.sup.drift_exits >= HOLD_DRIFT_EXITS
            || self.law.station.held_s() < HOLD_DRIFT_FIT_S
            || (self.law.hold_frames.judged
                && !(self.law.hold_frames.recheck
                    && self.law.station.held_s() >= HOLD_DRIFT_RECHECK_S))
            || !self.factors_differ_from_told()
            || !self.learned_gains_agree()
        {
            return false;
        }
        let first_look = !self.law.hold_frames.judged;
        self.law.hold_frames.judged = true;
        self.law.hold_frames.recheck = false;
        let station = &self.law.station;
        let xi_std = self.settings.position_noise_m * station.direction_norm();
        let Some(line) = self.law.hold_frames.line(xi_std) else {
            return false;
        };
        // The learned factors' authority, above the model's too (the entry
        // test caps it there): leaving a hold that would have settled costs
        // more than a second of drift.
        let authority = station.drag_authority(&self.est.applied_scales);
        let gap_s = self.hold_gap_s();
        let stops_within = |rate_std: f64| {
            station.motion_stops_within(
                line.coordinate,
                line.rate,
                S::DT_S,
                gap_s,
                HOLD_DRIFT_SPREAD_M,
                authority,
                rate_std,
            )
        };
        let stops = stops_within(HOLD_DRIFT_RATE_SIGMAS * line.rate_std);
        if stops && first_look {
            // Kept only on the rate's uncertainty: looked at again later.
            self.law.hold_frames.recheck = !stops_within(0.0);
        }
        if !stops {
            self.sup.drift_exits += 1;
        }
        !stops
    }
}
