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
    /// Largest eigenvalue of the stage weight (max Q_jj).
    pub q_max: f64,
    /// Growth factor per sample of a state error (infinity norm of the
    /// sampled Jacobian, max over the plan).
    pub growth_per_sample: f64,
    /// Current estimation error bound (3 sigma of the estimator), SI norm.
    pub estimate_error: f64,
    /// Disturbance bound gamma, SI.
    pub gamma: f64,
    pub dt_s: f64,
    pub sigma: f64,
}

/// Tighter rule: the prediction error after n samples is bounded by
/// `delta_n = rho^n (eps0 + gamma n dt)` (discrete Gronwall with the local
/// growth rho measured on the plan, instead of L_f on all of X), and the
/// cost mismatch for k >= n by `|grad L(e_k)| delta_n + q_max delta_n^2`
/// (exact for a quadratic L), instead of the global L_l. Actuate while the
/// summed mismatch over the rest of the prediction stays below sigma times
/// the cost already earned: the same decrease (18) with honest local
/// constants. Returns n in 1..=n_max.
pub fn tight_actuation_samples(inp: &TightInputs, n_max: usize) -> usize {
    let len = inp.stage_costs.len().min(inp.cost_gradients.len());
    let mut earned = 0.0;
    let mut best = 1;
    let mut rho_n = 1.0;
    for n in 1..=n_max.min(len) {
        earned += inp.stage_costs[n - 1];
        rho_n *= inp.growth_per_sample;
        let delta = rho_n * (inp.estimate_error + inp.gamma * n as f64 * inp.dt_s);
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

    #[test]
    fn tight_rule_extends_when_far_and_shortens_when_close() {
        let far = [1.0; 10];
        let grads = [1.0; 10];
        let inp = TightInputs {
            stage_costs: &far,
            cost_gradients: &grads,
            q_max: 1.0,
            growth_per_sample: 1.01,
            estimate_error: 1e-3,
            gamma: 1e-3,
            dt_s: 0.02,
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
}
