//! Offline tables: long-horizon plans from rest over a grid of target-relative
//! positions, and an index over the full relative state (positions and
//! speeds) that names the best stored plan sample to warm-start from.
//!
//! Why plans from rest: at rest the model linearizes to identical double
//! integrators, so a local solver online can never discover a separating
//! manoeuvre; it must be handed one. Every state visited along a stored plan
//! is itself covered by that plan's tail (principle of optimality), so the
//! index over moving states points into the tails.

use crate::config::Config;
use crate::grid::unflatten;
pub use crate::grid::{starting_guesses, Axis, PlanEntry, Progress, Silent};
use crate::index::{build_index, occupied_cells, IndexGrid};
use crate::legs::{build_leg_table, LegTable};
use crate::mintime::{
    arrival_sample, finish_at_rest, grid_min_time_plans, MinTimePlan, RingSearch, FINE_PLAN_BAND,
    FINISH_SAMPLES, PLAN_BAND, SETTLE_BAND,
};
use crate::model::Model;
use crate::ocp::{Ocp, Plan};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// The table file's layout version and magic bytes (see
/// `capsule_mpc_solver::format`).
pub use capsule_mpc_solver::format::{
    FORMAT_VERSION as TABLE_FORMAT_VERSION, MAGIC as TABLE_MAGIC,
};
/// Speed half-range of the warm-start index, m/s (plans peak near 0.35 m/s).
pub const INDEX_SPEED_RANGE_M_PER_S: f64 = 0.4;
/// Speed step of the warm-start index, m/s.
pub const INDEX_SPEED_STEP_M_PER_S: f64 = 0.1;
/// The index covers positions to this multiple of the plan grid's range
/// (plans overshoot their start box on the way).
pub const INDEX_POSITION_MARGIN: f64 = 1.25;

/// First instant (s) after which every state of `states` (one per sample)
/// lies in the settle band.
pub fn settle_time_s(states: &[Vec<f64>], dt_s: f64) -> f64 {
    arrival_sample(states, &SETTLE_BAND).unwrap_or(states.len()) as f64 * dt_s
}

/// Constants of the paper's switching rule (17), computed on X x U.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SwitchingConstants {
    /// Lipschitz constant of the dynamics, max(1, 2 b_i alpha_v).
    pub l_f: f64,
    /// Lipschitz constant of the stage cost on X x U.
    pub l_l: f64,
    /// Lipschitz constant of the terminal cost on X.
    pub l_v: f64,
    /// ||2 alpha||: diameter of X.
    pub x_diameter: f64,
}

/// `magic` and `format_version` must stay the first two fields in every
/// format version (see `crate::table_file`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableHeader {
    pub magic: [u8; 8],
    pub format_version: u32,
    /// SHA-256 of the canonical JSON of the config the tables were made from.
    pub config_hash: [u8; 32],
    pub generator_version: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tables {
    pub header: TableHeader,
    pub plan_steps: usize,
    /// Axis of each relative position in the plan grid.
    pub plan_axis: Axis,
    /// Plans in row-major order over the M position axes.
    pub plans: Vec<PlanEntry>,
    pub index_position_axis: Axis,
    pub index_speed_axis: Axis,
    /// Kept cells of the warm-start index, ascending row-major numbers over
    /// [e1, v1, e2, v2, ...] (see [`crate::index`]).
    pub index_cells: Vec<u64>,
    /// Per kept cell: (plan, step offset).
    pub index: Vec<(u16, u16)>,
    pub switching: SwitchingConstants,
    /// First legs of chained plans over the workspace's displacements.
    pub legs: LegTable,
    /// Plans and index for constant sampling (a coast after every sample).
    pub coasted: CoastedTables,
    /// Small moves from rest near the target (the end game).
    pub fine: FineTables,
}

/// Minimum-time plans from rest over a fine grid of small relative
/// positions (`grid.fine_range_m`, `grid.fine_step_m`), for both schedules: the main
/// grid's nearest plan to a rest state 1-2.5 mm off is the empty one, and
/// the local refinement cannot separate capsules at rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FineTables {
    pub axis: Axis,
    /// Gradients per plan (row-major over the M axes), padded to the plan
    /// length, back to back.
    pub plans: Vec<Vec<f64>>,
    /// The same for one sample per phase followed by the coast.
    pub coasted_plans: Vec<Vec<f64>>,
}

/// Tables for one sample per actuation phase followed by a zero-gradient
/// coast (constant sampling): same grid and index axes as the back-to-back
/// tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoastedTables {
    /// The coast after every sample, s (tracking time + extra delay).
    pub coast_s: f64,
    pub plans: Vec<PlanEntry>,
    /// Per kept cell of `Tables::index_cells`: (plan, step offset).
    pub index: Vec<(u16, u16)>,
}

