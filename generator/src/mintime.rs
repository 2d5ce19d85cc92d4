//! Minimum rest-to-rest time: the shortest horizon over which the offline
//! solver still brings a start at rest into a band around the target.
//!
//! For a horizon of T samples the problem is a feasibility problem: minimize
//! the terminal error scaled by the band (a component at the band's edge
//! costs 1) with a tiny input weight; T is feasible when every terminal
//! component lies inside the band. The search walks T down from a plan that
//! already arrives, warm-starting each horizon from the previous solution
//! time-scaled to the shorter length (and from its truncation), and stops
//! at the first horizon where neither start arrives. The problem is
//! nonconvex, so the result is an upper bound on the true minimum time, as
//! any local method's is; it is the plan the tables store.

use crate::grid::{flatten, starting_guesses, unflatten, Axis, Progress};
use crate::ocp::{Ocp, OcpWeights};
use rayon::prelude::*;

/// A box around the target at rest: |position error| and |speed|.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    pub position_m: f64,
    pub speed_m_per_s: f64,
}

/// The settle band of the closed loop (1 mm, 5 mm/s): the metric every
/// settle time and the minimum-time bound refer to.
pub const SETTLE_BAND: Band = Band {
    position_m: 1.0e-3,
    speed_m_per_s: 5.0e-3,
};

/// The band stored plans must end in: tighter than the settle band, so that
/// the residual speed drifts the capsules little before the closed loop's
/// hold takes over, and noise and model error have room.
pub const PLAN_BAND: Band = Band {
    position_m: 0.5e-3,
    speed_m_per_s: 1.5e-3,
};

/// The band the fine plans (moves of a few mm near the target, see
/// `grid.fine_range_m`) end in: a tenth of the settle band's position.
pub const FINE_PLAN_BAND: Band = Band {
    position_m: 0.1e-3,
    speed_m_per_s: 0.5e-3,
};

/// Input weight of the feasibility problem, per (T/m)^2: a regularizer only
/// (at u_max it costs 1.6e-6 per sample against 1 at the band's edge).
const REACH_INPUT_WEIGHT: f64 = 1.0e-3;

impl Band {
    pub fn contains(&self, e: &[f64]) -> bool {
        e.iter().enumerate().all(|(j, v)| {
            let bound = if j % 2 == 0 {
                self.position_m
            } else {
                self.speed_m_per_s
            };
            v.abs() <= bound
        })
    }

    /// Terminal weights that make a component at the band's edge cost 1.
    fn terminal_weights(&self, nx: usize) -> Vec<f64> {
        (0..nx)
            .map(|j| {
                if j % 2 == 0 {
                    1.0 / (self.position_m * self.position_m)
                } else {
                    1.0 / (self.speed_m_per_s * self.speed_m_per_s)
                }
            })
            .collect()
    }
}

/// First sample index k such that every state from k to the end of `states`
/// lies inside `band`; None when the last state is outside.
pub fn arrival_sample(states: &[Vec<f64>], band: &Band) -> Option<usize> {
    let mut k = states.len();
    while k > 0 && band.contains(&states[k - 1]) {
        k -= 1;
    }
    (k < states.len()).then_some(k)
}

/// `u` resampled to `len` samples (nearest sample in scaled time).
pub fn time_scaled(u: &[f64], len: usize) -> Vec<f64> {
    if u.is_empty() {
        return vec![0.0; len];
    }
    (0..len)
        .map(|j| {
            let src = ((j as f64 + 0.5) * u.len() as f64 / len as f64).floor() as usize;
            u[src.min(u.len() - 1)]
        })
        .collect()
}

/// The result of the search for one start.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MinTimePlan {
    /// Samples to arrival in `band` (the plan's length).
    pub samples: usize,
    /// The inputs (length `samples`), T/m.
    pub u: Vec<f64>,
}

impl MinTimePlan {
    /// The plan from the opposite start (minus the inputs).
    pub fn mirrored(&self) -> MinTimePlan {
        MinTimePlan {
            samples: self.samples,
            u: self.u.iter().map(|v| -v).collect(),
        }
    }
}

/// The feasibility problem over `steps` samples (see the module docs).
pub fn reach_ocp<'a>(base: &Ocp<'a>, steps: usize, band: &Band) -> Ocp<'a> {
    let nx = base.model.state_count();
    Ocp {
        weights: OcpWeights {
            q: vec![0.0; nx],
            r: REACH_INPUT_WEIGHT,
            p: band.terminal_weights(nx),
        },
        steps,
        ..base.clone()
    }
}

