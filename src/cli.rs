//! Command-line arguments of `capsule-mpc`, as plain structs so that the
//! modules implementing each subcommand can take them without clap plumbing.

use anyhow::{bail, Result};
use capsule_mpc_generator::config::{Config, ConfigError, DisturbanceKind};
use capsule_mpc_generator::generate::ControllerModule;
use capsule_mpc_sim::closed_loop::{Preset, Sampling, Scenario};
use capsule_mpc_sim::plant::DisturbanceLevel;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Parser)]
#[command(
    name = "capsule-mpc",
    version,
    about = "MPC steering of several magnetic capsules with one shared MRI gradient"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Clone, Subcommand)]
pub enum Command {
    /// Print the derived model constants and the config as understood.
    Inspect(InspectArgs),
    /// Run one closed-loop simulation.
    Simulate(SimulateArgs),
    /// Solve the offline tables and emit the fixed-size solver crate.
    Generate(GenerateArgs),
    /// Time the online solver on random states.
    Bench(BenchArgs),
    /// Produce the figures of the report.
    Figures(FiguresArgs),
    /// Run the closed loop to every target of a grid: the reach map.
    Reach(ReachArgs),
    /// Fit each capsule's gain and drag to a tracking log (or, with
    /// --design, write the excitation that identifies them).
    Calibrate(CalibrateArgs),
}

#[derive(Debug, Clone, Args)]
pub struct CalibrateArgs {
    /// Tracking log: CSV `t_s,gradient_t_per_m,x1_m,...` (docs/calibrate.md)
    /// or the run JSON of `simulate --json`.
    #[arg(
        long,
        value_name = "FILE",
        required_unless_present = "design",
        conflicts_with = "design"
    )]
    pub log: Option<PathBuf>,
    /// Base config (TOML); the embedded paper config when absent.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Write the base config with the fitted gain and drag of every
    /// capsule as overrides (`generate --config` takes it as it is).
    #[arg(long, value_name = "FITTED.toml")]
    pub out: Option<PathBuf>,
    /// Write the fit (SI, with standard errors, 95 % intervals, residuals
    /// and warnings) as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Draw the measured positions against the fitted model (calibration.svg/.png) here.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// With --design: play the excitation on the plant simulator (the
    /// config's capsules, off the model by --plant-drag-scale and
    /// --plant-gain-scale, the config's tracking noise) and write the
    /// measured positions into the CSV: a log to try `calibrate` on.
    #[arg(long, requires = "design")]
    pub play: bool,
    /// The simulated plant's drag and gain as factors of the model's (with --play).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "S1,S2,...",
        requires = "play"
    )]
    pub plant_drag_scale: Option<Vec<f64>>,
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "S1,S2,...",
        requires = "play"
    )]
    pub plant_gain_scale: Option<Vec<f64>>,
    /// Seed of the simulated tracking noise (with --play).
    #[arg(long, default_value_t = 1, requires = "play")]
    pub seed: u64,
    /// Fewest measurements a capsule must have in the log.
    #[arg(long, default_value_t = 20, value_name = "N")]
    pub min_measurements: usize,
    /// Design an excitation instead of fitting.
    #[arg(long)]
    pub design: bool,
    /// Length of the designed excitation, s.
    #[arg(long, default_value_t = 10.0, value_parser = positive_seconds, requires = "design")]
    pub duration: f64,
    /// Write the designed excitation as a log CSV (positions empty: the
    /// scanner measures them).
    #[arg(long, value_name = "FILE", requires = "design")]
    pub csv: Option<PathBuf>,
    /// Write the designed excitation as a Pulseq sequence.
    #[arg(long, value_name = "FILE.seq", requires = "design")]
    pub pulseq: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct InspectArgs {
    /// Config file (TOML); the embedded paper config when absent.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Reference scenario on the command line (see [`Scenario`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ScenarioArg {
    /// Both capsules the same way: (2 cm, 0, 3 cm, 0).
    #[value(name = "A", alias = "a")]
    A,
    /// Opposite ways: (2 cm, 0, -1 cm, 0).
    #[value(name = "C", alias = "c")]
    C,
}

impl From<ScenarioArg> for Scenario {
    fn from(s: ScenarioArg) -> Self {
        match s {
            ScenarioArg::A => Scenario::A,
            ScenarioArg::C => Scenario::C,
        }
    }
}

/// Sampling mode on the command line (see [`Sampling`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SamplingArg {
    /// Exact state every sample, no tracking time (an upper bound on quality).
    Ideal,
    /// Track, then actuate for a fixed time, every period.
    Constant,
    /// Actuate until the switching rule asks for a new measurement.
    Variable,
}

