//! The offline optimal-control problem and its solver: sequential QPs on
//! linearizations along the current trajectory (single shooting, Gauss-Newton
//! Hessian, trust region, backtracking on the true nonlinear cost), with
//! clarabel as the QP engine.
//!
//! States are relative to the target (`e = x - x_target`): the dynamics do not
//! depend on position, so a plan solved for `e0` works for every target.

// Index loops mirror the math (S[k][j], H[a][b]); iterator chains would hide it.
#![allow(clippy::needless_range_loop)]

use crate::config::Config;
use crate::model::{rk4_capsule, CapsuleParams, CapsuleStep, Model};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus};
use serde::{Deserialize, Serialize};

/// Weights and bounds of the problem, in SI (converted once from the config's
/// cost units).
#[derive(Debug, Clone, PartialEq)]
pub struct OcpWeights {
    /// Stage weights on e (per m^2 and (m/s)^2).
    pub q: Vec<f64>,
    /// Input weight per (T/m)^2.
    pub r: f64,
    /// Terminal weights on e.
    pub p: Vec<f64>,
}

impl OcpWeights {
    /// SI weights from the config: a weight w on a state in cm becomes
    /// w * 100^2 on the state in m, so that the cost value is unchanged.
    pub fn from_config(config: &Config) -> OcpWeights {
        let s2 = config.controller.cost_units.length_scale().powi(2);
        OcpWeights {
            q: config.controller.q.iter().map(|w| w * s2).collect(),
            r: config.controller.r,
            p: config.controller.p.iter().map(|w| w * s2).collect(),
        }
    }
}

/// A discretized optimal-control problem over `steps` samples.
#[derive(Debug, Clone)]
pub struct Ocp<'a> {
    pub model: &'a Model,
    pub weights: OcpWeights,
    pub dt_s: f64,
    pub substeps: usize,
    pub steps: usize,
    pub position_bound_m: f64,
    pub speed_bound_m_per_s: f64,
    /// Zero-gradient coast after every sample, s: the scanner's tracking
    /// phase (+ delay) under constant sampling; 0 for back-to-back samples.
    pub coast_s: f64,
}

/// A solved plan from a relative start state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Gradient per sample, T/m (length K).
    pub u: Vec<f64>,
    /// Relative states e_0..e_K (K+1 rows of 2M).
    pub states: Vec<Vec<f64>>,
    /// Nonlinear cost of the plan.
    pub cost: f64,
    /// SQP iterations used.
    pub iterations: usize,
}

impl Plan {
    /// Largest |e| position component at the end of the plan, m.
    pub fn final_position_error_m(&self) -> f64 {
        let last = self.states.last().expect("plan has states");
        last.iter().step_by(2).fold(0.0_f64, |a, e| a.max(e.abs()))
    }
}

