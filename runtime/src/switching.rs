//! When to stop actuating and track again: condition (17) of the paper, and
//! a tighter variant with local bounds.
//!
//! Both answer: after a measurement at k_i, for how many samples n (1..=N)
//! may the plan run open loop so that the value function still decreases,
//! `J*(t) - J*(k_i) <= (sigma - 1) * integral L` (18)? The cost is the
//! per-sample sum `sum_k L_k`, read as the integral of `L_k / dt`.

/// Worst-case constants of section III (from the generator).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperConstants {
    pub l_f: f64,
    pub l_l: f64,
    pub l_v: f64,
    /// ||2 alpha||.
    pub x_diameter: f64,
    /// gamma: bound on the disturbance, SI.
    pub gamma: f64,
    pub sigma: f64,
}

impl PaperConstants {
    /// beta = L_f ||2 alpha|| + gamma (Lemma 1).
    pub fn beta(&self) -> f64 {
        self.l_f * self.x_diameter + self.gamma
    }

    /// Condition (17) at `t_s` after the measurement for horizon `horizon_s`,
    /// given the predicted cost integral up to `t_s`.
    pub fn holds(&self, t_s: f64, horizon_s: f64, cost_integral: f64) -> bool {
        let beta = self.beta();
        let lhs = self.l_l * beta * t_s * (horizon_s - t_s) + self.l_v * beta * t_s;
        lhs <= self.sigma * cost_integral
    }
}

/// Largest n in 1..=n_max for which (17) holds at every sample end up to n.
/// `stage_costs[k]` is L_k of the predicted plan (per sample).
pub fn paper_actuation_samples(
    c: &PaperConstants,
    stage_costs: &[f64],
    dt_s: f64,
    horizon_s: f64,
) -> usize {
    let mut integral = 0.0;
    let mut n = 1;
    for (k, l) in stage_costs.iter().enumerate() {
        integral += l;
        let t = (k + 1) as f64 * dt_s;
        if !c.holds(t, horizon_s, integral) {
            break;
        }
        n = k + 1;
    }
    n.max(1)
}

/// The tighter rule's inputs along the predicted plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TightInputs<'a> {
    /// Predicted stage costs L_k, k = 0..len.
    pub stage_costs: &'a [f64],
    /// ||grad L(e_k)|| = ||2 Q e_k|| along the prediction.
    pub cost_gradients: &'a [f64],
    /// `extra_deviation[n - 1]`: bound on how much farther the true state
    /// is from the prediction after n open-loop samples than it is at the
    /// measurement (see [`extra_deviation_bound`]), SI norm.
    pub extra_deviation: &'a [f64],
    /// Largest eigenvalue of the stage weight (max Q_jj).
    pub q_max: f64,
    pub sigma: f64,
}

/// Per-capsule interval bound on the prediction error: starting from the
/// estimate's box `(dx0, dv0)` (3 sigma), each sample maps it through the
/// element-wise absolute sampled Jacobian and adds the disturbance
/// `gamma * dt` on both components. Returns the new box. This bounds the
/// linearized error exactly (triangle inequality per component).
pub fn propagate_error_box(a: &[f64; 4], box_xv: [f64; 2], gamma_dt: f64) -> [f64; 2] {
    [
        libm::fabs(a[0]) * box_xv[0] + libm::fabs(a[1]) * box_xv[1] + gamma_dt,
        libm::fabs(a[2]) * box_xv[0] + libm::fabs(a[3]) * box_xv[1] + gamma_dt,
    ]
}

/// Widens an error box `(dx, dv)` by an acceleration error
/// `accel_m_per_s2` held over `dt_s` (the model's own error, which the
/// disturbance bound does not cover).
pub fn widen_error_box(box_xv: [f64; 2], accel_m_per_s2: f64, dt_s: f64) -> [f64; 2] {
    let a = libm::fabs(accel_m_per_s2);
    [box_xv[0] + 0.5 * a * dt_s * dt_s, box_xv[1] + a * dt_s]
}

/// Extra deviation after n samples: the part of the propagated error box
/// that exceeds the box at the measurement (component-wise, >= 0), as a
/// Euclidean norm over all capsules. Tracking now would reset the error to
/// the estimate's box; actuating longer lets the speed error integrate into
/// position and the disturbance accumulate. That growth, not the estimate's
/// own error (present whatever n is), is what open-loop actuation costs.
pub fn extra_deviation_bound(now: &[[f64; 2]], start: &[[f64; 2]]) -> f64 {
    let mut s2 = 0.0;
    for (b, b0) in now.iter().zip(start) {
        for c in 0..2 {
            let d = (b[c] - b0[c]).max(0.0);
            s2 += d * d;
        }
    }
    libm::sqrt(s2)
}

