//! The explicit tier's offline data: the online window QP linearized once,
//! here, around every stored plan sample the runtime can be handed.
//!
//! The online refinement rolls the nonlinear model out over the whole plan
//! with Jacobians every step (26-60 us). But the index already names, for
//! every cell of the relative state space, one stored plan sample; around
//! that sample's state `s` and its plan tail everything a Gauss-Newton
//! window QP needs is fixed except the deviation `d = e - s`:
//!
//! ```text
//!   min_x 1/2 x' H x + (F d)' x    lo <= x <= hi   (x = change of the window's inputs)
//! ```
//!
//! with H the condensed Hessian and F the sensitivity of the QP gradient
//! to the deviation (the linearized model e_k = s_k + Phi_k d + S_k x is
//! exact to first order in both). The cost is the online cost's weights on
//! the deviation from the stored trajectory (tracking): at d = 0 the
//! answer is the stored minimum-time plan itself. Why tracking, not the
//! online cost itself (gradient g0 + F d): the stored plans are minimum-
//! time plans, not minimizers of the quadratic cost, and a full
//! Gauss-Newton step of that cost (no line search: there is no rollout to
//! check it with) undid their separating manoeuvres; the closed loop with
//! it did not settle A (5.9 mm off after 3 s, ideal sampling). Online, the
//! explicit tier evaluates F d (N x NX multiply-adds) and solves the box
//! QP warm-started from the active set of the stored solution (the stored
//! inputs at a bound): no RK4, no Jacobians. The online cost's gradient
//! g0 and a Gauss-Newton model of the cost in d are stored as well, for
//! the cost the explicit tier predicts without a rollout.
//!
//! Why per referenced sample, not per cell or per plan sample: the sparse
//! index keeps 13 660 cells (shared by both schedules) but names only
//! 3 099 (back to back) and 2 061 (constant sampling) distinct samples,
//! out of 289 x 80 stored; storing each named sample once (a u16 slot per
//! kept cell, parallel to `Tables::index_cells`) is 3-9x smaller than per
//! cell or per sample and loses nothing, since the cell's data would be
//! the same sample's anyway. Every named sample's successors on its plan,
//! up to the plan's last input, are stored too (20 930 samples for the
//! default config, 5 498 of them named), so that consecutive explicit steps
//! follow one plan instead of hopping between plans whose manoeuvres
//! differ (docs/decisions.md, "The online solver").
//! The u16 slots cap the count at 65 535
//! samples; the three-capsule module has no explicit data. Per sample: NX + N(N+1)/2 + N +
//! N NX + 1 + NX + NX^2 doubles (130 for N = 10, NX = 4) and N active-set
//! flags. The fine end-game plans (from rest near the target) get a sample
//! at their start and one per later sample with an input.

// Index loops mirror the math (S[k][j], H[a][b]), as in `ocp.rs`.
#![allow(clippy::needless_range_loop)]

use crate::config::Config;
use crate::grid::unflatten;
use crate::model::Model;
use crate::ocp::{rows_to_csc, upper_csc, Ocp};
use crate::tables::Tables;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Which stored plan table a sample lies on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum PlanSource {
    /// Back-to-back plans (`PLAN_U`).
    Main = 0,
    /// Constant sampling's plans (`COASTED_PLAN_U`).
    Coasted = 1,
    /// Fine end-game plans (`FINE_PLAN_U`).
    Fine = 2,
    /// Fine plans with the coast (`COASTED_FINE_PLAN_U`).
    CoastedFine = 3,
}

impl PlanSource {
    pub fn coasted(self) -> bool {
        matches!(self, PlanSource::Coasted | PlanSource::CoastedFine)
    }
}

