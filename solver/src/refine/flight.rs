//! A minimum-time shot in flight: looking for one (`acquire_shot`),
//! re-solving it every cycle from the estimate (`reshoot`, falling back to
//! the hold's entry tolerance), moving it to a new schedule
//! (`reschedule_shot`), and carrying a chained move through its waypoints
//! (`shoot_through_chain`).

use super::*;

impl<
        S: Spec<M, NX>,
        const M: usize,
        const NX: usize,
        const N: usize,
        const K: usize,
        E: QpEngine<N>,
    > Solver<S, M, NX, N, K, E>
{
    /// Moves a shot in flight to a new schedule: the plan, stretched or
    /// compressed to arrive when it did under the old one, is re-solved
    /// from `e` under the new one (the length that arrives then, one
    /// shorter, or up to two longer). True when a shot converges; then the
    /// schedule is the new one. False (no shot, or none converges) leaves
    /// the plan, the shot and the schedule as they were.
    pub fn reschedule_shot(
        &mut self,
        e: &[f64; NX],
        samples_per_phase: usize,
        coast_s: f64,
    ) -> bool {
        let n_old = self.shot_samples;
        if !self.shooting || n_old == 0 {
            return false;
        }
        let old = self.schedule;
        let new = Self::schedule_for(samples_per_phase, coast_s);
        let kept_plan = self.plan;
        self.schedule = new;
        self.shot_samples = n_old;
        // The same samples without the coasts first (an earlier arrival),
        // then the plan stretched to arrive when it did.
        if self.reshoot(e).is_some() {
            return true;
        }
        let arrival_s = old.duration_s(n_old, S::DT_S);
        let mut n = 1;
        while n < K && new.duration_s(n, S::DT_S) < arrival_s - 1e-9 {
            n += 1;
        }
        resample(&kept_plan, n_old, &mut self.plan, n);
        self.shot_samples = n;
        if self.reshoot(e).is_some() {
            return true;
        }
        self.schedule = old;
        self.plan = kept_plan;
        self.shot_samples = n_old;
        false
    }

    /// The current shot re-solved from `e` at its remaining length (then
    /// one sample shorter, or up to two longer): None when none converges.
    pub(super) fn reshoot(&mut self, e: &[f64; NX]) -> Option<SolveReport> {
        let n = self.shot_samples;
        let mut p = self.plan;
        let found =
            if self
                .shooter
                .shoot::<S>(e, &mut p, n, SHOT_ITERATIONS, &self.schedule, &self.scales)
            {
                self.candidate = p;
                if n > 1
                    && self.shooter.shoot::<S>(
                        e,
                        &mut self.candidate,
                        n - 1,
                        SHOT_ITERATIONS,
                        &self.schedule,
                        &self.scales,
                    )
                {
                    p = self.candidate;
                    // It still shortens: look further down while most of
                    // the cycle's budget is left (the shot may have been
                    // acquired from a longer local solution).
                    if self.shooter.budget_left() * 2 >= Shooter::<M, NX, K>::BUDGET_SAMPLES {
                        self.shorten_shot(
                            e,
                            &mut p,
                            n - 1,
                            (n - 1) / 2,
                            SHOT_RESHOOT_SHORTER_LENGTHS,
                        )
                    } else {
                        n - 1
                    }
                } else {
                    n
                }
            } else {
                // Longer, then aimed at the hold's entry; either leaves its
                // plan in `candidate`.
                let mut longer = self.first_converging_length(e, n + 1, n + 2);
                if longer == 0 {
                    longer = self.reshoot_into_hold(e, n);
                }
                if longer > 0 {
                    p = self.candidate;
                }
                longer
            };
        if found == 0 {
            self.shot_samples = 0;
            return None;
        }
        self.plan = p;
        self.shot_samples = found;
        self.explicit_ready = false;
        self.tier = Tier::Refined;
        Some(SolveReport {
            status: SolveStatus::Refined,
            cost: rollout_cost_below_scaled::<S, M, NX, K>(
                e,
                &self.plan,
                &self.schedule,
                &self.scales,
                f64::INFINITY,
            ),
            took_table_plan: false,
            qp_iterations: 0,
            max_qp_iterations: 0,
            tier: Tier::Refined,
        })
    }

    /// A shot in flight that no longer converges to its tolerance (the
    /// estimate moved near its end, where too few samples are left to
    /// correct the capsules' spread) aimed at the hold's entry instead:
    /// every capsule within `SHOT_HOLD_POSITION_TOLERANCE_M`, at the same
    /// speed tolerance, at the remaining length or up to two longer. The
    /// hold takes the rest; a new manoeuvre from here would leave the band
    /// for a second separation swing. Returns the length found (0: none),
    /// its plan in `candidate`.
    pub(super) fn reshoot_into_hold(&mut self, e: &[f64; NX], n: usize) -> usize {
        let tight = self.shooter.position_tolerance_m();
        if tight >= SHOT_HOLD_POSITION_TOLERANCE_M {
            return 0;
        }
        self.shooter
            .set_position_tolerance(SHOT_HOLD_POSITION_TOLERANCE_M);
        let found = self.first_converging_length(e, n, n + 2);
        self.shooter.set_position_tolerance(tight);
        found
    }

    /// The shortest length in `from..=to` (at most `K`) whose shot from
    /// `e`, started from the current plan, converges: its plan in
    /// `candidate`. 0 when none does.
    fn first_converging_length(&mut self, e: &[f64; NX], from: usize, to: usize) -> usize {
        let mut n = from;
        while n <= to.min(K) {
            self.candidate = self.plan;
            if self.shooter.shoot::<S>(
                e,
                &mut self.candidate,
                n,
                SHOT_ITERATIONS,
                &self.schedule,
                &self.scales,
            ) {
                return n;
            }
            n += 1;
        }
        0
    }

    /// After a refinement: where the refined plan settles (in the band from
    /// some sample to its end), look for a shot that arrives earlier,
    /// walking the length down one sample at a time.
    /// Searched from `wanted_samples` down where asked (`want_shot`), even
    /// when the refined plan stays in the band.
    pub(super) fn acquire_shot(
        &mut self,
        e: &[f64; NX],
        report: &mut SolveReport,
        wanted_samples: usize,
    ) {
        let settle = self
            .shooter
            .settle_sample::<S>(e, &self.plan, &self.schedule, &self.scales)
            .max(wanted_samples);
        if settle == 0 {
            return;
        }
        if settle > K && self.tail_shots && self.shoot_from_tail(e, report) {
            return;
        }
        // A plan that does not settle within the horizon: a shot of
        // `SHOT_UNSETTLED_SAMPLES` (the search shortens it from there).
        // Not longer: long shots played open loop between frames miss
        // when the capsules are not the model.
        let settle = if settle > K {
            SHOT_UNSETTLED_SAMPLES.min(K)
        } else {
            settle
        };
        // Lock the arrival at `settle`, then bisect for the shortest length
        // that converges from the plan compressed in time.
        self.candidate = self.plan;
        self.adopt_shot_from_candidate(e, settle, report);
    }

    /// A shot from the stored plan tail for `e` (the minimum-time plan the
    /// index names), as long as the tail takes to settle on its own
    /// schedule and at least `SHOT_UNSETTLED_SAMPLES`, then shortened. For
    /// a refined plan that does not settle within the horizon: from rest,
    /// three capsules' separations (minimum times near 1 s) under variable
    /// sampling's phases and coasts gave refined plans that never settled,
    /// and the 30-sample shot from them never converged (no shot until
    /// 2.2 s on (2, 0, -1) cm). True when one converges: the plan is that
    /// shot.
    fn shoot_from_tail(&mut self, e: &[f64; NX], report: &mut SolveReport) -> bool {
        if !S::USE_TABLES {
            return false;
        }
        let coasted = self.schedule.coasted();
        let Some(settles_in) = lookup_tail_for(&S::TABLES, e, &mut self.candidate, coasted) else {
            return false;
        };
        if settles_in == 0 || settles_in > K {
            return false;
        }
        let n = settles_in.max(SHOT_UNSETTLED_SAMPLES.min(K));
        self.adopt_shot_from_candidate(e, n, report)
    }

    /// Shoots `n` samples from `e` seeded with `candidate`, then bisects for
    /// the shortest length that converges; on success the plan is that
    /// shot, `report` carries its cost, and the call returns true. False
    /// leaves the plan as it was.
    fn adopt_shot_from_candidate(
        &mut self,
        e: &[f64; NX],
        n: usize,
        report: &mut SolveReport,
    ) -> bool {
        if !self.shooter.shoot::<S>(
            e,
            &mut self.candidate,
            n,
            SHOT_ITERATIONS,
            &self.schedule,
            &self.scales,
        ) {
            return false;
        }
        let mut p = self.candidate;
        let best = self.shorten_shot(e, &mut p, n, 0, SHOT_MAX_LENGTHS);
        if best == 0 {
            return false;
        }
        self.plan = p;
        self.shot_samples = best;
        report.cost = rollout_cost_below_scaled::<S, M, NX, K>(
            e,
            &self.plan,
            &self.schedule,
            &self.scales,
            f64::INFINITY,
        );
        true
    }

    /// On a leg to a waypoint of a chain (`e_leg` relative to the
    /// waypoint, `e_final` to the final target): one shot to the final
    /// target through the rest of the chain, seeded from the shot in
    /// flight to the waypoint (none: the state must be at rest) followed by
    /// the chain's stored plans from there (`lookup::chain_plan`), then
    /// shortened. The legs stop at each waypoint; the shot does not. True
    /// when one converges: the plan is that shot, to the final target.
    /// False leaves the plan as it was.
    pub fn shoot_through_chain(&mut self, e_leg: &[f64; NX], e_final: &[f64; NX]) -> bool {
        if !self.shooting {
            return false;
        }
        // The chain continues from the waypoint, or from here at rest.
        let head = self.shot_samples;
        let mut d = *e_final;
        if head > 0 {
            let mut i = 0;
            while i < NX / 2 {
                d[2 * i] = e_final[2 * i] - e_leg[2 * i];
                i += 1;
            }
        }
        let mut seed = [0.0; K];
        let Some(total) = chain_plan::<NX, K>(
            &S::TABLES,
            S::USE_TABLES,
            (&self.plan, head),
            &d,
            self.schedule.coasted(),
            &mut seed,
        ) else {
            return false;
        };
        let n = total.min(K);
        if !self.shooter.shoot::<S>(
            e_final,
            &mut seed,
            n,
            SHOT_ITERATIONS,
            &self.schedule,
            &self.scales,
        ) {
            return false;
        }
        let best = self.shorten_shot(e_final, &mut seed, n, 0, SHOT_MAX_LENGTHS);
        self.plan = seed;
        self.shot_samples = best;
        self.has_plan = true;
        self.explicit_ready = false;
        self.tier = Tier::Refined;
        true
    }

    /// Bisects for the shortest length in `lo + 1..best` whose shot from
    /// `e`, started from `p` (converged at `best`) compressed in time,
    /// converges, trying at most `tries` lengths. `p` becomes that shot;
    /// returns its length.
    fn shorten_shot(
        &mut self,
        e: &[f64; NX],
        p: &mut [f64; K],
        mut best: usize,
        mut lo: usize,
        tries: usize,
    ) -> usize {
        let mut tried = 0;
        while best - lo > 1 && tried < tries {
            let n = (lo + best) / 2;
            resample(p, best, &mut self.candidate, n);
            if self.shooter.shoot::<S>(
                e,
                &mut self.candidate,
                n,
                SHOT_ITERATIONS,
                &self.schedule,
                &self.scales,
            ) {
                *p = self.candidate;
                best = n;
            } else {
                lo = n;
            }
            tried += 1;
        }
        best
    }
}
