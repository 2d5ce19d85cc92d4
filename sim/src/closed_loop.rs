//! Closed-loop runs: the runtime controller against the plant simulator,
//! on the scanner's timeline (tracking phases with u = 0, measurement delay,
//! actuation phases chosen by the switching rule).

use crate::metrics::Metrics;
use crate::mismatch::PlantMismatch;
use crate::plant::{Phase, Plant};
use crate::report::{
    CalibratedReport, FactorEstimate, FrameCounts, MeasurementRecord, ModeChange, ModelParams,
    PlantReport, RetargetReport, RunReport, ScannerTiming, TierCycles,
};
use anyhow::{bail, Context, Result};
use capsule_mpc_generator::config::{Config, DisturbanceConfig, RefineMode};
use capsule_mpc_generator::generate::ControllerModule;
use capsule_mpc_generator::model::Model;
use capsule_mpc_generator::tables::{hex, solver_hash};
use capsule_mpc_runtime::controller::{Refine, Shooting, SwitchingRule};
use capsule_mpc_runtime::generated::{PlanSolver, Tier};
use capsule_mpc_runtime::{Controller, RuntimeError, RuntimeStatus};
use std::time::Instant;

/// Reference scenarios of the paper (targets in cm, see NOTES.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    /// Both capsules the same way: (2 cm, 0, 3 cm, 0).
    A,
    /// Opposite ways: (2 cm, 0, -1 cm, 0).
    C,
}

impl Scenario {
    /// Target state [x1, v1, x2, v2] in m and m/s.
    pub fn target_state(self) -> Vec<f64> {
        match self {
            Scenario::A => vec![0.02, 0.0, 0.03, 0.0],
            Scenario::C => vec![0.02, 0.0, -0.01, 0.0],
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Scenario::A => "A",
            Scenario::C => "C",
        }
    }
}

/// When the controller gets measurements and may actuate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Sampling {
    /// Exact state every sample, no tracking time (an upper bound on quality).
    Ideal,
    /// Track, then actuate for a fixed time, every period.
    Constant,
    /// Actuate until the switching rule asks for a new measurement.
    Variable,
}

impl Sampling {
    /// The runtime's sampling mode.
    pub fn runtime(self) -> capsule_mpc_runtime::controller::Sampling {
        use capsule_mpc_runtime::controller::Sampling as Rt;
        match self {
            Sampling::Ideal => Rt::Ideal,
            Sampling::Constant => Rt::Constant,
            Sampling::Variable => Rt::Variable,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Sampling::Ideal => "ideal",
            Sampling::Constant => "constant",
            Sampling::Variable => "variable",
        }
    }
}

/// Which generated controller drives the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Offline plan tables + online refinement (the product).
    Default,
    /// The paper's NMPC taken literally (N = 10, Table I weights).
    Paper,
}

/// A target change during the run.
#[derive(Debug, Clone, PartialEq)]
pub struct Retarget {
    /// When the host sets the new target, s.
    pub at_s: f64,
    /// The new target state [x1, v1, x2, v2, ...], m and m/s.
    pub target: Vec<f64>,
}

/// Everything that defines one closed-loop run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub target: Vec<f64>,
    /// Start positions of the capsules (at rest), m; the origin when empty.
    pub start_m: Vec<f64>,
    /// A target change during the run (settle metrics then refer to it).
    pub retarget: Option<Retarget>,
    pub sampling: Sampling,
    pub switching: SwitchingRule,
    pub compensate_delay: bool,
    pub duration_s: f64,
    pub disturbance: DisturbanceConfig,
    pub seed: u64,
    pub position_noise_m: f64,
    /// Extra compute/transfer delay, s (the config's by default).
    pub extra_delay_s: f64,
    /// Drop every n-th measurement (None: keep all).
    pub lose_every: Option<usize>,
    pub preset: Preset,
    /// Terminal hold near the target (off: the MPC re-plans to the end,
    /// as the paper's controller does).
    pub hold: bool,
    /// Minimum-time shots (`ControllerSettings::shooting`); None: the
    /// controller's default (on from three capsules).
    pub shooting: Option<bool>,
    /// When the SQP refinement runs after the explicit tier (the config's
    /// `controller.refine` by default).
    pub refine: RefineMode,
    /// How the simulated capsules differ from the model (none by default).
    pub mismatch: PlantMismatch,
    /// Factors the controller is told at the start
    /// (`Controller::set_model_factors`, e.g. from a calibration), each
    /// with standard deviation `known_factor_std`; None: it starts from
    /// the model and learns them.
    pub known_factors: Option<PlantMismatch>,
    pub known_factor_std: f64,
}