/// The window QP of one stored plan sample, as a function of the deviation.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplicitSample {
    pub source: PlanSource,
    pub plan: usize,
    /// Plan sample the window starts at.
    pub offset: usize,
    /// Stored relative state at `offset` (the linearization point), SI.
    pub state: Vec<f64>,
    /// Condensed Hessian, upper triangle row by row (N(N+1)/2).
    pub hessian: Vec<f64>,
    /// Gradient of the (halved) plan cost in the window inputs at zero
    /// deviation (N): for the cost prediction only.
    pub gradient: Vec<f64>,
    /// d gradient / d deviation, row a = input a (N x NX, row major): the
    /// tracking QP's whole gradient (see the module docs).
    pub sensitivity: Vec<f64>,
    /// Active set of the QP solution at zero deviation: -1 lower, +1 upper, 0 free.
    pub active: Vec<i8>,
    /// Nonlinear cost of the tail from the stored state.
    pub cost: f64,
    /// Gauss-Newton model of that cost in the deviation: gradient (NX) and
    /// Hessian (NX x NX, row major); with the QP terms it predicts the cost
    /// of the explicit plan without a rollout.
    pub cost_gradient: Vec<f64>,
    pub cost_hessian: Vec<f64>,
}

/// Every explicit sample and, per index cell / fine grid point, its slot
/// (`NO_SLOT`: none).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExplicitTables {
    pub samples: Vec<ExplicitSample>,
    pub index_slot: Vec<u16>,
    pub coasted_index_slot: Vec<u16>,
    pub fine_slot: Vec<u16>,
    pub coasted_fine_slot: Vec<u16>,
}

/// Slot value of a cell without an explicit sample.
pub const NO_SLOT: u16 = u16::MAX;

/// Below this distance (T/m) from a bound, a QP solution counts as on it.
const ACTIVE_TOLERANCE_T_PER_M: f64 = 1.0e-7;

impl ExplicitTables {
    /// Bytes the emitted arrays take (f64 = 8, slots 2, flags 1, the
    /// sample's source/plan/offset 5; the state in `EXPLICIT_STATE`).
    pub fn bytes(&self, n: usize, nx: usize) -> usize {
        let doubles = nx + n * (n + 1) / 2 + n + n * nx + 1 + nx + nx * nx;
        self.samples.len() * (8 * doubles + n + 5)
            + 2 * (self.index_slot.len()
                + self.coasted_index_slot.len()
                + self.fine_slot.len()
                + self.coasted_fine_slot.len())
    }
}

/// The plan tail from `offset`, zero-padded to the plan length.
pub fn tail(u: &[f64], offset: usize, steps: usize) -> Vec<f64> {
    let mut t = vec![0.0; steps];
    let rest = u.len().saturating_sub(offset).min(steps);
    t[..rest].copy_from_slice(&u[offset..offset + rest]);
    t
}