impl<'a> Ocp<'a> {
    pub fn from_config(model: &'a Model, config: &Config, steps: usize) -> Ocp<'a> {
        Ocp {
            model,
            weights: OcpWeights::from_config(config),
            dt_s: config.controller.sample_time_s,
            substeps: config.controller.rk4_substeps,
            steps,
            position_bound_m: config.controller.position_bound_m,
            speed_bound_m_per_s: config.controller.speed_bound_m_per_s,
            coast_s: 0.0,
        }
    }

    /// One sample of capsule `c` from `xv` at input `u`, then the coast:
    /// the next state and the exact Jacobians of the composite map.
    pub(crate) fn sample_step(&self, c: &CapsuleParams, xv: [f64; 2], u: f64) -> CapsuleStep {
        let act = rk4_capsule(c, xv, u, self.dt_s, self.substeps);
        if self.coast_s <= 0.0 {
            return act;
        }
        // Sub-steps of the coast no longer than the actuation's.
        let h = self.dt_s / self.substeps as f64;
        let steps = (self.coast_s / h).ceil().max(1.0) as usize;
        let coast = rk4_capsule(c, act.next, 0.0, self.coast_s, steps);
        let (a, b) = (coast.a, act);
        CapsuleStep {
            next: coast.next,
            a: [
                [
                    a[0][0] * b.a[0][0] + a[0][1] * b.a[1][0],
                    a[0][0] * b.a[0][1] + a[0][1] * b.a[1][1],
                ],
                [
                    a[1][0] * b.a[0][0] + a[1][1] * b.a[1][0],
                    a[1][0] * b.a[0][1] + a[1][1] * b.a[1][1],
                ],
            ],
            b: [
                a[0][0] * b.b[0] + a[0][1] * b.b[1],
                a[1][0] * b.b[0] + a[1][1] * b.b[1],
            ],
        }
    }

    fn nx(&self) -> usize {
        self.model.state_count()
    }

    /// Rollout from `e0` under `u`: states and the nonlinear cost.
    pub fn rollout(&self, e0: &[f64], u: &[f64]) -> (Vec<Vec<f64>>, f64) {
        let nx = self.nx();
        let mut states = Vec::with_capacity(u.len() + 1);
        states.push(e0.to_vec());
        let mut cost = 0.0;
        for &uk in u {
            let e = states.last().expect("non-empty");
            cost += self.stage_cost(e, uk);
            let mut next = vec![0.0; nx];
            for (i, c) in self.model.capsules.iter().enumerate() {
                let s = self.sample_step(c, [e[2 * i], e[2 * i + 1]], uk);
                next[2 * i] = s.next[0];
                next[2 * i + 1] = s.next[1];
            }
            states.push(next);
        }
        cost += self.terminal_cost(states.last().expect("non-empty"));
        (states, cost)
    }

    pub fn stage_cost(&self, e: &[f64], u: f64) -> f64 {
        e.iter()
            .zip(&self.weights.q)
            .map(|(e, q)| q * e * e)
            .sum::<f64>()
            + self.weights.r * u * u
    }

    pub fn terminal_cost(&self, e: &[f64]) -> f64 {
        e.iter().zip(&self.weights.p).map(|(e, p)| p * e * e).sum()
    }

    /// How far `states` leave the state bounds (0 when inside), m or m/s.
    pub fn bound_violation(&self, states: &[Vec<f64>]) -> f64 {
        states
            .iter()
            .flat_map(|e| {
                e.iter().enumerate().map(|(j, v)| {
                    let bound = if j % 2 == 0 {
                        self.position_bound_m
                    } else {
                        self.speed_bound_m_per_s
                    };
                    (v.abs() - bound).max(0.0)
                })
            })
            .fold(0.0, f64::max)
    }

    /// Sensitivities S[k][j] = d e_k / d u_j (2M entries each) along `u`.
    fn sensitivities(&self, states: &[Vec<f64>], u: &[f64]) -> Vec<Vec<Vec<f64>>> {
        let (k_steps, nx) = (u.len(), self.nx());
        let mut s = vec![vec![vec![0.0; nx]; k_steps]; k_steps + 1];
        for k in 0..k_steps {
            for (i, c) in self.model.capsules.iter().enumerate() {
                let e = &states[k];
                let step = self.sample_step(c, [e[2 * i], e[2 * i + 1]], u[k]);
                for j in 0..k {
                    let prev = [s[k][j][2 * i], s[k][j][2 * i + 1]];
                    s[k + 1][j][2 * i] = step.a[0][0] * prev[0] + step.a[0][1] * prev[1];
                    s[k + 1][j][2 * i + 1] = step.a[1][0] * prev[0] + step.a[1][1] * prev[1];
                }
                s[k + 1][k][2 * i] = step.b[0];
                s[k + 1][k][2 * i + 1] = step.b[1];
            }
        }
        s
    }

    /// Sequential QPs from `u_init`. Returns the best feasible plan found.
    pub fn solve(&self, e0: &[f64], u_init: &[f64], max_iterations: usize) -> Plan {
        let u_max = self.model.u_max_t_per_m;
        let mut u: Vec<f64> = u_init.iter().map(|v| v.clamp(-u_max, u_max)).collect();
        let (mut states, mut cost) = self.rollout(e0, &u);
        let mut trust = u_max;
        let mut iterations = 0;
        for _ in 0..max_iterations {
            iterations += 1;
            let Some(du) = self.qp_step(&states, &u, trust) else {
                break;
            };
            // Backtracking on the true cost (and state bounds).
            let mut alpha = 1.0;
            let mut accepted = false;
            let viol0 = self.bound_violation(&states);
            for _ in 0..6 {
                let cand: Vec<f64> = u
                    .iter()
                    .zip(&du)
                    .map(|(a, d)| (a + alpha * d).clamp(-u_max, u_max))
                    .collect();
                let (cs, cc) = self.rollout(e0, &cand);
                let viol = self.bound_violation(&cs);
                if (viol <= viol0.max(1e-9) && cc < cost) || viol < viol0 - 1e-9 {
                    let improvement = (cost - cc) / cost.max(1e-300);
                    u = cand;
                    states = cs;
                    cost = cc;
                    accepted = true;
                    if alpha == 1.0 {
                        trust = (trust * 2.0).min(2.0 * u_max);
                    }
                    if improvement < 1e-9 {
                        return self.finish(u, states, cost, iterations);
                    }
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                trust *= 0.25;
                if trust < 1e-7 * u_max {
                    break;
                }
            }
        }
        self.finish(u, states, cost, iterations)
    }

    fn finish(&self, u: Vec<f64>, states: Vec<Vec<f64>>, cost: f64, iterations: usize) -> Plan {
        Plan {
            u,
            states,
            cost,
            iterations,
        }
    }

    /// One Gauss-Newton QP around (states, u): returns the step du, or None
    /// when clarabel fails.
    fn qp_step(&self, states: &[Vec<f64>], u: &[f64], trust: f64) -> Option<Vec<f64>> {
        let (n, nx) = (u.len(), self.nx());
        let s = self.sensitivities(states, u);
        let w = &self.weights;
        // H = sum_k S_k' W_k S_k + R I; grad = sum_k S_k' W_k e_k + R u.
        let mut h = vec![vec![0.0; n]; n];
        let mut grad = vec![0.0; n];
        for k in 1..=n {
            // Stage costs run over e_0..e_{K-1} (e_0 is fixed), terminal on e_K.
            let weights = if k == n { &w.p } else { &w.q };
            let e = &states[k];
            for a in 0..k {
                let sa = &s[k][a];
                grad[a] += (0..nx).map(|r| sa[r] * weights[r] * e[r]).sum::<f64>();
                for b in a..k {
                    let sb = &s[k][b];
                    h[a][b] += (0..nx).map(|r| sa[r] * weights[r] * sb[r]).sum::<f64>();
                }
            }
        }
        for a in 0..n {
            h[a][a] += w.r;
            grad[a] += w.r * u[a];
        }
        // Constraints G du <= hvec: input box, trust box, state bounds.
        let u_max = self.model.u_max_t_per_m;
        let mut rows: Vec<(Vec<(usize, f64)>, f64)> = Vec::new();
        for a in 0..n {
            let hi = (u_max - u[a]).min(trust);
            let lo = (-u_max - u[a]).max(-trust);
            rows.push((vec![(a, 1.0)], hi));
            rows.push((vec![(a, -1.0)], -lo));
        }
        for k in 1..=n {
            for r in 0..nx {
                let bound = if r % 2 == 0 {
                    self.position_bound_m
                } else {
                    self.speed_bound_m_per_s
                };
                let e = states[k][r];
                // Only rows that could become active within this step.
                if e.abs() < 0.5 * bound {
                    continue;
                }
                let coeffs: Vec<(usize, f64)> = (0..k).map(|j| (j, s[k][j][r])).collect();
                let neg: Vec<(usize, f64)> = coeffs.iter().map(|&(j, c)| (j, -c)).collect();
                rows.push((coeffs, (bound - e).max(0.0)));
                rows.push((neg, (bound + e).max(0.0)));
            }
        }
        let p = upper_csc(&h);
        let a = rows_to_csc(&rows, n);
        let b: Vec<f64> = rows.iter().map(|r| r.1).collect();
        let cones = [NonnegativeConeT(rows.len())];
        let settings = DefaultSettings {
            verbose: false,
            ..DefaultSettings::default()
        };
        let mut solver = DefaultSolver::new(&p, &grad, &a, &b, &cones, settings).ok()?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Some(solver.solution.x.clone()),
            _ => None,
        }
    }
}

/// Upper triangle of a dense symmetric matrix as CSC.
pub fn upper_csc(h: &[Vec<f64>]) -> CscMatrix<f64> {
    let n = h.len();
    let mut colptr = vec![0];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for c in 0..n {
        for (r, row) in h.iter().enumerate().take(c + 1) {
            let v = if r <= c { row[c] } else { 0.0 };
            if v != 0.0 {
                rowval.push(r);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(n, n, colptr, rowval, nzval)
}

/// Sparse rows (column, value) to a CSC matrix with `n` columns.
pub fn rows_to_csc(rows: &[(Vec<(usize, f64)>, f64)], n: usize) -> CscMatrix<f64> {
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for (r, (entries, _)) in rows.iter().enumerate() {
        for &(c, v) in entries {
            if v != 0.0 {
                cols[c].push((r, v));
            }
        }
    }
    let mut colptr = vec![0];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for col in cols {
        for (r, v) in col {
            rowval.push(r);
            nzval.push(v);
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows.len(), n, colptr, rowval, nzval)
}
