//! The capsule model: physical parameters -> g_i, drag; continuous dynamics;
//! RK4 discretization with exact Jacobians.
//!
//! Each capsule i moves along the bore's x axis:
//!
//! ```text
//! x_i' = v_i
//! v_i' = a_drag,i(v_i) + g_i u          u = dBz/dx in T/m, |u| <= u_max
//! ```
//!
//! with `g_i = V_i M_s / m_i` (m/s^2 per T/m) and, for the quadratic law,
//! `a_drag = -b_i v|v|`, `b_i = rho_f C_d A / (2 m_i)` (1/m). The capsules are
//! coupled only through the shared input u, so every Jacobian is block
//! diagonal with one 2x2 block per capsule; this module works per capsule.

use crate::config::{Config, DragLaw};
use capsule_mpc_solver::DragLaw as SolverDrag;
use serde::Serialize;
use std::f64::consts::PI;

/// Drag acceleration law of one capsule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "law", rename_all = "kebab-case")]
pub enum Drag {
    /// a = -b v|v|, b in 1/m.
    Quadratic { b_per_m: f64 },
    /// a = -k C_d(Re) v|v| with Re = re_per_speed |v| (Clift-Gauvin correlation),
    /// k = rho A / (2 m) in 1/m, re_per_speed = rho D / mu in s/m.
    SphereCorrelation {
        k_per_m: f64,
        re_per_speed_s_per_m: f64,
    },
}

impl Drag {
    /// The law as the online solver evaluates it (one implementation).
    pub fn law(&self) -> SolverDrag {
        match *self {
            Drag::Quadratic { b_per_m } => SolverDrag::Quadratic { b_per_m },
            Drag::SphereCorrelation {
                k_per_m,
                re_per_speed_s_per_m,
            } => SolverDrag::SphereCorrelation {
                k_per_m,
                re_per_speed_s_per_m,
            },
        }
    }

    /// The law's coefficient: b (1/m) of the quadratic law, k (1/m) of the
    /// sphere correlation.
    pub fn coefficient(&self) -> f64 {
        match *self {
            Drag::Quadratic { b_per_m } => b_per_m,
            Drag::SphereCorrelation { k_per_m, .. } => k_per_m,
        }
    }

    /// The same law with coefficient `c` (1/m).
    pub fn with_coefficient(&self, c: f64) -> Drag {
        match *self {
            Drag::Quadratic { .. } => Drag::Quadratic { b_per_m: c },
            Drag::SphereCorrelation {
                re_per_speed_s_per_m,
                ..
            } => Drag::SphereCorrelation {
                k_per_m: c,
                re_per_speed_s_per_m,
            },
        }
    }

    /// Drag acceleration (m/s^2) at speed `v_m_per_s` and its derivative d a / d v (1/s).
    pub fn accel_and_slope(&self, v_m_per_s: f64) -> (f64, f64) {
        self.law().accel_and_slope(v_m_per_s)
    }

    /// The quadratic coefficient b (1/m) that matches this law at speed `v`:
    /// for the quadratic law it is b itself.
    pub fn effective_b_per_m(&self, v_m_per_s: f64) -> f64 {
        match *self {
            Drag::Quadratic { b_per_m } => b_per_m,
            Drag::SphereCorrelation { .. } => {
                let s = v_m_per_s.abs().max(1e-9);
                -self.accel_and_slope(s).0 / (s * s)
            }
        }
    }
}

/// Derived constants of one capsule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CapsuleParams {
    /// Magnetic acceleration per unit gradient, m/s^2 per T/m.
    pub g: f64,
    pub drag: Drag,
    /// Moving mass, kg.
    pub mass_kg: f64,
    /// Capsule diameter, m (for the Reynolds number).
    pub diameter_m: f64,
}

/// Derived model of all capsules plus the input bound.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Model {
    pub capsules: Vec<CapsuleParams>,
    pub u_max_t_per_m: f64,
    pub fluid_density_kg_per_m3: f64,
    pub fluid_viscosity_pa_s: f64,
}

impl Model {
    pub fn from_config(config: &Config) -> Model {
        let rho = config.fluid.density_kg_per_m3;
        let mu = config.fluid.dynamic_viscosity_pa_s;
        let capsules = config
            .capsule
            .iter()
            .map(|c| {
                let volume_m3 = 4.0 / 3.0 * PI * c.sphere_radius_m.powi(3);
                let mass_kg = volume_m3 * c.sphere_density_kg_per_m3 + c.shell_mass_kg;
                let area_m2 = PI * c.capsule_radius_m.powi(2);
                let k_per_m = rho * area_m2 / (2.0 * mass_kg);
                let diameter_m = 2.0 * c.capsule_radius_m;
                let drag = match config.drag.law {
                    DragLaw::Quadratic => Drag::Quadratic {
                        b_per_m: c
                            .drag_per_m
                            .unwrap_or(k_per_m * config.drag.drag_coefficient),
                    },
                    DragLaw::SphereCorrelation => Drag::SphereCorrelation {
                        k_per_m: c.drag_per_m.unwrap_or(k_per_m),
                        re_per_speed_s_per_m: rho * diameter_m / mu,
                    },
                };
                CapsuleParams {
                    g: c.gain_m_per_s2_per_t_per_m
                        .unwrap_or(volume_m3 * c.saturation_magnetization_a_per_m / mass_kg),
                    drag,
                    mass_kg,
                    diameter_m,
                }
            })
            .collect();
        Model {
            capsules,
            u_max_t_per_m: config.scanner.max_gradient_t_per_m,
            fluid_density_kg_per_m3: rho,
            fluid_viscosity_pa_s: mu,
        }
    }