/// Shortest horizon found from rest at `e0`, starting from `arriving`,
/// inputs that bring `e0` into `band` at their last sample. Tries shorter
/// horizons in steps of a quarter of the current length, halving the step
/// after a failure, down to single samples: about log2(T) + a few solves.
pub fn descend(
    base: &Ocp,
    e0: &[f64],
    arriving: MinTimePlan,
    band: &Band,
    sqp_iterations: usize,
) -> MinTimePlan {
    let mut best = arriving;
    let mut step = (best.samples / 4).max(1);
    while best.samples > 1 && step >= 1 {
        let t = best.samples.saturating_sub(step).max(1);
        let ocp = reach_ocp(base, t, band);
        let mut guesses = vec![time_scaled(&best.u, t)];
        if step == 1 {
            // Near the end, drop the first or last sample instead.
            guesses.push(best.u[..t].to_vec());
            guesses.push(best.u[best.samples - t..].to_vec());
        }
        let found = guesses.iter().find_map(|g| {
            let plan = ocp.solve(e0, g, sqp_iterations);
            band.contains(plan.states.last().expect("states"))
                .then_some(plan.u)
        });
        match found {
            Some(u) => best = MinTimePlan { samples: t, u },
            None if step == 1 => break,
            None => step /= 2,
        }
    }
    best
}

/// The first of `guesses` (each solved as a feasibility problem over its own
/// length, at most `max_samples`) that arrives in `band`, shortest first.
pub fn first_arriving(
    base: &Ocp,
    e0: &[f64],
    guesses: &[Vec<f64>],
    band: &Band,
    max_samples: usize,
    sqp_iterations: usize,
) -> Option<MinTimePlan> {
    let mut order: Vec<&Vec<f64>> = guesses.iter().collect();
    order.sort_by_key(|g| g.len());
    order.into_iter().find_map(|g| {
        let t = g.len().clamp(1, max_samples);
        let guess = if g.len() > t {
            time_scaled(g, t)
        } else {
            g.clone()
        };
        let plan = reach_ocp(base, t, band).solve(e0, &guess, sqp_iterations);
        band.contains(plan.states.last().expect("states"))
            .then_some(MinTimePlan {
                samples: t,
                u: plan.u,
            })
    })
}

/// Minimum-time plans from rest at every point of the grid `axis`^M, or
/// None where no horizon up to `max_samples` arrives.
///
/// Continuation in rings of growing Chebyshev distance from the target:
/// rest-to-rest legs compose exactly (the dynamics do not depend on
/// position), so a point p one unit step s beyond an inner point q is
/// reached by the plan of q followed by the plan of s (or s then q). Those
/// concatenations, and q's own plan stretched by a few samples, are the
/// starting guesses; the shortest that arrives is then shortened by
/// [`descend`], which fuses the legs. The first ring starts from
/// `random_starts` deterministic random guesses. Every ring depends only on
/// inner rings, so each ring is solved in parallel and the result does not
/// depend on the thread count. Odd symmetry (the plan for -e0 is minus the
/// plan for e0) halves the work.
///
/// The per-point work ([`RingSearch::ring_point`],
/// [`RingSearch::improve_point`]) is a pure function of the plans of the
/// previous rings, which is what lets `shard` split a ring over processes.
pub fn grid_min_time_plans(
    base: &Ocp,
    axis: &Axis,
    band: &Band,
    max_samples: usize,
    random_starts: usize,
    sqp_iterations: usize,
    progress: &dyn Progress,
) -> Vec<Option<MinTimePlan>> {
    let search = RingSearch {
        base,
        axis,
        band: *band,
        max_samples,
        random_starts,
        sqp_iterations,
    };
    let mut plans = search.initial();
    progress.start("minimum-time plans", search.half().saturating_sub(1));
    for r in 1..=search.rings() {
        let solved: Vec<(usize, Option<MinTimePlan>)> = search
            .ring_members(r)
            .par_iter()
            .map(|&flat| {
                let found = search.ring_point(&plans, flat, r);
                progress.tick();
                (flat, found)
            })
            .collect();
        for (flat, plan) in solved {
            search.store(&mut plans, flat, plan);
        }
    }
    // One improvement sweep: the nonconvex descent leaves some points
    // slower than their neighbours; restart each point from every
    // neighbour's plan that is shorter than its own, stretched by one
    // sample. Reads only the previous sweep, so it is deterministic too.
    progress.start("minimum-time plans, improvement sweep", search.half());
    let improved: Vec<(usize, Option<MinTimePlan>)> = (0..search.half())
        .into_par_iter()
        .map(|flat| {
            let found = search.improve_point(&plans, flat);
            progress.tick();
            (flat, found)
        })
        .collect();
    for (flat, plan) in improved {
        if plan.is_some() {
            search.store(&mut plans, flat, plan);
        }
    }
    plans
}