/// Builds the explicit data for every sample the index and the fine grid name.
pub fn build_explicit(config: &Config, tables: &Tables) -> ExplicitTables {
    let model = Model::from_config(config);
    let steps = tables.plan_steps;
    let ocp = Ocp::from_config(&model, config, steps);
    let coasted_ocp = Ocp {
        coast_s: tables.coasted.coast_s,
        ..ocp.clone()
    };
    let n = config.controller.horizon_steps;
    let m = model.capsule_count();
    // Distinct (source, plan, offset), in a fixed order (deterministic output).
    let mut keys: BTreeMap<(PlanSource, usize, usize), u16> = BTreeMap::new();
    let mut slot_of = |source: PlanSource, plan: usize, offset: usize| -> u16 {
        let next = keys.len();
        *keys
            .entry((source, plan, offset))
            .or_insert_with(|| u16::try_from(next).expect("fewer than 65535 explicit samples"))
    };
    let mut index_slots = |index: &[(u16, u16)], source: PlanSource| -> Vec<u16> {
        index
            .iter()
            .map(|&(plan, offset)| {
                if (plan as usize) < tables.plans.len() {
                    slot_of(source, plan as usize, offset as usize)
                } else {
                    NO_SLOT
                }
            })
            .collect()
    };
    let index_slot = index_slots(&tables.index, PlanSource::Main);
    let coasted_index_slot = index_slots(&tables.coasted.index, PlanSource::Coasted);
    let mut fine_slots = |plans: &[Vec<f64>], source: PlanSource| -> Vec<u16> {
        plans
            .iter()
            .enumerate()
            .map(|(f, u)| {
                if u.iter().any(|v| *v != 0.0) {
                    slot_of(source, f, 0)
                } else {
                    NO_SLOT
                }
            })
            .collect()
    };
    let fine_slot = fine_slots(&tables.fine.plans, PlanSource::Fine);
    let coasted_fine_slot = fine_slots(&tables.fine.coasted_plans, PlanSource::CoastedFine);
    // Every named sample's successors up to its plan's arrival, so that the
    // explicit tier can follow a plan it started on instead of hopping
    // between plans whose manoeuvres differ.
    let named: Vec<(PlanSource, usize, usize)> = keys.keys().copied().collect();
    for (source, plan, offset) in named {
        let end = match source {
            PlanSource::Main => last_input(&tables.plans[plan].plan.u),
            PlanSource::Coasted => last_input(&tables.coasted.plans[plan].plan.u),
            PlanSource::Fine => last_input(&tables.fine.plans[plan]),
            PlanSource::CoastedFine => last_input(&tables.fine.coasted_plans[plan]),
        };
        for k in offset + 1..end {
            // The u16 slots bound the count: a config with more samples
            // keeps the named ones and as many successors as fit.
            if keys.len() >= NO_SLOT as usize {
                break;
            }
            let next = keys.len();
            keys.entry((source, plan, k))
                .or_insert_with(|| u16::try_from(next).expect("fewer than 65535 explicit samples"));
        }
    }
    // Slots in key order, so a plan's samples are consecutive: the runtime
    // finds a sample's successors at the next slots, and reads their states
    // from one stretch of `EXPLICIT_STATE`.
    let renumber: BTreeMap<u16, u16> = keys
        .values()
        .zip(0u16..)
        .map(|(&first, sorted)| (first, sorted))
        .collect();
    let remap = |slots: Vec<u16>| -> Vec<u16> {
        slots
            .into_iter()
            .map(|s| if s == NO_SLOT { NO_SLOT } else { renumber[&s] })
            .collect()
    };
    let (index_slot, coasted_index_slot) = (remap(index_slot), remap(coasted_index_slot));
    let (fine_slot, coasted_fine_slot) = (remap(fine_slot), remap(coasted_fine_slot));
    let ordered: Vec<((PlanSource, usize, usize), u16)> = keys.into_keys().zip(0u16..).collect();
    let fine_dims = vec![tables.fine.axis.count; m];
    let samples: Vec<ExplicitSample> = ordered
        .par_iter()
        .map(|&((source, plan, offset), _)| {
            let (ocp, u, start) = match source {
                PlanSource::Main => {
                    let p = &tables.plans[plan].plan;
                    (&ocp, &p.u, p.states[offset].clone())
                }
                PlanSource::Coasted => {
                    let p = &tables.coasted.plans[plan].plan;
                    (&coasted_ocp, &p.u, p.states[offset].clone())
                }
                PlanSource::Fine | PlanSource::CoastedFine => {
                    let (o, plans) = if source == PlanSource::Fine {
                        (&ocp, &tables.fine.plans)
                    } else {
                        (&coasted_ocp, &tables.fine.coasted_plans)
                    };
                    let e0: Vec<f64> = unflatten(plan, &fine_dims)
                        .iter()
                        .flat_map(|&i| [tables.fine.axis.value(i), 0.0])
                        .collect();
                    let (states, _) = o.rollout(&e0, &plans[plan][..offset]);
                    (o, &plans[plan], states[offset].clone())
                }
            };
            linearize(
                ocp,
                n,
                source,
                plan,
                offset,
                &start,
                &tail(u, offset, steps),
            )
        })
        .collect();
    ExplicitTables {
        samples,
        index_slot,
        coasted_index_slot,
        fine_slot,
        coasted_fine_slot,
    }
}

/// One past a plan's last non-zero input: its arrival and the samples that
/// finish it (a chain that stopped at the arrival left the last inputs to
/// another plan's sample).
fn last_input(u: &[f64]) -> usize {
    u.iter().rposition(|v| *v != 0.0).map_or(0, |k| k + 1)
}

/// Block-diagonal per-capsule 2x2 matrices as a dense NX x NX matrix.
fn block_diag(blocks: &[[[f64; 2]; 2]]) -> Vec<Vec<f64>> {
    let nx = 2 * blocks.len();
    let mut a = vec![vec![0.0; nx]; nx];
    for (i, b) in blocks.iter().enumerate() {
        for r in 0..2 {
            for c in 0..2 {
                a[2 * i + r][2 * i + c] = b[r][c];
            }
        }
    }
    a
}