impl From<SamplingArg> for Sampling {
    fn from(s: SamplingArg) -> Self {
        match s {
            SamplingArg::Ideal => Sampling::Ideal,
            SamplingArg::Constant => Sampling::Constant,
            SamplingArg::Variable => Sampling::Variable,
        }
    }
}

/// Disturbance level on the command line (see [`DisturbanceLevel`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DisturbanceArg {
    /// No disturbance.
    None,
    /// The paper's ||d|| <= 0.05 (cm units), random.
    Paper,
    /// 5 % of the first capsule's full magnetic acceleration, random.
    Stress,
}

impl From<DisturbanceArg> for DisturbanceLevel {
    fn from(d: DisturbanceArg) -> Self {
        match d {
            DisturbanceArg::None => DisturbanceLevel::None,
            DisturbanceArg::Paper => DisturbanceLevel::Paper,
            DisturbanceArg::Stress => DisturbanceLevel::Stress,
        }
    }
}

/// Disturbance model on the command line: how a disturbance of the
/// `--disturbance` size varies in time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DisturbanceModelArg {
    /// Piecewise constant, redrawn every 20 ms, uniform in the ball.
    Random,
    /// Slowly varying: sums of sinusoids with periods of 1-5 s.
    Drift,
    /// A constant bias of norm equal to the bound.
    Constant,
}

impl From<DisturbanceModelArg> for DisturbanceKind {
    fn from(d: DisturbanceModelArg) -> Self {
        match d {
            DisturbanceModelArg::Random => DisturbanceKind::Random,
            DisturbanceModelArg::Drift => DisturbanceKind::Drift,
            DisturbanceModelArg::Constant => DisturbanceKind::Constant,
        }
    }
}

/// Generated controller on the command line (see [`Preset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PresetArg {
    /// Offline plan tables + online refinement (the product).
    Default,
    /// The paper's NMPC taken literally (N = 10, Table I weights).
    Paper,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Self {
        match p {
            PresetArg::Default => Preset::Default,
            PresetArg::Paper => Preset::Paper,
        }
    }
}

/// How the simulated capsules differ from the model, and what the
/// controller is told of them (`simulate`, `reach`).
#[derive(Args, Debug, Clone)]
pub struct PlantArgs {
    /// The simulated capsules' drag as a factor of the model's: one for all
    /// or one per capsule (S1,S2,...); the controller keeps the model.
    #[arg(long, value_delimiter = ',', value_name = "S1,S2,...")]
    pub plant_drag_scale: Option<Vec<f64>>,
    /// The simulated capsules' magnetic gain as a factor of the model's
    /// (one for all or one per capsule).
    #[arg(long, value_delimiter = ',', value_name = "S1,S2,...")]
    pub plant_gain_scale: Option<Vec<f64>>,
    /// Drag factors the controller is told at the start, as a calibration
    /// gives them (one for all or one per capsule):
    /// `Controller::set_model_factors`. Without it the controller starts
    /// from the model and learns them from frames.
    #[arg(long, value_delimiter = ',', value_name = "S1,S2,...")]
    pub calibrated_drag_scale: Option<Vec<f64>>,
    /// Gain factors the controller is told at the start (as above).
    #[arg(long, value_delimiter = ',', value_name = "S1,S2,...")]
    pub calibrated_gain_scale: Option<Vec<f64>>,
    /// Standard deviation of the told factors, as a fraction (default
    /// 0.03): how far the calibration may be off.
    #[arg(long, value_name = "FRACTION", allow_hyphen_values = true)]
    pub calibrated_std: Option<f64>,
}

impl PlantArgs {
    /// The simulated plant's factors.
    pub fn mismatch(&self) -> capsule_mpc_sim::mismatch::PlantMismatch {
        mismatch(&self.plant_drag_scale, &self.plant_gain_scale)
    }

    /// The told factors (None: none given) and their deviation, checked.
    pub fn told(&self) -> anyhow::Result<(Option<capsule_mpc_sim::mismatch::PlantMismatch>, f64)> {
        capsule_mpc_sim::closed_loop::told_factors(
            self.calibrated_drag_scale.clone(),
            self.calibrated_gain_scale.clone(),
            self.calibrated_std,
        )
    }
}

