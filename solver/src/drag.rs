//! The drag laws, written once: the generator solves its tables with them
//! and the online solver rolls plans out with them.

/// Drag acceleration law of one capsule (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DragLaw {
    /// a = -b v|v|, b in 1/m.
    Quadratic { b_per_m: f64 },
    /// a = -k C_d(Re) v|v| with Re = c |v| (Clift-Gauvin correlation),
    /// k = rho A / (2 m) in 1/m, c = rho D / mu in s/m.
    SphereCorrelation {
        k_per_m: f64,
        re_per_speed_s_per_m: f64,
    },
}

/// Exponent of the Clift-Gauvin correction term, Re^0.687, and one more
/// (written out: 1.0 + 0.687 is not the literal 1.687 in binary).
const CG_EXPONENT: f64 = 0.687;
const CG_EXPONENT_PLUS_ONE: f64 = 1.687;
/// Coefficient of that term.
const CG_COEFFICIENT: f64 = 0.15;
/// Newton-regime drag coefficient of the correlation.
const CG_NEWTON_CD: f64 = 0.42;
/// Transition constant and exponent of the Newton term, 42500 Re^-1.16.
const CG_TRANSITION: f64 = 42500.0;
const CG_TRANSITION_EXPONENT: f64 = 1.16;
/// Stokes drag coefficient times Re.
const STOKES_CD_RE: f64 = 24.0;

impl DragLaw {
    /// The law with its coefficient times `factor` (1: the law itself, bit
    /// for bit).
    #[inline(always)]
    pub fn scaled(self, factor: f64) -> DragLaw {
        match self {
            DragLaw::Quadratic { b_per_m } => DragLaw::Quadratic {
                b_per_m: b_per_m * factor,
            },
            DragLaw::SphereCorrelation {
                k_per_m,
                re_per_speed_s_per_m,
            } => DragLaw::SphereCorrelation {
                k_per_m: k_per_m * factor,
                re_per_speed_s_per_m,
            },
        }
    }

    /// Drag acceleration (m/s^2) at speed `v_m_per_s` and its slope
    /// d a / d v (1/s). Finite at v = 0 for both laws.
    #[inline]
    pub fn accel_and_slope(&self, v: f64) -> (f64, f64) {
        match *self {
            DragLaw::Quadratic { b_per_m: b } => {
                let s = v.abs();
                (-b * v * s, -2.0 * b * s)
            }
            DragLaw::SphereCorrelation {
                k_per_m: k,
                re_per_speed_s_per_m: c,
            } => {
                let s = v.abs();
                let sign = if v < 0.0 { -1.0 } else { 1.0 };
                // h(s) = C_d(c s) s^2, the Stokes part linear in s.
                let cp = libm::pow(c, CG_EXPONENT);
                let t1 = STOKES_CD_RE / c
                    * (s + CG_COEFFICIENT * cp * libm::pow(s, CG_EXPONENT_PLUS_ONE));
                let dt1 = STOKES_CD_RE / c
                    * (1.0
                        + CG_COEFFICIENT * CG_EXPONENT_PLUS_ONE * cp * libm::pow(s, CG_EXPONENT));
                let (t2, dt2) = if s > 0.0 {
                    let w = CG_TRANSITION * libm::pow(c * s, -CG_TRANSITION_EXPONENT);
                    (
                        CG_NEWTON_CD * s * s / (1.0 + w),
                        CG_NEWTON_CD * (2.0 * s * (1.0 + w) + CG_TRANSITION_EXPONENT * s * w)
                            / ((1.0 + w) * (1.0 + w)),
                    )
                } else {
                    (0.0, 0.0)
                };
                (-k * sign * (t1 + t2), -k * (dt1 + dt2))
            }
        }
    }
}