fn mat_mul(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (rows, inner, cols) = (a.len(), b.len(), b[0].len());
    (0..rows)
        .map(|r| {
            (0..cols)
                .map(|c| (0..inner).map(|k| a[r][k] * b[k][c]).sum())
                .collect()
        })
        .collect()
}

fn mat_vec(a: &[Vec<f64>], v: &[f64]) -> Vec<f64> {
    a.iter()
        .map(|row| row.iter().zip(v).map(|(x, y)| x * y).sum())
        .collect()
}

fn transpose(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
    (0..a[0].len())
        .map(|c| a.iter().map(|row| row[c]).collect())
        .collect()
}

/// The window QP of the plan tail `u` from `start` (see the module docs).
pub fn linearize(
    ocp: &Ocp,
    n: usize,
    source: PlanSource,
    plan: usize,
    offset: usize,
    start: &[f64],
    u: &[f64],
) -> ExplicitSample {
    let steps = u.len();
    let nx = start.len();
    let w = &ocp.weights;
    let (states, cost) = ocp.rollout(start, u);
    // Per-sample full-state Jacobians A_k (NX x NX) and input columns B_k.
    let mut a_k = Vec::with_capacity(steps);
    let mut b_k = Vec::with_capacity(steps);
    for k in 0..steps {
        let mut blocks = Vec::new();
        let mut b = vec![0.0; nx];
        for (i, c) in ocp.model.capsules.iter().enumerate() {
            let s = ocp.sample_step(c, [states[k][2 * i], states[k][2 * i + 1]], u[k]);
            blocks.push(s.a);
            b[2 * i] = s.b[0];
            b[2 * i + 1] = s.b[1];
        }
        a_k.push(block_diag(&blocks));
        b_k.push(b);
    }
    // Gauss-Newton cost-to-go of the fixed tail from K back to N (the
    // emitted solver's `tail_cost_to_go`): H_k = W_k + A_k' H_{k+1} A_k.
    let diag = |d: &[f64]| -> Vec<Vec<f64>> {
        (0..nx)
            .map(|r| (0..nx).map(|c| if r == c { d[r] } else { 0.0 }).collect())
            .collect()
    };
    let mut h_tail = diag(&w.p);
    let mut g_tail: Vec<f64> = (0..nx).map(|r| w.p[r] * states[steps][r]).collect();
    for k in (n..steps).rev() {
        let at = transpose(&a_k[k]);
        h_tail = mat_mul(&at, &mat_mul(&h_tail, &a_k[k]));
        let ag = mat_vec(&at, &g_tail);
        for r in 0..nx {
            h_tail[r][r] += w.q[r];
            g_tail[r] = ag[r] + w.q[r] * states[k][r];
        }
    }
    // Window sensitivities S_k[j] = d e_k / d u_j and transitions Phi_k = d e_k / d e_0.
    let mut sens = vec![vec![vec![0.0; nx]; n]; n + 1];
    let mut phi = vec![diag(&vec![1.0; nx])];
    for k in 0..n {
        for j in 0..k {
            sens[k + 1][j] = mat_vec(&a_k[k], &sens[k][j]);
        }
        sens[k + 1][k] = b_k[k].clone();
        phi.push(mat_mul(&a_k[k], &phi[k]));
    }
    // Stage terms k = 1..N-1 with W = Q, terminal (tail) at N; stage 0 does
    // not depend on x, and its dependence on d enters only the cost model.
    let mut h = vec![vec![0.0; n]; n];
    let mut g = vec![0.0; n];
    let mut f = vec![vec![0.0; nx]; n];
    let mut cost_grad = vec![0.0; nx];
    let mut cost_hess = vec![vec![0.0; nx]; nx];
    for k in 0..=n {
        // Weighted quantities at step k: W e_k, W S_k[b], W Phi_k.
        let (w_e, w_s, w_phi): (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>) = if k < n {
            (
                (0..nx).map(|r| w.q[r] * states[k][r]).collect(),
                (0..n)
                    .map(|b| (0..nx).map(|r| w.q[r] * sens[k][b][r]).collect())
                    .collect(),
                (0..nx)
                    .map(|r| (0..nx).map(|c| w.q[r] * phi[k][r][c]).collect())
                    .collect(),
            )
        } else {
            (
                g_tail.clone(),
                (0..n).map(|b| mat_vec(&h_tail, &sens[n][b])).collect(),
                mat_mul(&h_tail, &phi[n]),
            )
        };
        let dot = |x: &[f64], y: &[f64]| -> f64 { x.iter().zip(y).map(|(p, q)| p * q).sum() };
        for a in 0..k.min(n) {
            let sa = &sens[k][a];
            g[a] += dot(sa, &w_e);
            for b in 0..k.min(n) {
                h[a][b] += dot(sa, &w_s[b]);
            }
            for c in 0..nx {
                f[a][c] += (0..nx).map(|r| sa[r] * w_phi[r][c]).sum::<f64>();
            }
        }
        for r in 0..nx {
            cost_grad[r] += (0..nx).map(|s| phi[k][s][r] * w_e[s]).sum::<f64>();
            for c in 0..nx {
                cost_hess[r][c] += (0..nx).map(|s| phi[k][s][r] * w_phi[s][c]).sum::<f64>();
            }
        }
    }
    let u_max = ocp.model.u_max_t_per_m;
    for a in 0..n {
        h[a][a] += w.r;
        g[a] += w.r * u[a];
    }
    // The tracking QP's solution at zero deviation is x = 0 (the stored
    // plan itself): inputs stored at a bound start on it.
    let active = (0..n)
        .map(|a| {
            if u[a] >= u_max - ACTIVE_TOLERANCE_T_PER_M {
                1
            } else if u[a] <= -u_max + ACTIVE_TOLERANCE_T_PER_M {
                -1
            } else {
                0
            }
        })
        .collect();
    ExplicitSample {
        source,
        plan,
        offset,
        state: start.to_vec(),
        hessian: (0..n).flat_map(|a| h[a][a..].to_vec()).collect(),
        gradient: g,
        sensitivity: f.into_iter().flatten().collect(),
        active,
        cost,
        cost_gradient: cost_grad,
        cost_hessian: cost_hess.into_iter().flatten().collect(),
    }
}