    pub fn capsule_count(&self) -> usize {
        self.capsules.len()
    }

    pub fn state_count(&self) -> usize {
        2 * self.capsules.len()
    }

    /// Continuous dynamics x' = f(x, u) + d, written into `dx`.
    pub fn derivative(&self, x: &[f64], u: f64, d: &[f64], dx: &mut [f64]) {
        for (i, c) in self.capsules.iter().enumerate() {
            let v = x[2 * i + 1];
            dx[2 * i] = v + d[2 * i];
            dx[2 * i + 1] = c.drag.accel_and_slope(v).0 + c.g * u + d[2 * i + 1];
        }
    }

    /// Terminal speed (m/s) of capsule `i` under a constant gradient `u`.
    pub fn terminal_speed_m_per_s(&self, i: usize, u: f64) -> f64 {
        let c = &self.capsules[i];
        let target = c.g * u.abs();
        // Drag magnitude grows monotonically with speed: bisect.
        let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
        while -c.drag.accel_and_slope(hi).0 < target && hi < 1e6 {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if -c.drag.accel_and_slope(mid).0 < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Reynolds number of capsule `i` at speed `v`.
    pub fn reynolds(&self, i: usize, v_m_per_s: f64) -> f64 {
        self.fluid_density_kg_per_m3 * v_m_per_s.abs() * self.capsules[i].diameter_m
            / self.fluid_viscosity_pa_s
    }

    /// Lipschitz constant of (4) on the box |v_i| <= speed_bound, as in the
    /// paper: the infinity norm of the Jacobian, `max(1, max_i |da_i/dv|)`.
    pub fn lipschitz_f(&self, speed_bound_m_per_s: f64) -> f64 {
        self.capsules.iter().fold(1.0_f64, |acc, c| {
            acc.max(c.drag.accel_and_slope(speed_bound_m_per_s).1.abs())
        })
    }
}

/// One discrete step of one capsule: new state and Jacobians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CapsuleStep {
    /// [x, v] after the step.
    pub next: [f64; 2],
    /// d next / d [x, v] (row major).
    pub a: [[f64; 2]; 2],
    /// d next / d u.
    pub b: [f64; 2],
}

/// RK4 over `dt_s` in `substeps` equal sub-steps with constant u, and the
/// exact Jacobians of that discrete map (not a finite-difference estimate).
pub fn rk4_capsule(
    c: &CapsuleParams,
    xv: [f64; 2],
    u: f64,
    dt_s: f64,
    substeps: usize,
) -> CapsuleStep {
    let h = dt_s / substeps as f64;
    let mut state = xv;
    let mut a = [[1.0, 0.0], [0.0, 1.0]];
    let mut b = [0.0, 0.0];
    for _ in 0..substeps {
        let s = rk4_capsule_single(c, state, u, h);
        // Chain rule: A_total = A_s A_total, B_total = A_s B_total + B_s.
        let na = mat2_mul(&s.a, &a);
        let nb = [
            s.a[0][0] * b[0] + s.a[0][1] * b[1] + s.b[0],
            s.a[1][0] * b[0] + s.a[1][1] * b[1] + s.b[1],
        ];
        state = s.next;
        a = na;
        b = nb;
    }
    CapsuleStep { next: state, a, b }
}

fn mat2_mul(p: &[[f64; 2]; 2], q: &[[f64; 2]; 2]) -> [[f64; 2]; 2] {
    [
        [
            p[0][0] * q[0][0] + p[0][1] * q[1][0],
            p[0][0] * q[0][1] + p[0][1] * q[1][1],
        ],
        [
            p[1][0] * q[0][0] + p[1][1] * q[1][0],
            p[1][0] * q[0][1] + p[1][1] * q[1][1],
        ],
    ]
}

/// One classical RK4 step with forward sensitivities. Since f = (v, a(v) + g u)
/// does not depend on x, each stage needs only the speed and the drag slope.
fn rk4_capsule_single(c: &CapsuleParams, xv: [f64; 2], u: f64, h: f64) -> CapsuleStep {
    const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
    const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];
    // k = f(stage); dk_dz = d k / d [x0, v0] (2x2); dk_du = d k / d u.
    let mut k_prev = [0.0; 2];
    let mut dk_prev = [[0.0; 2]; 2];
    let mut dku_prev = [0.0; 2];
    let mut next = xv;
    let mut a = [[1.0, 0.0], [0.0, 1.0]];
    let mut b = [0.0; 2];
    for stage in 0..4 {
        let ch = C[stage] * h;
        let v = xv[1] + ch * k_prev[1];
        // d v_stage / d [x0, v0] and / d u.
        let dv = [ch * dk_prev[1][0], 1.0 + ch * dk_prev[1][1]];
        let dvu = ch * dku_prev[1];
        let (acc, slope) = c.drag.accel_and_slope(v);
        let k = [v, acc + c.g * u];
        let dk = [dv, [slope * dv[0], slope * dv[1]]];
        let dku = [dvu, slope * dvu + c.g];
        let wh = W[stage] * h / 6.0;
        for r in 0..2 {
            next[r] += wh * k[r];
            b[r] += wh * dku[r];
            for col in 0..2 {
                a[r][col] += wh * dk[r][col];
            }
        }
        k_prev = k;
        dk_prev = dk;
        dku_prev = dku;
    }
    CapsuleStep { next, a, b }
}