/// Default standard deviation of told factors (`RunOptions`), 3 %: a
/// calibration's error (about 0.5 %) with room for the capsule changing
/// since. Told 2-3 % wrong, 1 % made the loop slower than not told at
/// all (the estimator then corrects them too slowly).
pub const KNOWN_FACTOR_STD: f64 = 0.03;

impl RunOptions {
    /// Options from the config with the given target and sampling.
    pub fn new(config: &Config, target: Vec<f64>, sampling: Sampling) -> RunOptions {
        RunOptions {
            target,
            start_m: Vec::new(),
            retarget: None,
            sampling,
            switching: SwitchingRule::Tight,
            compensate_delay: true,
            duration_s: 3.0,
            disturbance: DisturbanceConfig::default(),
            seed: 1,
            position_noise_m: config.measurement.position_noise_m,
            extra_delay_s: config.scanner.extra_delay_s,
            lose_every: None,
            preset: Preset::Default,
            hold: true,
            shooting: None,
            refine: config.controller.refine,
            mismatch: PlantMismatch::default(),
            known_factors: None,
            known_factor_std: KNOWN_FACTOR_STD,
        }
    }
}

/// The product controllers compiled into this binary: module name, capsule
/// count and the solver hash of the config each was generated for.
pub fn compiled_controllers() -> [(ControllerModule, usize, &'static str); 2] {
    use capsule_mpc_runtime::generated::{controller, three_capsules};
    [
        (
            ControllerModule::Controller,
            controller::spec::M,
            controller::spec::SOLVER_SHA256,
        ),
        (
            ControllerModule::ThreeCapsules,
            three_capsules::spec::M,
            three_capsules::spec::SOLVER_SHA256,
        ),
    ]
}

/// The compiled controller module generated for `config` (by solver hash:
/// the simulation-only sections may differ), or an error that says how to
/// generate one.
pub fn compiled_controller_for(config: &Config) -> Result<ControllerModule> {
    let wanted = hex(&solver_hash(config));
    let compiled = compiled_controllers();
    if let Some((module, _, _)) = compiled.iter().find(|(_, _, h)| *h == wanted) {
        return Ok(*module);
    }
    let list: Vec<String> = compiled
        .iter()
        .map(|(module, m, h)| format!("`{}` ({m} capsules, {}…)", module.module_name(), &h[..12]))
        .collect();
    let module = match config.capsule_count() {
        3 => ControllerModule::ThreeCapsules,
        _ => ControllerModule::Controller,
    };
    bail!(
        "no compiled controller for this config ({} capsules, solver hash {}…); this binary has {}. \
         Generate one with `capsule-mpc generate --config FILE --module {}` and rebuild \
         (`cargo build --release`)",
        config.capsule_count(),
        &wanted[..12],
        list.join(" and "),
        module.cli_name()
    )
}

/// Longest simulated run, s: the report keeps every plant step (1 ms), so
/// 600 s is 600 000 rows, tens of MB; a maneuver takes seconds.
pub const MAX_RUN_DURATION_S: f64 = 600.0;

/// A run duration in (0, `MAX_RUN_DURATION_S`] s, or an error naming it.
pub fn check_duration(duration_s: f64) -> Result<()> {
    if !(duration_s > 0.0 && duration_s <= MAX_RUN_DURATION_S) {
        bail!(
            "run duration {duration_s} s is outside (0, {MAX_RUN_DURATION_S}] s (the report keeps every 1 ms plant step)"
        );
    }
    Ok(())
}

/// A told factor's standard deviation must be a fraction within the
/// runtime's `[MODEL_FACTOR_STD_MIN, MODEL_FACTOR_STD_MAX]` (its own error
/// would only name the argument); the error says the value and the range.
pub fn check_known_factor_std(std: f64) -> Result<()> {
    use capsule_mpc_runtime::controller::{MODEL_FACTOR_STD_MAX, MODEL_FACTOR_STD_MIN};
    if !(MODEL_FACTOR_STD_MIN..=MODEL_FACTOR_STD_MAX).contains(&std) {
        bail!(
            "calibrated std {std} is outside [{MODEL_FACTOR_STD_MIN}, {MODEL_FACTOR_STD_MAX}] (a fraction of the factor: 0.03 is 3 %)"
        );
    }
    Ok(())
}

/// Factors the controller is told (None when neither scale is given) and
/// their standard deviation (`KNOWN_FACTOR_STD` when absent), checked: a
/// deviation without factors is refused, as is one out of range. The CLI's
/// and Python's arguments both come through here.
pub fn told_factors(
    drag_scale: Option<Vec<f64>>,
    gain_scale: Option<Vec<f64>>,
    std: Option<f64>,
) -> Result<(Option<PlantMismatch>, f64)> {
    let known = (drag_scale.is_some() || gain_scale.is_some())
        .then(|| PlantMismatch::from_scales(drag_scale, gain_scale));
    let std = match (&known, std) {
        (None, Some(s)) => bail!(
            "calibrated std {s} needs the factors it qualifies: a calibrated drag or gain scale"
        ),
        (_, Some(s)) => {
            check_known_factor_std(s)?;
            s
        }
        (_, None) => KNOWN_FACTOR_STD,
    };
    Ok((known, std))
}

/// The extra delay after each tracking phase must lie in
/// `[0, MAX_EXTRA_DELAY_S]` s, the runtime's range (its error would only
/// name the setting); the error says the value and the range.
pub fn check_extra_delay(config: &Config, extra_delay_s: f64) -> Result<()> {
    use capsule_mpc_runtime::controller::{max_proven_gap_s, MAX_EXTRA_DELAY_S};
    if !(0.0..=MAX_EXTRA_DELAY_S).contains(&extra_delay_s) {
        bail!("extra delay {extra_delay_s} s is outside [0, {MAX_EXTRA_DELAY_S}] s");
    }
    let tracking_s = config.scanner.tracking_time_s;
    let max_s = max_proven_gap_s(
        tracking_s + config.scanner.extra_delay_s,
        config.capsule_count(),
    );
    if tracking_s + extra_delay_s > max_s + capsule_mpc_runtime::controller::TIME_TOLERANCE_S {
        bail!(
            "{}",
            gap_beyond_proven(tracking_s + extra_delay_s, max_s, config.capsule_count())
        );
    }
    Ok(())
}

/// What to say when tracking + delay is beyond the proven range of a
/// controller for `capsules` capsules.
fn gap_beyond_proven(gap_s: f64, max_s: f64, capsules: usize) -> String {
    let margin_s = capsule_mpc_runtime::controller::proven_extra_gap_s(capsules);
    format!(
        "tracking time + extra delay = {gap_s:.4} s is beyond the range this controller is proven to settle with \
         ({max_s} s: the generated config's tracking time + delay + {margin_s} s for {capsules} capsules); \
         regenerate with the longer scanner.tracking_time_s or extra_delay_s"
    )
}

/// Runs the closed loop and returns the full report.
pub fn run(config: &Config, opts: &RunOptions) -> Result<RunReport> {
    use capsule_mpc_runtime::generated::{controller, paper_preset, three_capsules};
    check_duration(opts.duration_s)?;
    check_extra_delay(config, opts.extra_delay_s)?;
    let module = compiled_controller_for(config)?;
    match (opts.preset, module) {
        (Preset::Default, ControllerModule::Controller) => {
            run_with::<controller::Solver, { controller::spec::NX }, { controller::spec::K }>(
                config, opts,
            )
        }
        (Preset::Default, ControllerModule::ThreeCapsules) => run_with::<
            three_capsules::Solver,
            { three_capsules::spec::NX },
            { three_capsules::spec::K },
        >(config, opts),
        (Preset::Paper, ControllerModule::ThreeCapsules) => {
            bail!("the paper preset is compiled for the default two-capsule config only")
        }
        (Preset::Paper, ControllerModule::Controller) => {
            run_with::<paper_preset::Solver, { paper_preset::spec::NX }, { paper_preset::spec::K }>(
                config, opts,
            )
        }
    }
}

fn run_with<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    config: &Config,
    opts: &RunOptions,
) -> Result<RunReport> {
    let model = Model::from_config(config);
    if model.state_count() != NX {
        bail!(
            "the config has {} capsules but the generated solver was built for {}; run `capsule-mpc generate` and rebuild",
            model.capsule_count(),
            NX / 2
        );
    }
    let target: [f64; NX] = opts
        .target
        .as_slice()
        .try_into()
        .with_context(|| format!("target needs {NX} entries"))?;
    let mut x0 = vec![0.0; NX];
    if opts.start_m.iter().any(|p| !p.is_finite()) {
        bail!("start {:?} m is not finite", opts.start_m);
    }
    if !opts.start_m.is_empty() {
        if opts.start_m.len() != NX / 2 {
            bail!(
                "start has {} positions; the solver has {} capsules",
                opts.start_m.len(),
                NX / 2
            );
        }
        for (i, &p) in opts.start_m.iter().enumerate() {
            x0[2 * i] = p;
        }
    }
    check_in_workspace::<S, NX, K>("start", &x0)
        .with_context(|| format!("start {:?} m", opts.start_m))?;
    let plant_model = opts.mismatch.apply(&model)?;
    let mut plant = Plant::new(
        plant_model.clone(),
        x0.clone(),
        opts.disturbance.clone(),
        if opts.sampling == Sampling::Ideal {
            0.0
        } else {
            opts.position_noise_m
        },
        opts.seed,
    )?;
    let mut settings = Controller::<S, NX, K>::default_settings();
    settings.sampling = opts.sampling.runtime();
    settings.switching = opts.switching;
    settings.compensate_delay = opts.compensate_delay;
    settings.refine = runtime_refine(opts.refine);
    settings.extra_delay_s = opts.extra_delay_s;
    settings.position_noise_m = opts.position_noise_m;
    settings.disturbance_bound = opts.disturbance.bound_si();
    settings.shooting = match (opts.shooting, opts.preset) {
        (Some(on), _) => on.into(),
        // The paper's NMPC plans on its quadratic cost alone.
        (None, Preset::Paper) => Shooting::Off,
        (None, Preset::Default) => settings.shooting,
    };
    if !opts.hold || opts.preset == Preset::Paper {
        // Zero-size entry set: the hold is never entered.
        settings.hold_enter_position_m = 0.0;
        settings.hold_enter_speed_m_per_s = 0.0;
    }
    let positions: Vec<f64> = x0.iter().step_by(2).copied().collect();
    let mut ctl = Controller::<S, NX, K>::new(settings, &positions).map_err(|e| match e {
        RuntimeError::BadSetting("refine") => anyhow::anyhow!(
            "refine = none needs the explicit tier's data, which only the default two-capsule controller has \
             (not the paper preset, which has no tables, nor the three-capsule module): use refine once or per-sample"
        ),
        RuntimeError::GapBeyondProven { gap_s, max_s } => {
            anyhow::anyhow!("{}", gap_beyond_proven(gap_s, max_s, NX / 2))
        }
        e => anyhow::anyhow!("controller settings: {e:?}"),
    })?;
    if let Some(known) = &opts.known_factors {
        let (drag, gain) = known.factors_named(NX / 2, "calibrated")?;
        let std = opts.known_factor_std;
        check_known_factor_std(std)?;
        for i in 0..NX / 2 {
            ctl.set_model_factors(i, [gain[i], drag[i]], [std, std])
                .map_err(|e| anyhow::anyhow!("calibrated factors of capsule {}: {e:?}", i + 1))?;
        }
    }
    set_target_or_explain(&mut ctl, &target, "target")?;
    let retarget: Option<(f64, [f64; NX])> = match &opts.retarget {
        Some(r) => {
            if !(r.at_s.is_finite() && r.at_s >= 0.0 && r.at_s < opts.duration_s) {
                bail!(
                    "retarget at {} s: the target can change only during the run, [0, {}) s",
                    r.at_s,
                    opts.duration_s
                );
            }
            let Ok(t) = <[f64; NX]>::try_from(r.target.as_slice()) else {
                bail!(
                    "retarget has {} entries; the config has {NX} states (x, v per capsule)",
                    r.target.len()
                );
            };
            if t.iter().any(|v| !v.is_finite()) {
                bail!("retarget {t:?} is not finite");
            }
            check_in_workspace::<S, NX, K>("retarget", &t)
                .with_context(|| format!("retarget {t:?} m"))?;
            if t.iter().skip(1).step_by(2).any(|&v| v != 0.0) {
                return Err(explain::<S, NX, K>(
                    capsule_mpc_runtime::RuntimeError::TargetNotAtRest,
                    &t,
                ))
                .with_context(|| format!("retarget {t:?} m"));
            }
            Some((r.at_s, t))
        }
        None => None,
    };
    let final_target = retarget.map_or(target, |(_, t)| t);
    // The minimum rest-to-rest time of the move, from the tables.
    let mut displacement = [0.0; NX];
    for i in 0..NX / 2 {
        displacement[2 * i] = x0[2 * i] - target[2 * i];
    }
    let min_time_bound_s = S::chain_time_s(&displacement);
    let schedule_min_time_s = match opts.sampling {
        Sampling::Constant => S::coasted_time_s(&displacement),
        Sampling::Ideal | Sampling::Variable => min_time_bound_s,
    };
    let mut retarget_pending = retarget;

    let mut measurements = Vec::new();
    let mut max_ns: u64 = 0;
    let mut statuses = StatusCounts::default();
    let mut modes: Vec<ModeChange> = Vec::new();
    let mut cycle = 0usize;
    let tracking_s = settings.tracking_time_s;
    while plant.time_s() < opts.duration_s - 1e-9 {
        cycle += 1;
        if let Some((at_s, t)) = retarget_pending {
            if plant.time_s() >= at_s - 1e-9 {
                set_target_or_explain(&mut ctl, &t, "retarget")?;
                retarget_pending = None;
            }
        }
        let out = if opts.sampling == Sampling::Ideal {
            let x: [f64; NX] = plant.state().try_into().expect("state length");
            measurements.push(MeasurementRecord {
                t_s: plant.time_s(),
                available_s: plant.time_s(),
                positions_m: x.iter().step_by(2).copied().collect(),
                lost: false,
            });
            let started = Instant::now();
            let out = ctl
                .cycle_full_state(&x)
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            max_ns = max_ns.max(started.elapsed().as_nanos() as u64);
            out
        } else {
            let t_meas = plant.time_s();
            let z = plant.measure_positions();
            let lost = opts
                .lose_every
                .is_some_and(|n| n > 0 && cycle.is_multiple_of(n));
            plant.advance(tracking_s, 0.0, Phase::Track)?;
            if opts.extra_delay_s > 0.0 {
                plant.advance(opts.extra_delay_s, 0.0, Phase::Track)?;
            }
            measurements.push(MeasurementRecord {
                t_s: t_meas,
                available_s: plant.time_s(),
                positions_m: z.clone(),
                lost,
            });
            let started = Instant::now();
            let out = ctl
                .cycle(if lost { None } else { Some(&z) })
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            max_ns = max_ns.max(started.elapsed().as_nanos() as u64);
            if !lost {
                statuses.frames.received += 1;
                match out.status {
                    RuntimeStatus::MeasurementRejected => statuses.frames.rejected += 1,
                    RuntimeStatus::Reacquired => statuses.frames.reacquired += 1,
                    _ => {}
                }
            }
            out
        };
        if modes.last().map(|m: &ModeChange| m.mode.as_str()) != Some(ctl.mode().name()) {
            modes.push(ModeChange {
                t_s: plant.time_s(),
                mode: ctl.mode().name().to_string(),
            });
        }
        statuses.count(out.status);
        match out.solve.map(|r| r.tier) {
            Some(Tier::Explicit) => statuses.explicit += 1,
            Some(Tier::Refined) => statuses.refined += 1,
            None => {}
        }
        for &u in &out.gradients_t_per_m[..out.actuation_samples] {
            if plant.time_s() >= opts.duration_s - 1e-9 {
                break;
            }
            plant.advance(S::DT_S, u, Phase::Actuate)?;
        }
    }
    let (pos_bound, speed_bound) = (S::POSITION_BOUND_M, S::SPEED_BOUND_M_PER_S);
    let records = plant.into_records();
    let mut metrics = Metrics::compute(&records, &final_target, pos_bound, speed_bound, max_ns)?;
    if retarget.is_none() && min_time_bound_s.is_finite() && min_time_bound_s > 0.0 {
        metrics.min_time_bound_s = Some(min_time_bound_s);
        metrics.settle_over_bound = metrics.settle_time_s.map(|t| t / min_time_bound_s);
        metrics.held_settle_over_bound = metrics.settle_held_s.map(|t| t / min_time_bound_s);
    }
    if retarget.is_none() && schedule_min_time_s.is_finite() && schedule_min_time_s > 0.0 {
        metrics.schedule_min_time_s = Some(schedule_min_time_s);
        metrics.settle_over_schedule_bound = metrics.settle_time_s.map(|t| t / schedule_min_time_s);
    }
    metrics.workspace_excursion_m = records
        .iter()
        .flat_map(|r| r.x.iter().step_by(2))
        .map(|&p| {
            (S::WORKSPACE_MIN_M - p)
                .max(p - S::WORKSPACE_MAX_M)
                .max(0.0)
        })
        .fold(0.0, f64::max);
    let mut report = RunReport::from_records(
        &records,
        measurements,
        &model,
        final_target.to_vec(),
        metrics,
    );
    if !opts.mismatch.is_nominal() {
        let (drag, gain) = opts.mismatch.factors(NX / 2)?;
        report.plant = Some(PlantReport {
            drag_scale: drag,
            gain_scale: gain,
            params: ModelParams::from_model(&plant_model),
        });
    }
    if let Some(known) = &opts.known_factors {
        let (drag, gain) = known.factors_named(NX / 2, "calibrated")?;
        report.calibrated = Some(CalibratedReport {
            drag_scale: drag,
            gain_scale: gain,
            std: opts.known_factor_std,
        });
    }
    report.retarget = retarget.map(|(at_s, _)| RetargetReport {
        at_s,
        first_target: target.to_vec(),
    });
    report.sampling = Some(opts.sampling.name().to_string());
    report.seed = Some(opts.seed);
    report.fallback_cycles = Some(statuses.fallback);
    if opts.sampling != Sampling::Ideal {
        report.frames = Some(statuses.frames);
        report.timing = Some(ScannerTiming {
            tracking_time_s: tracking_s,
            extra_delay_s: opts.extra_delay_s,
            lose_every: opts.lose_every,
        });
    }
    report.estimated_factors = Some(
        (0..NX / 2)
            .filter_map(|i| ctl.model_factors(i))
            .map(|f| FactorEstimate {
                gain: f.mean[0],
                gain_std: f.cov[0].max(0.0).sqrt(),
                drag: f.mean[1],
                drag_std: f.cov[3].max(0.0).sqrt(),
            })
            .collect(),
    );
    report.tier_cycles = Some(TierCycles {
        explicit: statuses.explicit,
        refined: statuses.refined,
    });
    report.modes = Some(modes);
    Ok(report)
}