/// Errors reading a table file.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("table file {path}: {reason}")]
    Io { path: String, reason: String },
    #[error("table file is truncated or corrupted: {0}")]
    Corrupt(String),
    #[error("table file has magic {found:?}, not a capsule-mpc table")]
    Magic { found: [u8; 8] },
    #[error("table file format version {found}, this build reads version {expected}; regenerate")]
    Version { found: u32, expected: u32 },
    #[error("table file is truncated or corrupted: payload SHA-256 is {computed}, the file stores {stored}; regenerate")]
    Checksum { stored: String, computed: String },
    #[error("table file was made from a different config (hash {found}, config hash {expected}); regenerate")]
    ConfigMismatch { found: String, expected: String },
}

/// SHA-256 of the config's canonical JSON.
pub fn config_hash(config: &Config) -> [u8; 32] {
    let json = serde_json::to_vec(config).expect("config serializes");
    Sha256::digest(&json).into()
}

/// SHA-256 of the parts of the config that shape the emitted solver: the
/// config with the simulation-only sections (`disturbance`, `measurement`)
/// at their defaults, the runtime's `controller.refine` (a setting of the
/// runtime, not of the emitted solver) at its default and the Pulseq
/// writer's scanner limits cleared. Two configs with the same solver hash
/// run on the same compiled controller.
pub fn solver_hash(config: &Config) -> [u8; 32] {
    let mut solver = config.clone();
    solver.disturbance = Default::default();
    solver.measurement = Default::default();
    solver.controller.refine = Default::default();
    let s = &mut solver.scanner;
    s.slew_rate_t_per_m_per_s = None;
    s.gradient_raster_s = None;
    s.tracking_rf_duration_s = None;
    s.tracking_adc_duration_s = None;
    config_hash(&solver)
}

pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl Tables {
    /// Number of plans that reach their target (a minimum-time plan was found).
    pub fn reached_count(&self) -> usize {
        self.plans.iter().filter(|p| p.reached).count()
    }
}

/// The four plan sets the tables hold, in the order they are built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlanSet {
    /// Back-to-back samples over the plan grid.
    Main,
    /// One sample, then the tracking coast, over the plan grid.
    Coasted,
    /// Back-to-back samples over the fine grid.
    Fine,
    /// The coasted schedule over the fine grid.
    FineCoasted,
}

impl PlanSet {
    pub const ALL: [PlanSet; 4] = [
        PlanSet::Main,
        PlanSet::Coasted,
        PlanSet::Fine,
        PlanSet::FineCoasted,
    ];
    /// The sets with a warm-start index.
    pub const INDEXED: [PlanSet; 2] = [PlanSet::Main, PlanSet::Coasted];

    pub fn position(self) -> usize {
        self as usize
    }
}

/// Everything the plan sets and indexes are computed from: the problems of
/// both schedules and the grids. Built the same way by the single-process
/// path ([`build_tables`]) and by every shard (`crate::shard`).
pub struct Problems<'a> {
    pub config: &'a Config,
    pub model: &'a Model,
    pub ocp: Ocp<'a>,
    pub coasted_ocp: Ocp<'a>,
    pub axis: Axis,
    pub fine_axis: Axis,
    pub index_position_axis: Axis,
    pub index_speed_axis: Axis,
}

