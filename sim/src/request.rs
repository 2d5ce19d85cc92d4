//! One `simulate` run described as plain data, as the command line and the
//! Python package take it: both build the run's options here, so the same
//! arguments give the same run, bit for bit.

use crate::closed_loop::{run, Preset, Retarget, RunOptions, Sampling};
use crate::mismatch::PlantMismatch;
use crate::plant::{disturbance_kind_name, DisturbanceLevel};
use crate::report::RunReport;
use anyhow::{bail, Result};
use capsule_mpc_generator::config::{Config, DisturbanceConfig, DisturbanceKind, RefineMode};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::SwitchingRule;

/// Everything a `simulate` run takes (the CLI's defaults in `new`).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateRequest {
    /// Target state [x1, v1, x2, v2, ...], m and m/s.
    pub target: Vec<f64>,
    /// "A", "C" or "custom", for the report.
    pub scenario: String,
    /// Start positions, m (empty: the origin).
    pub start_m: Vec<f64>,
    /// A new target set during the run (None: `target` to the end).
    pub retarget: Option<Retarget>,
    pub sampling: Sampling,
    pub disturbance: DisturbanceLevel,
    pub disturbance_kind: DisturbanceKind,
    pub seed: u64,
    pub duration_s: f64,
    pub preset: Preset,
    pub switching: SwitchingRule,
    pub compensate_delay: bool,
    pub lose_every: Option<usize>,
    pub hold: bool,
    /// Minimum-time shots; None: the controller's default (on from three
    /// capsules).
    pub shooting: Option<bool>,
    /// None: the config's `controller.refine`.
    pub refine: Option<RefineMode>,
    /// None: the config's extra delay (refused with ideal sampling).
    pub extra_delay_s: Option<f64>,
    pub mismatch: PlantMismatch,
    /// Factors the controller is told at the start (see
    /// `RunOptions::known_factors`).
    pub known_factors: Option<PlantMismatch>,
    /// Their standard deviation (`RunOptions::known_factor_std`).
    pub known_factor_std: f64,
}

impl SimulateRequest {
    /// The CLI's defaults: variable sampling, the paper's random
    /// disturbance, seed 1, 3 s, the default preset.
    pub fn new(target: Vec<f64>, scenario: &str) -> SimulateRequest {
        SimulateRequest {
            target,
            scenario: scenario.to_string(),
            start_m: Vec::new(),
            retarget: None,
            sampling: Sampling::Variable,
            disturbance: DisturbanceLevel::Paper,
            disturbance_kind: DisturbanceKind::Random,
            seed: 1,
            duration_s: 3.0,
            preset: Preset::Default,
            switching: SwitchingRule::Tight,
            compensate_delay: true,
            lose_every: None,
            hold: true,
            shooting: None,
            refine: None,
            extra_delay_s: None,
            mismatch: PlantMismatch::default(),
            known_factors: None,
            known_factor_std: crate::closed_loop::KNOWN_FACTOR_STD,
        }
    }

    /// The run's options for `config`, checked (each error names the argument).
    pub fn options(&self, config: &Config) -> Result<RunOptions> {
        let model = Model::from_config(config);
        let (m, n) = (model.capsule_count(), model.state_count());
        if self.target.len() != n {
            bail!(
                "target has {} entries; the config has {n} states (x, v per capsule)",
                self.target.len()
            );
        }
        if self.target.iter().any(|v| !v.is_finite()) {
            bail!("target {:?} is not finite", self.target);
        }
        if !self.start_m.is_empty() && self.start_m.len() != m {
            bail!(
                "start has {} positions; the config has {m} capsules",
                self.start_m.len()
            );
        }
        if self.start_m.iter().any(|v| !v.is_finite()) {
            bail!("start {:?} is not finite", self.start_m);
        }
        if let (Sampling::Ideal, Some(d)) = (self.sampling, self.extra_delay_s) {
            bail!("extra delay {d} applies to the scanner cycle (constant or variable sampling); ideal sampling has no tracking phase to delay");
        }
        if self.lose_every == Some(0) {
            bail!("lose every 0: N counts the tracking frames, so it is at least 1 (1 loses every frame, 4 every 4th)");
        }
        self.mismatch.factors(m)?;
        if let Some(known) = &self.known_factors {
            known.factors_named(m, "calibrated")?;
            crate::closed_loop::check_known_factor_std(self.known_factor_std)?;
        }
        let mut opts = RunOptions::new(config, self.target.clone(), self.sampling);
        opts.start_m = self.start_m.clone();
        opts.retarget = self.retarget.clone();
        opts.duration_s = self.duration_s;
        opts.seed = self.seed;
        opts.disturbance =
            self.disturbance
                .config_of_kind(&model, self.seed, self.disturbance_kind);
        opts.preset = self.preset;
        opts.switching = self.switching;
        opts.compensate_delay = self.compensate_delay;
        opts.lose_every = self.lose_every;
        opts.hold = self.hold;
        opts.shooting = self.shooting;
        opts.mismatch = self.mismatch.clone();
        opts.known_factors = self.known_factors.clone();
        opts.known_factor_std = self.known_factor_std;
        if let Some(r) = self.refine {
            opts.refine = r;
        }
        if let Some(d) = self.extra_delay_s {
            opts.extra_delay_s = d;
        }
        if self.disturbance == DisturbanceLevel::None {
            opts.disturbance = DisturbanceConfig::default();
        }
        Ok(opts)
    }

    /// The disturbance's name in the report ("none", "paper",
    /// "paper-drift", ...).
    pub fn disturbance_name(&self) -> String {
        if self.disturbance == DisturbanceLevel::None {
            "none".to_string()
        } else if self.disturbance_kind == DisturbanceKind::Random {
            format!("{:?}", self.disturbance).to_lowercase()
        } else {
            format!(
                "{:?}-{}",
                self.disturbance,
                disturbance_kind_name(self.disturbance_kind)
            )
            .to_lowercase()
        }
    }

    /// Runs it: the report, named.
    pub fn run(&self, config: &Config) -> Result<RunReport> {
        let opts = self.options(config)?;
        let mut report = run(config, &opts)?;
        report.scenario = Some(self.scenario.clone());
        report.disturbance = Some(self.disturbance_name());
        Ok(report)
    }
}