/// The ring-by-ring search over one grid, split into its units of work: a
/// point of a ring (reads the inner rings), and a point's improvement
/// (reads every ring). Points are flat row-major indices over `axis`^M;
/// only the first half (`0..half()`) is solved, the other half is its
/// mirror image (see [`RingSearch::store`]).
pub struct RingSearch<'s, 'a> {
    pub base: &'s Ocp<'a>,
    pub axis: &'s Axis,
    pub band: Band,
    pub max_samples: usize,
    pub random_starts: usize,
    pub sqp_iterations: usize,
}

impl RingSearch<'_, '_> {
    fn m(&self) -> usize {
        self.base.model.capsule_count()
    }

    fn dims(&self) -> Vec<usize> {
        vec![self.axis.count; self.m()]
    }

    fn centre(&self) -> usize {
        self.axis.count / 2
    }

    /// Points of the grid.
    pub fn total(&self) -> usize {
        self.dims().iter().product()
    }

    /// Points solved (the rest are mirror images); includes the centre.
    pub fn half(&self) -> usize {
        self.total().div_ceil(2)
    }

    /// Number of rings around the centre.
    pub fn rings(&self) -> usize {
        self.centre()
    }

    fn offset(&self, flat: usize) -> Vec<i64> {
        let c = self.centre() as i64;
        unflatten(flat, &self.dims())
            .iter()
            .map(|&i| i as i64 - c)
            .collect()
    }

    fn ring_of_offset(o: &[i64]) -> usize {
        o.iter()
            .map(|v| v.unsigned_abs() as usize)
            .max()
            .unwrap_or(0)
    }

    fn flat_of_offset(&self, o: &[i64]) -> Option<usize> {
        let c = self.centre() as i64;
        let idx: Option<Vec<usize>> = o
            .iter()
            .map(|&v| {
                let i = v + c;
                (0..self.axis.count as i64)
                    .contains(&i)
                    .then_some(i as usize)
            })
            .collect();
        idx.map(|i| flatten(&i, &self.dims()))
    }

    fn e0_of(&self, flat: usize) -> Vec<f64> {
        unflatten(flat, &self.dims())
            .iter()
            .flat_map(|&i| [self.axis.value(i), 0.0])
            .collect()
    }

    /// The state before the first ring: only the centre (an empty plan).
    pub fn initial(&self) -> Vec<Option<MinTimePlan>> {
        let mut plans = vec![None; self.total()];
        let centre_flat = flatten(&vec![self.centre(); self.m()], &self.dims());
        plans[centre_flat] = Some(MinTimePlan {
            samples: 0,
            u: Vec::new(),
        });
        plans
    }

    /// Points of ring `r` among the solved half, ascending.
    pub fn ring_members(&self, r: usize) -> Vec<usize> {
        (0..self.half())
            .filter(|&f| Self::ring_of_offset(&self.offset(f)) == r)
            .collect()
    }

    /// Stores `plan` at `flat` and its mirror image (minus the inputs) at
    /// the opposite point.
    pub fn store(&self, plans: &mut [Option<MinTimePlan>], flat: usize, plan: Option<MinTimePlan>) {
        let total = plans.len();
        plans[total - 1 - flat] = plan.as_ref().map(MinTimePlan::mirrored);
        plans[flat] = plan;
    }