#[derive(Debug, Clone, Args)]
pub struct SimulateArgs {
    /// Config file (TOML); the embedded paper config when absent.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Reference scenario (default A).
    #[arg(long, value_enum, conflicts_with = "target")]
    pub scenario: Option<ScenarioArg>,
    /// Explicit target state x1,v1,x2,v2,... in m and m/s.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X1,V1,X2,V2,..."
    )]
    pub target: Option<Vec<f64>>,
    /// Start positions x1,x2,... in m, capsules at rest (default: the
    /// origin); must lie in the config's workspace like a target.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X1,X2,..."
    )]
    pub start: Option<Vec<f64>>,
    /// A new target state x1,v1,x2,v2,... in m and m/s that the host sets
    /// at `--retarget-at`, wherever the capsules are then (moving or not);
    /// the settle metrics refer to it.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X1,V1,X2,V2,...",
        requires = "retarget_at"
    )]
    pub retarget: Option<Vec<f64>>,
    /// When the host sets `--retarget`, s from the start.
    #[arg(
        long,
        value_name = "S",
        requires = "retarget",
        allow_hyphen_values = true
    )]
    pub retarget_at: Option<f64>,
    #[command(flatten)]
    pub plant: PlantArgs,
    #[arg(long, value_enum, default_value = "variable")]
    pub sampling: SamplingArg,
    #[arg(long, value_enum, default_value = "paper")]
    pub disturbance: DisturbanceArg,
    /// How the disturbance varies in time (its size is `--disturbance`).
    #[arg(long, value_enum, default_value = "random")]
    pub disturbance_model: DisturbanceModelArg,
    /// Seed of the disturbance and the measurement noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated time, s.
    #[arg(long, default_value_t = 3.0, value_parser = positive_seconds)]
    pub duration: f64,
    /// Write the run report (JSON) here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write plots into this directory.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Write the run as played as a Pulseq 1.4 sequence (x gradient per
    /// sample, placeholder tracking events) here; see docs/pulseq.md.
    #[arg(long, value_name = "FILE.seq")]
    pub pulseq: Option<PathBuf>,
    /// Which generated controller: the product's (`default`) or the paper's NMPC.
    #[arg(long, value_enum, default_value = "default")]
    pub preset: PresetArg,
    /// Switching rule for `--sampling variable`.
    #[arg(long, value_enum, default_value = "tight")]
    pub switching: SwitchingArg,
    /// Solve from the measured state instead of predicting through the
    /// tracking time and delay (the paper's way).
    #[arg(long)]
    pub no_delay_compensation: bool,
    /// No terminal hold near the target: the MPC re-plans to the end.
    #[arg(long)]
    pub no_hold: bool,
    /// Minimum-time shots: the plan is the shortest one that ends at the
    /// target at rest, re-solved every cycle, wherever one converges.
    /// Default: on.
    #[arg(long, conflicts_with = "no_shooting")]
    pub shooting: bool,
    /// No minimum-time shots (the refinement of the stored plans alone).
    #[arg(long)]
    pub no_shooting: bool,
    /// When the SQP refinement runs after the explicit tier (default: the
    /// config's `controller.refine`, itself `per-sample` by default).
    #[arg(long, value_enum)]
    pub refine: Option<RefineArg>,
    /// Lose every N-th tracking frame.
    #[arg(long, value_name = "N")]
    pub lose_every: Option<usize>,
    /// Extra compute/transfer delay after tracking, s (overrides the config).
    #[arg(long, value_name = "S")]
    pub extra_delay: Option<f64>,
}

impl SimulateArgs {
    /// The target state for `state_count` states: `--target` if given, else
    /// the scenario's (default A). Errors on a wrong length or non-finite value.
    pub fn target_state(&self, state_count: usize) -> Result<Vec<f64>> {
        let target = match &self.target {
            Some(t) => t.clone(),
            None => self
                .scenario
                .map_or(Scenario::A, Scenario::from)
                .target_state(),
        };
        if target.len() != state_count {
            bail!(
                "target has {} entries; the config has {state_count} states (x, v per capsule)",
                target.len()
            );
        }
        if target.iter().any(|v| !v.is_finite()) {
            bail!("target {target:?} is not finite");
        }
        Ok(target)
    }

    /// The start positions for `capsules` capsules (see [`start_positions`]).
    pub fn start_positions(&self, capsules: usize) -> Result<Vec<f64>> {
        start_positions(self.start.as_deref(), capsules)
    }

    /// "A", "C" or "custom" (for reports).
    pub fn scenario_name(&self) -> &'static str {
        match (&self.target, self.scenario) {
            (Some(_), _) => "custom",
            (None, s) => s.map_or(Scenario::A, Scenario::from).name(),
        }
    }
}