impl<'a> Problems<'a> {
    pub fn new(config: &'a Config, model: &'a Model) -> Problems<'a> {
        let grid = &config.grid;
        let ocp = Ocp::from_config(model, config, config.controller.plan_steps);
        // Constant sampling plays one sample, then tracks (u = 0) for the
        // tracking time + delay: back-to-back plans, played that way, miss
        // their targets by centimetres, so that schedule has plans of its own.
        let coast_s = config.scanner.tracking_time_s + config.scanner.extra_delay_s;
        let coasted_ocp = Ocp {
            coast_s,
            ..ocp.clone()
        };
        Problems {
            config,
            model,
            ocp,
            coasted_ocp,
            axis: Axis::symmetric(grid.position_range_m, grid.position_step_m),
            // The end game: small moves from rest on a fine grid around the target.
            fine_axis: Axis::symmetric(grid.fine_range_m(), grid.fine_step_m()),
            index_position_axis: Axis::symmetric(
                INDEX_POSITION_MARGIN * grid.position_range_m,
                grid.position_step_m,
            ),
            index_speed_axis: Axis::symmetric(INDEX_SPEED_RANGE_M_PER_S, INDEX_SPEED_STEP_M_PER_S),
        }
    }

    pub fn ocp(&self, set: PlanSet) -> &Ocp<'a> {
        match set {
            PlanSet::Main | PlanSet::Fine => &self.ocp,
            PlanSet::Coasted | PlanSet::FineCoasted => &self.coasted_ocp,
        }
    }

    pub fn search(&self, set: PlanSet) -> RingSearch<'_, 'a> {
        let (axis, band) = match set {
            PlanSet::Main | PlanSet::Coasted => (&self.axis, PLAN_BAND),
            PlanSet::Fine | PlanSet::FineCoasted => (&self.fine_axis, FINE_PLAN_BAND),
        };
        RingSearch {
            base: self.ocp(set),
            axis,
            band,
            max_samples: self.ocp.steps,
            random_starts: self.config.grid.starts,
            sqp_iterations: self.config.grid.sqp_iterations,
        }
    }

    /// The stored entry of point `flat` of `set`, from its minimum-time
    /// plan (finished at rest, padded to the plan length, rolled out).
    pub fn plan_entry(&self, set: PlanSet, flat: usize, found: Option<&MinTimePlan>) -> PlanEntry {
        let search = self.search(set);
        let dims = vec![search.axis.count; self.model.capsule_count()];
        let e0: Vec<f64> = unflatten(flat, &dims)
            .iter()
            .flat_map(|&i| [search.axis.value(i), 0.0])
            .collect();
        plan_entry(
            self.ocp(set),
            e0,
            found,
            self.config.grid.sqp_iterations,
            set,
        )
    }

    /// The grid of the warm-start index.
    pub fn index_grid(&self) -> IndexGrid<'_> {
        IndexGrid {
            position: &self.index_position_axis,
            speed: &self.index_speed_axis,
            capsules: self.model.capsule_count(),
        }
    }

    /// The index cells kept for the finished plans of the indexed sets
    /// (in [`PlanSet::INDEXED`] order), ascending.
    pub fn index_cells(&self, indexed: [&[PlanEntry]; 2]) -> Vec<u64> {
        occupied_cells(self.index_grid(), &indexed, self.ocp.steps)
    }

    /// The tables from the four plan sets (in [`PlanSet::ALL`] order), the
    /// kept index cells and the two indexes over them (in
    /// [`PlanSet::INDEXED`] order).
    pub fn assemble(
        &self,
        plan_sets: [Vec<PlanEntry>; 4],
        index_cells: Vec<u64>,
        indexes: [Vec<(u16, u16)>; 2],
    ) -> Tables {
        let config = self.config;
        let m = self.model.capsule_count();
        let [plans, coasted_plans, fine_plans, fine_coasted_plans] = plan_sets;
        let [index, coasted_index] = indexes;
        let inputs = |entries: Vec<PlanEntry>| -> Vec<Vec<f64>> {
            entries.into_iter().map(|p| p.plan.u).collect()
        };
        let legs = build_leg_table(&self.axis, &plans, m, config.workspace.span_m());
        Tables {
            header: TableHeader {
                magic: TABLE_MAGIC,
                format_version: TABLE_FORMAT_VERSION,
                config_hash: config_hash(config),
                generator_version: env!("CARGO_PKG_VERSION").to_string(),
            },
            plan_steps: self.ocp.steps,
            plan_axis: self.axis.clone(),
            plans,
            index_position_axis: self.index_position_axis.clone(),
            index_speed_axis: self.index_speed_axis.clone(),
            index_cells,
            index,
            switching: switching_constants(config, self.model),
            legs,
            coasted: CoastedTables {
                coast_s: self.coasted_ocp.coast_s,
                plans: coasted_plans,
                index: coasted_index,
            },
            fine: FineTables {
                axis: self.fine_axis.clone(),
                plans: inputs(fine_plans),
                coasted_plans: inputs(fine_coasted_plans),
            },
        }
    }
}

/// Solves every grid plan (multi-start, then continuation from neighbours)
/// and builds the warm-start index. Deterministic: same config, same bytes.
/// `crate::shard` computes the same phases split over processes.
pub fn build_tables(config: &Config, progress: &dyn Progress) -> Tables {
    let model = Model::from_config(config);
    let problems = Problems::new(config, &model);
    let plan_sets = PlanSet::ALL.map(|set| schedule_plans(&problems, set, progress));
    let index_cells = problems.index_cells(PlanSet::INDEXED.map(|s| &plan_sets[s.position()][..]));
    let indexes = PlanSet::INDEXED.map(|set| {
        build_index(
            problems.ocp(set),
            &plan_sets[set.position()],
            problems.index_grid(),
            &index_cells,
            progress,
        )
    });
    problems.assemble(plan_sets, index_cells, indexes)
}