    /// The plan of point `flat` of ring `r`, from the plans of the inner
    /// rings in `plans`.
    pub fn ring_point(
        &self,
        plans: &[Option<MinTimePlan>],
        flat: usize,
        r: usize,
    ) -> Option<MinTimePlan> {
        let base = self.base;
        let m = self.m();
        let e0 = self.e0_of(flat);
        let mut guesses: Vec<Vec<f64>> = Vec::new();
        if r == 1 {
            guesses = starting_guesses(
                flat as u64,
                self.random_starts,
                FIRST_RING_SAMPLES.min(self.max_samples),
                base.model.u_max_t_per_m,
            );
        } else {
            let p = self.offset(flat);
            // Unit steps s toward the target: components 0 or sign(p_i).
            for mask in 1..(1usize << m) {
                let s: Vec<i64> = (0..m)
                    .map(|i| if mask >> i & 1 == 1 { p[i].signum() } else { 0 })
                    .collect();
                if s.iter().all(|&v| v == 0) {
                    continue;
                }
                let q: Vec<i64> = p.iter().zip(&s).map(|(a, b)| a - b).collect();
                let (Some(qf), Some(sf)) = (self.flat_of_offset(&q), self.flat_of_offset(&s))
                else {
                    continue;
                };
                if Self::ring_of_offset(&q) >= r {
                    continue;
                }
                let (Some(uq), Some(us)) = (&plans[qf], &plans[sf]) else {
                    continue;
                };
                guesses.push([uq.u.as_slice(), us.u.as_slice()].concat());
                guesses.push([us.u.as_slice(), uq.u.as_slice()].concat());
                for extra in STRETCH_SAMPLES {
                    guesses.push(time_scaled(&uq.u, uq.samples + extra));
                }
            }
        }
        first_arriving(
            base,
            &e0,
            &guesses,
            &self.band,
            self.max_samples,
            self.sqp_iterations,
        )
        .map(|start| descend(base, &e0, start, &self.band, self.sqp_iterations))
    }

    /// A shorter plan for point `flat` than the one in `plans` (the state
    /// after every ring), restarted from each neighbour's shorter plan
    /// stretched by one sample; None when none is shorter.
    pub fn improve_point(&self, plans: &[Option<MinTimePlan>], flat: usize) -> Option<MinTimePlan> {
        let m = self.m();
        let own = plans[flat]
            .as_ref()
            .map_or(self.max_samples + 1, |p| p.samples);
        let p = self.offset(flat);
        let mut guesses = Vec::new();
        for n in 0..3usize.pow(m as u32) {
            let d: Vec<i64> = (0..m)
                .map(|i| (n / 3usize.pow(i as u32) % 3) as i64 - 1)
                .collect();
            let q: Vec<i64> = p.iter().zip(&d).map(|(a, b)| a + b).collect();
            if let Some(Some(nb)) = self.flat_of_offset(&q).map(|f| &plans[f]) {
                if nb.samples + 1 < own && nb.samples > 0 {
                    guesses.push(time_scaled(&nb.u, nb.samples + 1));
                }
            }
        }
        let e0 = self.e0_of(flat);
        first_arriving(
            self.base,
            &e0,
            &guesses,
            &self.band,
            self.max_samples,
            self.sqp_iterations,
        )
        .map(|start| descend(self.base, &e0, start, &self.band, self.sqp_iterations))
        .filter(|b| b.samples < own)
    }
}

/// Horizon of the first ring's random starting guesses, samples (unit
/// steps of the default grid take 0.1-0.4 s).
const FIRST_RING_SAMPLES: usize = 30;
/// An inner neighbour's plan, stretched by these many samples, is a
/// starting guess too.
const STRETCH_SAMPLES: [usize; 2] = [2, 6];

/// The band stored plans are finished into, a few samples after their
/// minimum-time arrival: near rest, so that the residual relative speed of
/// the capsules (which the single gradient cannot damp near rest) drifts
/// them apart slowly, and the closed loop's refinement starts from a plan
/// that already stops.
pub const FINISH_BAND: Band = Band {
    position_m: 0.05e-3,
    speed_m_per_s: 0.05e-3,
};

/// Samples added after the minimum-time arrival to finish at rest.
pub const FINISH_SAMPLES: usize = 2;

/// The minimum-time inputs `arrived` (length T), padded with
/// `finish_samples` zero samples (usually [`FINISH_SAMPLES`]) and
/// re-solved over the longer horizon
/// toward [`FINISH_BAND`]; the padded inputs when that does not end nearer
/// rest, `arrived` itself when it does not fit in `max_samples`.
pub fn finish_at_rest(
    base: &Ocp,
    e0: &[f64],
    arrived: &MinTimePlan,
    max_samples: usize,
    sqp_iterations: usize,
    finish_samples: usize,
) -> Vec<f64> {
    let t = arrived.samples + finish_samples;
    if arrived.samples == 0 || t > max_samples {
        return arrived.u.clone();
    }
    let ocp = reach_ocp(base, t, &FINISH_BAND);
    let mut guess = arrived.u.clone();
    guess.resize(t, 0.0);
    let (_, before) = ocp.rollout(e0, &guess);
    let plan = ocp.solve(e0, &guess, sqp_iterations);
    if plan.cost < before {
        plan.u
    } else {
        guess
    }
}
