//! The benchmark states: closed-loop states of scenarios A and C, the rest
//! uniform over the admissible region's kept index cells.

use anyhow::{Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_runtime::generated::controller::{spec, TABLES};
use capsule_mpc_runtime::solver::lookup;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling, Scenario};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spec::NX;

/// Speed range of the uniformly drawn states, m/s.
pub const SAMPLED_SPEED_M_PER_S: f64 = 0.3;
/// Closed-loop runs that contribute states (ideal sampling).
pub const CLOSED_LOOP_SECONDS: f64 = 3.0;

/// Where a benchmark state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    Uniform,
    ClosedLoopA,
    ClosedLoopC,
}

impl Origin {
    pub fn name(self) -> &'static str {
        match self {
            Origin::Uniform => "uniform",
            Origin::ClosedLoopA => "closed-loop-A",
            Origin::ClosedLoopC => "closed-loop-C",
        }
    }
}

/// One benchmark state, relative to the target (SI).
#[derive(Debug, Clone, Copy)]
pub struct BenchState {
    pub e: [f64; NX],
    pub origin: Origin,
}

/// `n` states: every closed-loop state of scenarios A and C (at most `n`),
/// the rest uniform over the admissible region's kept index cells.
pub fn sample_states(config: &Config, n: usize, seed: u64) -> Result<Vec<BenchState>> {
    let mut closed = Vec::new();
    for (scenario, origin) in [
        (Scenario::A, Origin::ClosedLoopA),
        (Scenario::C, Origin::ClosedLoopC),
    ] {
        let target = scenario.target_state();
        let mut opts = RunOptions::new(config, target.clone(), Sampling::Ideal);
        opts.duration_s = CLOSED_LOOP_SECONDS;
        let report = run(config, &opts)
            .with_context(|| format!("closed-loop run of scenario {}", scenario.name()))?;
        let mut last = None;
        for (t, x) in report.t.iter().zip(&report.x) {
            let k = (t / spec::DT_S).round();
            if (t - k * spec::DT_S).abs() > 1e-9 || last == Some(k) {
                continue;
            }
            last = Some(k);
            let mut e = [0.0; NX];
            for j in 0..NX {
                e[j] = x[j] - target[j];
            }
            closed.push(BenchState { e, origin });
        }
    }
    let mut states: Vec<BenchState> = if closed.len() > n {
        (0..n).map(|i| closed[i * closed.len() / n]).collect()
    } else {
        closed
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = TABLES.index_position_axis;
    let (p_lo, p_hi) = (axis.start, axis.start + (axis.count - 1) as f64 * axis.step);
    while states.len() < n {
        let mut e = [0.0; NX];
        for j in 0..NX {
            e[j] = if j % 2 == 0 {
                rng.gen_range(p_lo..=p_hi)
            } else {
                rng.gen_range(-SAMPLED_SPEED_M_PER_S..=SAMPLED_SPEED_M_PER_S)
            };
        }
        // Only states in a kept cell of the sparse warm-start index: the
        // others have no stored plan and go to the runtime's fallback, not
        // to the solver being timed.
        if lookup::index_cell(&TABLES, &e).is_none() {
            continue;
        }
        states.push(BenchState {
            e,
            origin: Origin::Uniform,
        });
    }
    Ok(states)
}