/// Minimum-time plans over the grid of `set`, finished at rest and padded
/// with zero gradient to the plan length, with their states and cost
/// under the online cost.
fn schedule_plans(problems: &Problems, set: PlanSet, progress: &dyn Progress) -> Vec<PlanEntry> {
    let s = problems.search(set);
    let min_time = grid_min_time_plans(
        s.base,
        s.axis,
        &s.band,
        s.max_samples,
        s.random_starts,
        s.sqp_iterations,
        progress,
    );
    min_time
        .par_iter()
        .enumerate()
        .map(|(flat, found)| problems.plan_entry(set, flat, found.as_ref()))
        .collect()
}

/// Plans of the main grids that arrive in fewer samples than this are
/// finished with one sample instead of [`FINISH_SAMPLES`]: on the shortest
/// moves (0.16 s) a second finishing sample is an eighth of the move, and
/// the closed loop arrived at speed and overshot in it (reach worst ratio
/// 1.65 -> 1.29 on the 1 cm grid). The end game's fine plans keep two:
/// with one, the end games changed and C under variable sampling settled
/// later on average (1.20 -> 1.24 s).
pub const SHORT_PLAN_SAMPLES: usize = 10;

/// Finishing samples for a plan of `set` that arrives in `arrival_samples`.
pub fn finish_samples(set: PlanSet, arrival_samples: usize) -> usize {
    match set {
        PlanSet::Main | PlanSet::Coasted if arrival_samples < SHORT_PLAN_SAMPLES => 1,
        _ => FINISH_SAMPLES,
    }
}

/// The stored entry of `set` for a start at rest at `e0` from its
/// minimum-time plan `found` (None: not reached).
fn plan_entry(
    ocp: &Ocp,
    e0: Vec<f64>,
    found: Option<&MinTimePlan>,
    sqp_iterations: usize,
    set: PlanSet,
) -> PlanEntry {
    let steps = ocp.steps;
    // Wall time per plan sample: the sample and the coast after it.
    let sample_period_s = ocp.dt_s + ocp.coast_s;
    let (reached, samples, arrival_states, mut u) = match found {
        Some(p) => {
            let (states, _) = ocp.rollout(&e0, &p.u);
            let finish = finish_samples(set, p.samples);
            let u = finish_at_rest(ocp, &e0, p, steps, sqp_iterations, finish);
            (true, p.samples, states, u)
        }
        None => (false, 0, Vec::new(), Vec::new()),
    };
    u.resize(steps, 0.0);
    let (states, cost) = ocp.rollout(&e0, &u);
    // The bound is the minimum-time plan's own arrival, before the
    // finishing samples.
    let min_time_s = match reached {
        true => settle_time_s(&arrival_states, sample_period_s),
        false => f64::INFINITY,
    };
    PlanEntry {
        e0,
        plan: Plan {
            u,
            states,
            cost,
            iterations: 0,
        },
        reached,
        arrival_samples: samples,
        min_time_s,
    }
}

/// L_f, L_l, L_v of section III on X x U (in the cost's units, SI here).
pub fn switching_constants(config: &Config, model: &Model) -> SwitchingConstants {
    let c = &config.controller;
    let w = crate::ocp::OcpWeights::from_config(config);
    let alpha: Vec<f64> = (0..model.state_count())
        .map(|j| {
            if j % 2 == 0 {
                c.position_bound_m
            } else {
                c.speed_bound_m_per_s
            }
        })
        .collect();
    // |grad L| = ||(2 Q alpha, 2 R u_max)||, |grad V| = ||2 P alpha||.
    let l_l = (alpha
        .iter()
        .zip(&w.q)
        .map(|(a, q)| (2.0 * q * a).powi(2))
        .sum::<f64>()
        + (2.0 * w.r * model.u_max_t_per_m).powi(2))
    .sqrt();
    let l_v = alpha
        .iter()
        .zip(&w.p)
        .map(|(a, p)| (2.0 * p * a).powi(2))
        .sum::<f64>()
        .sqrt();
    SwitchingConstants {
        l_f: model.lipschitz_f(c.speed_bound_m_per_s),
        l_l,
        l_v,
        x_diameter: alpha.iter().map(|a| (2.0 * a).powi(2)).sum::<f64>().sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_nearest_and_bounds() {
        let a = Axis::symmetric(0.04, 0.005);
        assert_eq!(a.count, 17);
        assert_eq!(a.nearest(0.0), Some(8));
        assert_eq!(a.nearest(0.0399), Some(16));
        assert_eq!(a.nearest(0.05), None);
        assert!((a.value(0) + 0.04).abs() < 1e-15);
    }
}