/// Discrete step of the whole state (no Jacobians), used for rollouts.
pub fn rk4_step(model: &Model, x: &[f64], u: f64, dt_s: f64, substeps: usize, out: &mut [f64]) {
    for (i, c) in model.capsules.iter().enumerate() {
        let s = rk4_capsule(c, [x[2 * i], x[2 * i + 1]], u, dt_s, substeps);
        out[2 * i] = s.next[0];
        out[2 * i + 1] = s.next[1];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> Model {
        Model::from_config(&Config::embedded_default())
    }

    #[test]
    fn table_one_constants() {
        let m = paper();
        for c in &m.capsules {
            assert!((c.g - 173.25).abs() / 173.25 < 1e-3, "g = {}", c.g);
        }
        let b: Vec<f64> = m
            .capsules
            .iter()
            .map(|c| c.drag.effective_b_per_m(0.1))
            .collect();
        assert!((b[0] - 134.7).abs() / 134.7 < 1e-3, "b1 = {}", b[0]);
        assert!((b[1] - 16.84).abs() / 16.84 < 1e-3, "b2 = {}", b[1]);
        assert!((m.terminal_speed_m_per_s(0, 0.04) - 0.227).abs() < 1e-3);
        assert!((m.terminal_speed_m_per_s(1, 0.04) - 0.642).abs() < 1e-3);
    }

    #[test]
    fn drag_opposes_velocity() {
        let m = paper();
        let mut dx = [0.0; 4];
        m.derivative(&[0.0, 0.1, 0.0, -0.1], 0.0, &[0.0; 4], &mut dx);
        assert!(dx[1] < 0.0 && dx[3] > 0.0);
    }

    /// The Jacobians are exact derivatives of the discrete map: compare with
    /// central differences at a few states, for both drag laws.
    #[test]
    fn rk4_jacobians_match_finite_differences() {
        let mut cfg = Config::embedded_default();
        for law in [DragLaw::Quadratic, DragLaw::SphereCorrelation] {
            cfg.drag.law = law;
            let m = Model::from_config(&cfg);
            for c in &m.capsules {
                for &(x, v, u) in &[(0.01, 0.12, 0.03), (-0.02, -0.3, -0.04), (0.0, 0.004, 0.01)] {
                    let s = rk4_capsule(c, [x, v], u, 0.02, 3);
                    let eps = 1e-7;
                    for col in 0..2 {
                        let mut p = [x, v];
                        let mut q = [x, v];
                        p[col] += eps;
                        q[col] -= eps;
                        let sp = rk4_capsule(c, p, u, 0.02, 3).next;
                        let sq = rk4_capsule(c, q, u, 0.02, 3).next;
                        for r in 0..2 {
                            let fd = (sp[r] - sq[r]) / (2.0 * eps);
                            assert!(
                                (fd - s.a[r][col]).abs() < 1e-6 * (1.0 + fd.abs()),
                                "{law:?} a[{r}][{col}]"
                            );
                        }
                    }
                    let sp = rk4_capsule(c, [x, v], u + eps, 0.02, 3).next;
                    let sq = rk4_capsule(c, [x, v], u - eps, 0.02, 3).next;
                    for r in 0..2 {
                        let fd = (sp[r] - sq[r]) / (2.0 * eps);
                        assert!(
                            (fd - s.b[r]).abs() < 1e-6 * (1.0 + fd.abs()),
                            "{law:?} b[{r}]"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn sphere_correlation_is_newton_like_at_high_re() {
        let mut cfg = Config::embedded_default();
        cfg.drag.law = DragLaw::SphereCorrelation;
        let m = Model::from_config(&cfg);
        // Re ~ 900 at 0.1 m/s for a 9 mm capsule in water: C_d ~ 0.47-0.5.
        let k = match m.capsules[0].drag {
            Drag::SphereCorrelation { k_per_m, .. } => k_per_m,
            _ => unreachable!(),
        };
        let cd = m.capsules[0].drag.effective_b_per_m(0.1) / k;
        assert!(cd > 0.4 && cd < 0.7, "C_d = {cd}");
    }
}
