//! The config's model and weights, against the generated spec's.
//!
//! The peers run inside the generated solver itself (see
//! [`engine`](crate::bench::engine)), on the spec's constants; what is
//! left of the former plain-Rust reference loop is this check that the
//! embedded config and the generated module agree (`bench` warns when they
//! do not, and reports the difference in the JSON).

use anyhow::{bail, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::{CapsuleParams, Model};
use capsule_mpc_generator::ocp::OcpWeights;
use capsule_mpc_runtime::generated::controller::spec;
use spec::{M, NX};

/// Model and weights read from the config (not from the generated spec).
#[derive(Debug, Clone)]
pub struct RefProblem {
    pub capsules: Vec<CapsuleParams>,
    pub q: [f64; NX],
    pub r: f64,
    pub p: [f64; NX],
    pub dt_s: f64,
    pub substeps: usize,
    pub u_max: f64,
}

impl RefProblem {
    pub fn from_config(config: &Config) -> Result<RefProblem> {
        let model = Model::from_config(config);
        let w = OcpWeights::from_config(config);
        if model.capsules.len() != M || w.q.len() != NX || w.p.len() != NX {
            bail!(
                "the config has {} capsules but the generated solver was built for {M}",
                model.capsules.len()
            );
        }
        let mut q = [0.0; NX];
        let mut p = [0.0; NX];
        q.copy_from_slice(&w.q);
        p.copy_from_slice(&w.p);
        Ok(RefProblem {
            capsules: model.capsules,
            q,
            r: w.r,
            p,
            dt_s: config.controller.sample_time_s,
            substeps: config.controller.rk4_substeps,
            u_max: model.u_max_t_per_m,
        })
    }

    /// Largest relative difference to the generated spec's constants.
    pub fn spec_mismatch(&self) -> f64 {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-300);
        let mut worst = rel(self.r, spec::R).max(rel(self.dt_s, spec::DT_S));
        worst = worst.max(rel(self.u_max, spec::U_MAX_T_PER_M));
        worst = worst.max(if self.substeps == spec::RK4_SUBSTEPS {
            0.0
        } else {
            1.0
        });
        for j in 0..NX {
            worst = worst
                .max(rel(self.q[j], spec::Q[j]))
                .max(rel(self.p[j], spec::P[j]));
        }
        for i in 0..M {
            worst = worst.max(rel(self.capsules[i].g, spec::G[i]));
            let (a_ref, _) = self.capsules[i].drag.accel_and_slope(0.1);
            worst = worst.max(rel(a_ref, spec::drag(i, 0.1).0));
        }
        worst
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_config_matches_the_generated_spec() {
        let problem = RefProblem::from_config(&Config::embedded_default()).unwrap();
        assert!(
            problem.spec_mismatch() <= 1e-9,
            "{}",
            problem.spec_mismatch()
        );
    }
}