/// `min 1/2 x'Hx + g'x, lo <= x <= hi` with clarabel (interior point, to
/// tight tolerances), polished on its active set: the reference the
/// explicit tier is checked against, and the stored active sets.
pub fn reference_box_qp(h: &[Vec<f64>], g: &[f64], lo: &[f64], hi: &[f64]) -> Option<Vec<f64>> {
    let n = g.len();
    let mut rows = Vec::with_capacity(2 * n);
    for a in 0..n {
        rows.push((vec![(a, 1.0)], hi[a]));
        rows.push((vec![(a, -1.0)], -lo[a]));
    }
    // Scaled to a unit largest diagonal: the Hessians reach 1e7 against an
    // input weight of 1e-5, and the interior point's tolerances are absolute.
    let scale = 1.0
        / h.iter()
            .enumerate()
            .fold(1e-300_f64, |m, (i, r)| m.max(r[i].abs()));
    let hs: Vec<Vec<f64>> = h
        .iter()
        .map(|r| r.iter().map(|v| v * scale).collect())
        .collect();
    let gs: Vec<f64> = g.iter().map(|v| v * scale).collect();
    let p = upper_csc(&hs);
    let a = rows_to_csc(&rows, n);
    let b: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let cones = [NonnegativeConeT(rows.len())];
    let settings = DefaultSettings {
        verbose: false,
        tol_gap_abs: 1e-12,
        tol_gap_rel: 1e-12,
        tol_feas: 1e-12,
        max_iter: 400,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p, &gs, &a, &b, &cones, settings).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            Some(polish(h, g, lo, hi, &solver.solution.x).unwrap_or(solver.solution.x.clone()))
        }
        _ => None,
    }
}

/// Within this of a bound (T/m) clarabel's solution is taken to be on it
/// when polishing: its interior-point iterate stops up to 1e-3 T/m short on
/// these ill-conditioned Hessians (diagonal 1e-5 to 1e7).
const POLISH_GUESS_T_PER_M: f64 = 1.0e-4;

