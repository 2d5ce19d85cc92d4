//! The benchmark states: closed-loop states of scenarios A and C, the rest
//! uniform over the admissible region's kept index cells.

use anyhow::{Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_runtime::generated::controller::{spec, TABLES};
use capsule_mpc_runtime::solver::{lookup, Tables};
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
        closed.extend(
            sample_instants::<NX>(&report.t, &report.x, &target, spec::DT_S)
                .into_iter()
                .map(|e| BenchState { e, origin }),
        );
    }
    let mut states: Vec<BenchState> = if closed.len() > n {
        (0..n).map(|i| closed[i * closed.len() / n]).collect()
    } else {
        closed
    };
    let uniform = uniform_in_kept_cells::<NX>(&TABLES, n.saturating_sub(states.len()), seed);
    states.extend(uniform.into_iter().map(|e| BenchState {
        e,
        origin: Origin::Uniform,
    }));
    Ok(states)
}

/// The states of a closed-loop run at its sample instants (one row per
/// multiple of `dt_s`), relative to `target`.
pub fn sample_instants<const NX: usize>(
    t: &[f64],
    x: &[Vec<f64>],
    target: &[f64],
    dt_s: f64,
) -> Vec<[f64; NX]> {
    let mut out = Vec::new();
    let mut last = None;
    for (t, x) in t.iter().zip(x) {
        let k = (t / dt_s).round();
        if (t - k * dt_s).abs() > 1e-9 || last == Some(k) {
            continue;
        }
        last = Some(k);
        let mut e = [0.0; NX];
        for (ej, (xj, tj)) in e.iter_mut().zip(x.iter().zip(target)) {
            *ej = xj - tj;
        }
        out.push(e);
    }
    out
}

/// `n` states drawn uniformly (seeded): each relative position over the
/// warm-start index range, each speed in +-`SAMPLED_SPEED_M_PER_S`, kept
/// when they fall in a kept cell of the sparse index (the others have no
/// stored plan and go to the runtime's fallback, not to the solver).
pub fn uniform_in_kept_cells<const NX: usize>(
    tables: &Tables,
    n: usize,
    seed: u64,
) -> Vec<[f64; NX]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = tables.index_position_axis;
    let (p_lo, p_hi) = (axis.start, axis.start + (axis.count - 1) as f64 * axis.step);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let mut e = [0.0; NX];
        for (j, ej) in e.iter_mut().enumerate() {
            *ej = if j % 2 == 0 {
                rng.gen_range(p_lo..=p_hi)
            } else {
                rng.gen_range(-SAMPLED_SPEED_M_PER_S..=SAMPLED_SPEED_M_PER_S)
            };
        }
        if lookup::index_cell(tables, &e).is_some() {
            out.push(e);
        }
    }
    out
}