#[derive(Debug, Clone, Args)]
pub struct ReachArgs {
    /// Config file (TOML); the embedded paper config when absent.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Half-width of the target grid around the start, per capsule, cm.
    #[arg(long, default_value_t = 4.0, value_name = "R")]
    pub range_cm: f64,
    /// Grid spacing, cm.
    #[arg(long, default_value_t = 1.0, value_name = "S")]
    pub step_cm: f64,
    #[arg(long, value_enum, default_value = "ideal")]
    pub sampling: SamplingArg,
    #[arg(long, value_enum, default_value = "none")]
    pub disturbance: DisturbanceArg,
    /// How the disturbance varies in time (its size is `--disturbance`).
    #[arg(long, value_enum, default_value = "random")]
    pub disturbance_model: DisturbanceModelArg,
    /// Seed of the disturbance and the measurement noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Start positions x1,x2,... in m, at rest (default: the origin).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X1,X2,..."
    )]
    pub start: Option<Vec<f64>>,
    #[command(flatten)]
    pub plant: PlantArgs,
    /// Minimum-time shots (see `simulate --shooting`; default: on).
    #[arg(long, conflicts_with = "no_shooting")]
    pub shooting: bool,
    /// No minimum-time shots.
    #[arg(long)]
    pub no_shooting: bool,
    /// Simulated time per run, s (default: long enough for the grid).
    #[arg(long, value_parser = positive_seconds)]
    pub duration: Option<f64>,
    /// Extra compute/transfer delay after each tracking phase, s, for the
    /// scanner-cycle samplings (overrides the config's).
    #[arg(long, value_name = "S")]
    pub extra_delay: Option<f64>,
    /// Write every target's outcome and the summary (JSON) here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write heatmaps (settle time, settle / bound) into this directory.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct GenerateArgs {
    /// Config file (TOML); the module's embedded config when absent (the
    /// paper's two capsules for `controller`, configs/three-capsules.toml
    /// for `three-capsules`).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Which compiled controller module of the crate to generate.
    #[arg(long, value_enum, default_value = "controller")]
    pub module: ModuleArg,
    /// Output directory of the generated crate (default `generated`); with
    /// `--shard`, the part file to write.
    #[arg(long, value_name = "DIR|PART")]
    pub out: Option<PathBuf>,
    /// Do not write: fail if the output differs from what would be generated.
    #[arg(long)]
    pub check: bool,

    /// Re-emit from the tables already in `--out` (they must match the config).
    #[arg(long, conflicts_with_all = ["shard", "merge", "rounds"])]
    pub reuse_tables: bool,

    /// Sharded generation: compute shard I (from 0) of N of round `--round`
    /// and write it to `--out PART`; the positional PARTs are the parts of
    /// every earlier round.
    #[arg(long, value_name = "I/N", requires = "round", conflicts_with_all = ["merge", "rounds", "check"])]
    pub shard: Option<String>,
    /// The round a `--shard` computes (0 .. `--rounds` - 1).
    #[arg(long, value_name = "R", requires = "shard")]
    pub round: Option<usize>,
    /// Assemble the tables from the parts of every round (the positional
    /// PARTs) and emit the crate into `--out` as a plain run does (or, with
    /// `--check`, compare).
    #[arg(long, conflicts_with = "rounds")]
    pub merge: bool,
    /// Print the number of rounds of sharded generation for the config
    /// (stdout) and what each computes (stderr), then exit.
    #[arg(long)]
    pub rounds: bool,
    /// Part files, for `--shard` (earlier rounds) and `--merge` (all rounds).
    #[arg(value_name = "PART")]
    pub parts: Vec<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct BenchArgs {
    /// Number of states to solve from (closed-loop states of scenarios A
    /// and C, the rest uniform over the admissible region's kept index cells).
    #[arg(long, default_value_t = 100000)]
    pub states: usize,
    /// How many of those states (evenly spread) the peers solve too.
    #[arg(long, default_value_t = 3000)]
    pub peer_states: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Schedule of the timed controller step and solver: ideal (samples back
    /// to back), constant (each sample followed by the modelled tracking
    /// coast) or variable (phases of up to N samples; one cycle refines the
    /// plan once per sample of its phase). The peers always solve the ideal
    /// problem.
    #[arg(long, value_enum, default_value_t = SamplingArg::Ideal)]
    pub sampling: SamplingArg,
    /// Write the timings (JSON) here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Config file (TOML) of another compiled controller (e.g.
    /// configs/three-capsules.toml): its controller step only, over its
    /// own closed-loop states and index cells. The embedded config when
    /// absent.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct FiguresArgs {
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "figures")]
    pub out: PathBuf,
    /// Simulated time per run, s.
    #[arg(long, default_value_t = 3.0, value_parser = positive_seconds)]
    pub duration: f64,
}