/// Positions of the full state `x` must lie in the workspace; the error
/// names the argument, the capsule and by how much.
fn check_in_workspace<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    argument: &'static str,
    x: &[f64],
) -> Result<()> {
    capsule_mpc_runtime::controller::check_workspace::<S, NX, K>(argument, x, 2)
        .map_err(|e| explain::<S, NX, K>(e, x))
}

fn set_target_or_explain<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    ctl: &mut Controller<S, NX, K>,
    target: &[f64; NX],
    argument: &'static str,
) -> Result<()> {
    ctl.set_target(target)
        .map_err(|e| explain::<S, NX, K>(e, target))
        .with_context(|| format!("{argument} {target:?} m"))
}

/// A runtime error as a sentence for the command line.
fn explain<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    e: capsule_mpc_runtime::RuntimeError,
    x: &[f64],
) -> anyhow::Error {
    use capsule_mpc_runtime::RuntimeError as E;
    match e {
        E::OutsideWorkspace {
            argument: _,
            capsule,
            excess_m,
        } => anyhow::anyhow!(
            "capsule {} at {} m is outside the workspace [{}, {}] m by {:.4} m ({} the {} bound; config section [workspace])",
            capsule + 1,
            x.get(2 * capsule).copied().unwrap_or(f64::NAN),
            S::WORKSPACE_MIN_M,
            S::WORKSPACE_MAX_M,
            excess_m.abs(),
            if excess_m < 0.0 { "below" } else { "above" },
            if excess_m < 0.0 { "lower" } else { "upper" },
        ),
        E::TargetNotAtRest => anyhow::anyhow!(
            "target speeds {:?} m/s are not 0; targets are rest states",
            x.iter().skip(1).step_by(2).collect::<Vec<_>>()
        ),
        E::TargetOutOfRange => anyhow::anyhow!(
            "no chain of stored plans reaches it from the current state (the state lies outside the workspace the tables were made for)"
        ),
        other => anyhow::anyhow!("{other:?}"),
    }
}

#[derive(Debug, Default)]
struct StatusCounts {
    fallback: usize,
    /// Cycles whose plan came from each tier.
    explicit: usize,
    refined: usize,
    frames: FrameCounts,
}

/// The runtime's refinement setting for the config's.
pub fn runtime_refine(r: RefineMode) -> Refine {
    match r {
        RefineMode::None => Refine::None,
        RefineMode::Once => Refine::Once,
        RefineMode::PerSample => Refine::PerSample,
    }
}

impl StatusCounts {
    fn count(&mut self, s: RuntimeStatus) {
        if s == RuntimeStatus::Fallback {
            self.fallback += 1;
        }
    }
}