/// Polishing (as OSQP's): clarabel's solution names an active set; the
/// equality-constrained problem on it is solved exactly, and the set is
/// corrected (a free variable beyond its bound is fixed there, a wrongly
/// signed multiplier released) until the KKT conditions hold. None when
/// they do not within 3N corrections.
fn polish(h: &[Vec<f64>], g: &[f64], lo: &[f64], hi: &[f64], x0: &[f64]) -> Option<Vec<f64>> {
    let n = g.len();
    let mut active: Vec<i8> = (0..n)
        .map(|j| {
            if x0[j] >= hi[j] - POLISH_GUESS_T_PER_M {
                1
            } else if x0[j] <= lo[j] + POLISH_GUESS_T_PER_M {
                -1
            } else {
                0
            }
        })
        .collect();
    for _ in 0..=3 * n {
        let mut x: Vec<f64> = (0..n)
            .map(|j| match active[j] {
                1 => hi[j],
                -1 => lo[j],
                _ => 0.0,
            })
            .collect();
        let free: Vec<usize> = (0..n).filter(|&j| active[j] == 0).collect();
        let rhs: Vec<f64> = free
            .iter()
            .map(|&r| {
                -g[r]
                    - (0..n)
                        .filter(|&c| active[c] != 0)
                        .map(|c| h[r][c] * x[c])
                        .sum::<f64>()
            })
            .collect();
        let sub: Vec<Vec<f64>> = free
            .iter()
            .map(|&r| free.iter().map(|&c| h[r][c]).collect())
            .collect();
        let xf = solve_dense(sub, rhs)?;
        for (i, &j) in free.iter().enumerate() {
            x[j] = xf[i];
        }
        // Most violated bound among the free variables.
        let beyond = free
            .iter()
            .map(|&j| (j, (x[j] - hi[j]).max(lo[j] - x[j])))
            .filter(|&(_, v)| v > 0.0)
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((j, _)) = beyond {
            active[j] = if x[j] > hi[j] { 1 } else { -1 };
            continue;
        }
        // Multipliers: at an upper bound the gradient must be <= 0, at a lower >= 0.
        let wrong = (0..n)
            .filter(|&j| active[j] != 0)
            .map(|j| {
                let grad = g[j] + (0..n).map(|c| h[j][c] * x[c]).sum::<f64>();
                (j, if active[j] > 0 { grad } else { -grad })
            })
            .filter(|&(_, w)| w > 0.0)
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match wrong {
            Some((j, _)) => active[j] = 0,
            None => return Some(x),
        }
    }
    None
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting.
fn solve_dense(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col] == 0.0 || !a[pivot][col].is_finite() {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for r in col + 1..n {
            let f = a[r][col] / a[col][col];
            for c in col..n {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

/// The condensed Hessian of `s` as a dense N x N matrix.
pub fn dense_hessian(s: &ExplicitSample, n: usize) -> Vec<Vec<f64>> {
    let mut h = vec![vec![0.0; n]; n];
    let mut i = 0;
    for a in 0..n {
        for b in a..n {
            h[a][b] = s.hessian[i];
            h[b][a] = s.hessian[i];
            i += 1;
        }
    }
    h
}

/// The certified operation count of one explicit step (the online code's own count).
pub use capsule_mpc_solver::explicit::explicit_step_ops;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_qp_respects_the_box_and_is_optimal() {
        // 2 variables, unconstrained minimizer (-3, 0.5) outside the box in x0.
        let h = vec![vec![2.0, 0.0], vec![0.0, 2.0]];
        let g = vec![6.0, -1.0];
        let x = reference_box_qp(&h, &g, &[-1.0, -1.0], &[1.0, 1.0]).expect("solves");
        assert!((x[0] + 1.0).abs() < 1e-9, "{x:?}");
        assert!((x[1] - 0.5).abs() < 1e-9, "{x:?}");
    }

    #[test]
    fn op_count_grows_with_iterations() {
        let one = explicit_step_ops(10, 4, 80, 1);
        let two = explicit_step_ops(10, 4, 80, 2);
        assert!(two > one && one > 0);
        // Per iteration at N = 10 the Cholesky alone is 440 operations.
        assert!(two - one >= 440, "{}", two - one);
    }
}