/// `--shooting` / `--no-shooting` (clap refuses both): None leaves the
/// controller's default.
pub fn shooting_choice(shooting: bool, no_shooting: bool) -> Option<bool> {
    match (shooting, no_shooting) {
        (true, _) => Some(true),
        (_, true) => Some(false),
        _ => None,
    }
}

/// `--extra-delay` is a delay after each tracking phase: ideal sampling has
/// none, so the flag with `--sampling ideal` is refused rather than ignored.
pub fn extra_delay_for(sampling: SamplingArg, extra_delay_s: Option<f64>) -> Result<Option<f64>> {
    if let (SamplingArg::Ideal, Some(d)) = (sampling, extra_delay_s) {
        bail!("--extra-delay {d} applies to the scanner cycle (--sampling constant or variable); ideal sampling has no tracking phase to delay");
    }
    Ok(extra_delay_s)
}

/// `--start` for `capsules` capsules (empty: the origin). Errors on a wrong
/// length or a non-finite value; the workspace is checked by the run.
pub fn start_positions(start: Option<&[f64]>, capsules: usize) -> Result<Vec<f64>> {
    let Some(start) = start else {
        return Ok(Vec::new());
    };
    if start.len() != capsules {
        bail!(
            "--start has {} positions; the config has {capsules} capsules",
            start.len()
        );
    }
    if start.iter().any(|v| !v.is_finite()) {
        bail!("--start {start:?} is not finite");
    }
    Ok(start.to_vec())
}

/// clap value parser: a finite positive number of seconds.
fn positive_seconds(text: &str) -> std::result::Result<f64, String> {
    let v: f64 = text.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{v} is not a positive, finite number of seconds"))
    }
}

/// Loads and validates `path`, or the embedded default when `None`.
pub fn load_config(path: Option<&Path>) -> std::result::Result<Config, ConfigError> {
    match path {
        Some(p) => Config::from_file(p),
        None => Ok(Config::embedded_default()),
    }
}

/// Refinement choice on the command line (as the config's `controller.refine`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RefineArg {
    /// The explicit tier alone (no model rollout in the solver).
    None,
    /// One SQP refinement per cycle.
    Once,
    /// One SQP refinement per sample the coming phase plays.
    PerSample,
}

impl From<RefineArg> for capsule_mpc_generator::config::RefineMode {
    fn from(r: RefineArg) -> Self {
        use capsule_mpc_generator::config::RefineMode;
        match r {
            RefineArg::None => RefineMode::None,
            RefineArg::Once => RefineMode::Once,
            RefineArg::PerSample => RefineMode::PerSample,
        }
    }
}

/// A controller module of the generated crate on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModuleArg {
    /// `controller`: the default two-capsule controller (and the C ABI's);
    /// also writes the paper preset and the QP iteration map.
    Controller,
    /// `three_capsules`: the three-capsule preset.
    ThreeCapsules,
}

impl From<ModuleArg> for ControllerModule {
    fn from(m: ModuleArg) -> Self {
        match m {
            ModuleArg::Controller => ControllerModule::Controller,
            ModuleArg::ThreeCapsules => ControllerModule::ThreeCapsules,
        }
    }
}

/// Switching rule choice on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SwitchingArg {
    /// Local bounds along the plan (see runtime::switching).
    Tight,
    /// Condition (17) with the paper's worst-case constants.
    Paper,
}

impl From<SwitchingArg> for capsule_mpc_runtime::controller::SwitchingRule {
    fn from(s: SwitchingArg) -> Self {
        match s {
            SwitchingArg::Tight => capsule_mpc_runtime::controller::SwitchingRule::Tight,
            SwitchingArg::Paper => capsule_mpc_runtime::controller::SwitchingRule::Paper,
        }
    }
}

/// The plant mismatch of `--plant-drag-scale` and `--plant-gain-scale`
/// (checked against the capsule count by `PlantMismatch::factors`).
pub fn mismatch(
    drag: &Option<Vec<f64>>,
    gain: &Option<Vec<f64>>,
) -> capsule_mpc_sim::mismatch::PlantMismatch {
    capsule_mpc_sim::mismatch::PlantMismatch::from_scales(drag.clone(), gain.clone())
}