/// Tighter rule: actuate n samples while the cost the extra deviation
/// `delta_n` can add to the rest of the plan stays below sigma times the
/// cost already earned: for a quadratic L, |L(e + d) - L(e)| <=
/// ||grad L(e)|| ||d|| + q_max ||d||^2, summed over k >= n. This is the
/// decrease (18) with local constants measured on the plan (instead of
/// L_l, L_v and L_f over all of X x U) and the estimator's actual error
/// instead of the diameter of X. Returns n in 1..=n_max.
pub fn tight_actuation_samples(inp: &TightInputs, n_max: usize) -> usize {
    let len = inp
        .stage_costs
        .len()
        .min(inp.cost_gradients.len())
        .min(inp.extra_deviation.len());
    let mut earned = 0.0;
    let mut best = 1;
    for n in 1..=n_max.min(len) {
        earned += inp.stage_costs[n - 1];
        let delta = inp.extra_deviation[n - 1];
        let mut mismatch = 0.0;
        for k in n..len {
            mismatch += inp.cost_gradients[k] * delta + inp.q_max * delta * delta;
        }
        if mismatch > inp.sigma * earned {
            break;
        }
        best = n;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed: L_l = 2, L_v = 1, L_f = 1, ||2a|| = 1, gamma = 0 ->
    /// beta = 1; T = 1, t = 0.5: lhs = 2 * 0.5 * 0.5 + 0.5 = 1.0.
    #[test]
    fn paper_condition_matches_hand_computation() {
        let c = PaperConstants {
            l_f: 1.0,
            l_l: 2.0,
            l_v: 1.0,
            x_diameter: 1.0,
            gamma: 0.0,
            sigma: 0.5,
        };
        assert_eq!(c.beta(), 1.0);
        assert!(c.holds(0.5, 1.0, 2.0)); // 1.0 <= 0.5 * 2.0
        assert!(!c.holds(0.5, 1.0, 1.99)); // 1.0 > 0.995
    }

    #[test]
    fn paper_rule_picks_the_last_sample_that_holds() {
        let c = PaperConstants {
            l_f: 1.0,
            l_l: 1.0,
            l_v: 0.0,
            x_diameter: 1.0,
            gamma: 0.0,
            sigma: 1.0,
        };
        // T = 1, dt = 0.25: lhs(t) = t (1 - t) = 0.1875, 0.25, 0.1875, 0.
        // Integrals 0.2, 0.2, ... : holds at t = 0.25 only.
        let n = paper_actuation_samples(&c, &[0.2, 0.0, 0.0, 0.0], 0.25, 1.0);
        assert_eq!(n, 1);
        let n = paper_actuation_samples(&c, &[0.2, 0.1, 0.0, 0.0], 0.25, 1.0);
        assert_eq!(n, 4);
    }

    /// The model's error held over a sample widens the box by a v t and
    /// a t^2 / 2, and a box that grows faster shortens the tight rule's
    /// phase on the same plan.
    #[test]
    fn the_models_error_widens_the_box_and_shortens_the_phase() {
        let b = widen_error_box([1e-4, 1e-3], -0.5, 0.02);
        assert!((b[0] - (1e-4 + 0.5 * 0.5 * 4e-4)).abs() < 1e-15, "{b:?}");
        assert!((b[1] - (1e-3 + 0.5 * 0.02)).abs() < 1e-15, "{b:?}");
        let a = [1.0, 0.02, 0.0, 1.0];
        let start = [[1e-4, 1e-3]];
        let deviation = |accel: f64| -> [f64; 10] {
            let mut bx = start;
            core::array::from_fn(|_| {
                bx[0] = widen_error_box(propagate_error_box(&a, bx[0], 1e-5), accel, 0.02);
                extra_deviation_bound(&bx, &start)
            })
        };
        let costs = [1e-3; 10];
        let grads = [0.1; 10];
        let (model, off) = (deviation(0.0), deviation(0.5));
        let phase = |d: &[f64; 10]| {
            tight_actuation_samples(
                &TightInputs {
                    stage_costs: &costs,
                    cost_gradients: &grads,
                    extra_deviation: d,
                    q_max: 1.0,
                    sigma: 0.9,
                },
                10,
            )
        };
        assert!(
            phase(&off) < phase(&model),
            "{} vs {}",
            phase(&off),
            phase(&model)
        );
    }

    #[test]
    fn tight_rule_extends_when_far_and_shortens_when_close() {
        let far = [1.0; 10];
        let grads = [1.0; 10];
        let deviation: [f64; 10] = core::array::from_fn(|n| 1e-3 * (n + 1) as f64);
        let inp = TightInputs {
            stage_costs: &far,
            cost_gradients: &grads,
            extra_deviation: &deviation,
            q_max: 1.0,
            sigma: 0.5,
        };
        assert_eq!(tight_actuation_samples(&inp, 10), 10);
        let near = [1e-6; 10];
        let inp = TightInputs {
            stage_costs: &near,
            ..inp
        };
        assert_eq!(tight_actuation_samples(&inp, 10), 1);
    }

    /// Hand-computed: costs 1, 1, 1; gradients 1; deviations 0.1, 0.3, 1;
    /// q_max 0; sigma 0.5. n = 1: mismatch 2 * 0.1 = 0.2 <= 0.5;
    /// n = 2: 1 * 0.3 = 0.3 <= 1.0; n = 3: nothing left, 0 <= 1.5 -> 3.
    /// With deviations 0.1, 1.5: n = 2 gives 1.5 > 1.0 -> 1.
    #[test]
    fn tight_rule_matches_hand_computation() {
        let inp = TightInputs {
            stage_costs: &[1.0, 1.0, 1.0],
            cost_gradients: &[1.0, 1.0, 1.0],
            extra_deviation: &[0.1, 0.3, 1.0],
            q_max: 0.0,
            sigma: 0.5,
        };
        assert_eq!(tight_actuation_samples(&inp, 3), 3);
        assert_eq!(tight_actuation_samples(&inp, 2), 2);
        let inp = TightInputs {
            extra_deviation: &[0.1, 1.5, 1.5],
            ..inp
        };
        assert_eq!(tight_actuation_samples(&inp, 3), 1);
    }

    #[test]
    fn error_box_grows_by_speed_error_times_time() {
        // A double integrator sample of 0.02 s: x error grows by dv * dt.
        let a = [1.0, 0.02, 0.0, 1.0];
        let b = propagate_error_box(&a, [1e-4, 3e-3], 0.0);
        assert!((b[0] - (1e-4 + 0.02 * 3e-3)).abs() < 1e-15);
        assert_eq!(b[1], 3e-3);
        let extra = extra_deviation_bound(&[b], &[[1e-4, 3e-3]]);
        assert!((extra - 6e-5).abs() < 1e-15);
    }
}
