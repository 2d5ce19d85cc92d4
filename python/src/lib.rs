//! Python bindings of capsule-mpc: thin over the same library code the CLI
//! uses (`sim::request::SimulateRequest` for `simulate`, `sim::reach` for
//! `reach`, the runtime's `Controller` for the closed loop), returning the
//! CLI's JSON for the Python layer (`capsule_mpc/__init__.py`) to turn into
//! numpy arrays. Long calls release the GIL; nothing is printed.

use capsule_mpc_generator::config::{
    Config as GenConfig, ConfigError as GenConfigError, RefineMode,
};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::{ControllerSettings, CycleOutput, Sampling as RtSampling};
use capsule_mpc_runtime::{Controller as RtController, RuntimeError};
use capsule_mpc_sim::closed_loop::{told_factors, Retarget, Sampling};
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::{disturbance_kind_from_name, DisturbanceLevel};
use capsule_mpc_sim::reach::{reach_map, ReachOptions, ReachSummary};
use capsule_mpc_sim::request::SimulateRequest;
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    _native,
    ConfigError,
    PyValueError,
    "A config field is missing or out of its range (the message names it)."
);

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn config_error(e: GenConfigError, path: Option<&str>) -> PyErr {
    let text = e.to_string();
    match path {
        Some(p) if !std::path::Path::new(p).exists() => {
            PyFileNotFoundError::new_err(format!("config file {p} not found"))
        }
        _ => ConfigError::new_err(text),
    }
}

/// A capsule/scanner config (read-only from Python).
#[pyclass(module = "capsule_mpc._native", name = "Config", frozen)]
#[derive(Clone)]
struct PyConfig {
    inner: GenConfig,
}

#[pymethods]
impl PyConfig {
    #[staticmethod]
    fn default() -> PyConfig {
        PyConfig {
            inner: GenConfig::embedded_default(),
        }
    }
    #[staticmethod]
    fn three_capsules() -> PyConfig {
        PyConfig {
            inner: GenConfig::embedded_three_capsules(),
        }
    }
    #[staticmethod]
    fn from_toml(path: &str) -> PyResult<PyConfig> {
        GenConfig::from_file(std::path::Path::new(path))
            .map(|inner| PyConfig { inner })
            .map_err(|e| config_error(e, Some(path)))
    }
    #[staticmethod]
    fn from_str(text: &str) -> PyResult<PyConfig> {
        GenConfig::from_toml_str(text)
            .map(|inner| PyConfig { inner })
            .map_err(|e| config_error(e, None))
    }
    #[getter]
    fn capsule_count(&self) -> usize {
        self.inner.capsule_count()
    }
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.capsule.iter().map(|c| c.name.clone()).collect()
    }
    #[getter]
    fn g(&self) -> Vec<f64> {
        Model::from_config(&self.inner)
            .capsules
            .iter()
            .map(|c| c.g)
            .collect()
    }
    #[getter]
    fn b(&self) -> Vec<f64> {
        Model::from_config(&self.inner)
            .capsules
            .iter()
            .map(|c| {
                c.drag
                    .effective_b_per_m(capsule_mpc_sim::report::B_REFERENCE_SPEED_M_PER_S)
            })
            .collect()
    }
    #[getter]
    fn sample_time_s(&self) -> f64 {
        self.inner.controller.sample_time_s
    }
    #[getter]
    fn tracking_time_s(&self) -> f64 {
        self.inner.scanner.tracking_time_s
    }
    #[getter]
    fn u_max_t_per_m(&self) -> f64 {
        self.inner.scanner.max_gradient_t_per_m
    }
    #[getter]
    fn workspace(&self) -> (f64, f64) {
        (
            self.inner.workspace.position_min_m,
            self.inner.workspace.position_max_m,
        )
    }
    /// The config as JSON (the canonical form its hash is taken of).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner).map_err(value_error)
    }
}

fn sampling_of(name: &str) -> PyResult<Sampling> {
    match name {
        "ideal" => Ok(Sampling::Ideal),
        "constant" => Ok(Sampling::Constant),
        "variable" => Ok(Sampling::Variable),
        other => Err(value_error(format!(
            "sampling '{other}' is not one of 'ideal', 'constant', 'variable'"
        ))),
    }
}

fn refine_of(name: &str) -> PyResult<RefineMode> {
    match name {
        "none" => Ok(RefineMode::None),
        "once" => Ok(RefineMode::Once),
        "per-sample" => Ok(RefineMode::PerSample),
        other => Err(value_error(format!(
            "refine '{other}' is not one of 'none', 'once', 'per-sample'"
        ))),
    }
}

/// One closed-loop run: the CLI's `simulate --json` report as a string.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (config, target, start, sampling, disturbance, disturbance_model, seed, duration_s, refine, plant_drag_scale, plant_gain_scale, shooting, calibrated_drag_scale = None, calibrated_gain_scale = None, calibrated_std = None, extra_delay_s = None, lose_every = None, retarget = None, retarget_at_s = None))]
fn simulate_json(
    py: Python<'_>,
    config: &PyConfig,
    target: Vec<f64>,
    start: Option<Vec<f64>>,
    sampling: &str,
    disturbance: &str,
    disturbance_model: &str,
    seed: u64,
    duration_s: f64,
    refine: Option<&str>,
    plant_drag_scale: Option<Vec<f64>>,
    plant_gain_scale: Option<Vec<f64>>,
    shooting: Option<bool>,
    calibrated_drag_scale: Option<Vec<f64>>,
    calibrated_gain_scale: Option<Vec<f64>>,
    calibrated_std: Option<f64>,
    extra_delay_s: Option<f64>,
    lose_every: Option<usize>,
    retarget: Option<Vec<f64>>,
    retarget_at_s: Option<f64>,
) -> PyResult<String> {
    let mut r = SimulateRequest::new(target, "custom");
    r.retarget = match (retarget, retarget_at_s) {
        (Some(target), Some(at_s)) => Some(Retarget { at_s, target }),
        (None, None) => None,
        _ => {
            return Err(value_error(
                "retarget and retarget_at_s go together: the new target and when it is set",
            ))
        }
    };
    r.extra_delay_s = extra_delay_s;
    r.lose_every = lose_every;
    r.shooting = shooting;
    r.start_m = start.unwrap_or_default();
    r.sampling = sampling_of(sampling)?;
    r.disturbance = DisturbanceLevel::from_name(disturbance).map_err(value_error)?;
    r.disturbance_kind = disturbance_kind_from_name(disturbance_model).map_err(value_error)?;
    r.seed = seed;
    r.duration_s = duration_s;
    r.refine = refine.map(refine_of).transpose()?;
    r.mismatch = PlantMismatch::from_scales(plant_drag_scale, plant_gain_scale);
    (r.known_factors, r.known_factor_std) =
        told_factors(calibrated_drag_scale, calibrated_gain_scale, calibrated_std)
            .map_err(|e| value_error(format!("{e:#}")))?;
    let cfg = config.inner.clone();
    let report = py
        .allow_threads(|| r.run(&cfg))
        .map_err(|e| value_error(format!("{e:#}")))?;
    serde_json::to_string(&report).map_err(value_error)
}

/// The reach map: `{"points": [...], "summary": {...}}` as the CLI's JSON.
#[pyfunction]
#[pyo3(signature = (config, range_cm, step_cm, sampling, disturbance, seed, shooting, plant_drag_scale = None, plant_gain_scale = None, calibrated_drag_scale = None, calibrated_gain_scale = None, calibrated_std = None, disturbance_model = "random", duration_s = None, extra_delay_s = None, start = None))]
#[allow(clippy::too_many_arguments)]
fn reach_json(
    py: Python<'_>,
    config: &PyConfig,
    range_cm: f64,
    step_cm: f64,
    sampling: &str,
    disturbance: &str,
    seed: u64,
    shooting: Option<bool>,
    plant_drag_scale: Option<Vec<f64>>,
    plant_gain_scale: Option<Vec<f64>>,
    calibrated_drag_scale: Option<Vec<f64>>,
    calibrated_gain_scale: Option<Vec<f64>>,
    calibrated_std: Option<f64>,
    disturbance_model: &str,
    duration_s: Option<f64>,
    extra_delay_s: Option<f64>,
    start: Option<Vec<f64>>,
) -> PyResult<String> {
    if !(range_cm.is_finite() && range_cm >= 0.0) {
        return Err(value_error(format!(
            "range_cm {range_cm} must be a finite number >= 0"
        )));
    }
    if !(step_cm.is_finite() && step_cm > 0.0) {
        return Err(value_error(format!(
            "step_cm {step_cm} must be a finite number > 0"
        )));
    }
    let (known_factors, known_factor_std) =
        told_factors(calibrated_drag_scale, calibrated_gain_scale, calibrated_std)
            .map_err(|e| value_error(format!("{e:#}")))?;
    let opts = ReachOptions {
        range_m: range_cm / 100.0,
        step_m: step_cm / 100.0,
        sampling: sampling_of(sampling)?,
        disturbance: DisturbanceLevel::from_name(disturbance).map_err(value_error)?,
        disturbance_kind: disturbance_kind_from_name(disturbance_model).map_err(value_error)?,
        seed,
        start_m: start.unwrap_or_default(),
        duration_s,
        extra_delay_s,
        mismatch: PlantMismatch::from_scales(plant_drag_scale, plant_gain_scale),
        known_factors,
        known_factor_std,
        shooting,
    };
    let cfg = config.inner.clone();
    let points = py
        .allow_threads(|| reach_map(&cfg, &opts, &|| {}))
        .map_err(|e| value_error(format!("{e:#}")))?;
    let summary = ReachSummary::of(&points);
    serde_json::to_string(&serde_json::json!({"points": points, "summary": summary}))
        .map_err(value_error)
}

/// Fits the capsules' gain and drag to a log (CSV text in the documented
/// format, or the run JSON of `simulate`): `{"calibration": ..., "fitted_config_toml": ...}`.
#[pyfunction]
#[pyo3(signature = (config, text, min_measurements))]
fn calibrate_json(
    py: Python<'_>,
    config: &PyConfig,
    text: &str,
    min_measurements: usize,
) -> PyResult<String> {
    use capsule_mpc_calibrate::{fit, fitted_config, FitSettings, TrackingLog};
    let m = config.inner.capsule_count();
    let log = if text.trim_start().starts_with('{') {
        TrackingLog::from_run_json(text, m, min_measurements)
    } else {
        TrackingLog::from_csv(text, m, min_measurements)
    }
    .map_err(value_error)?;
    let cfg = config.inner.clone();
    let cal = py
        .allow_threads(|| fit(&log, &cfg, &FitSettings::default()))
        .map_err(value_error)?;
    let fitted = fitted_config(&cfg, &cal);
    fitted
        .validate()
        .map_err(|e| ConfigError::new_err(e.to_string()))?;
    let toml = toml::to_string(&fitted).map_err(value_error)?;
    serde_json::to_string(&serde_json::json!({"calibration": cal, "fitted_config_toml": toml}))
        .map_err(value_error)
}

/// The excitation of `duration_s`: its log CSV (positions empty) and the
/// model's predicted positions.
#[pyfunction]
#[pyo3(signature = (config, duration_s))]
fn design_excitation_json(config: &PyConfig, duration_s: f64) -> PyResult<String> {
    let e =
        capsule_mpc_calibrate::design_excitation(&config.inner, duration_s).map_err(value_error)?;
    serde_json::to_string(&serde_json::json!({
        "csv": e.log.to_csv(),
        "t_s": e.log.t_s,
        "gradient_t_per_m": e.log.gradient_t_per_m,
        "actuation_rows": e.actuation_rows,
        "predicted_m": e.predicted_m,
        "push_samples": e.push_samples,
    }))
    .map_err(value_error)
}

/// What the host fed since the last actuation (as the C ABI keeps it).
#[derive(Clone, Copy)]
enum Pending<const NX: usize> {
    Nothing,
    Lost(f64),
    Positions([f64; 16], f64),
    FullState([f64; NX]),
}

/// The closed loop of one compiled-in controller.
struct Loop<S: capsule_mpc_runtime::solver::PlanSolver<NX, K>, const NX: usize, const K: usize> {
    controller: RtController<S, NX, K>,
    pending: Pending<NX>,
}

impl<S: capsule_mpc_runtime::solver::PlanSolver<NX, K>, const NX: usize, const K: usize>
    Loop<S, NX, K>
{
    fn new(positions: &[f64]) -> Result<Self, RuntimeError> {
        Ok(Loop {
            controller: RtController::new(RtController::<S, NX, K>::default_settings(), positions)?,
            pending: Pending::Nothing,
        })
    }
    fn set_sampling(&mut self, sampling: RtSampling) -> Result<(), RuntimeError> {
        let mut settings: ControllerSettings = *self.controller.settings();
        if settings.sampling == sampling {
            return Ok(());
        }
        settings.sampling = sampling;
        self.rebuild(settings)
    }
    fn set_disturbance_bound(&mut self, bound_si: f64) -> Result<(), RuntimeError> {
        let mut settings: ControllerSettings = *self.controller.settings();
        settings.disturbance_bound = bound_si;
        self.rebuild(settings)
    }
    /// The runtime fixes settings at construction: a new controller at the
    /// estimated positions, at rest, with the target kept.
    fn rebuild(&mut self, settings: ControllerSettings) -> Result<(), RuntimeError> {
        let x = self.controller.estimate();
        let positions: Vec<f64> = x.iter().step_by(2).copied().collect();
        let mut c = RtController::new(settings, &positions)?;
        if let Some(t) = self.controller.target() {
            c.set_target(t)?;
        }
        self.controller = c;
        self.pending = Pending::Nothing;
        Ok(())
    }
    fn next(&mut self, t: f64) -> Result<CycleOutput<K>, RuntimeError> {
        let ideal = self.controller.settings().sampling == RtSampling::Ideal;
        let out = match self.pending {
            Pending::Nothing if ideal => self.controller.cycle(None),
            Pending::Nothing => self.controller.cycle_at(None, t, t),
            Pending::Lost(tm) => self.controller.cycle_at(None, tm, t),
            Pending::Positions(z, tm) => self.controller.cycle_at(Some(&z[..NX / 2]), tm, t),
            Pending::FullState(x) => self.controller.cycle_full_state(&x),
        }?;
        self.pending = Pending::Nothing;
        Ok(out)
    }
}

enum AnyLoop {
    Two(Box<Loop<capsule_mpc_runtime::generated::controller::Solver, 4, 80>>),
    Three(
        Box<
            Loop<
                capsule_mpc_runtime::generated::three_capsules::Solver,
                6,
                { capsule_mpc_runtime::generated::three_capsules::spec::K },
            >,
        >,
    ),
}

macro_rules! each {
    ($self:expr, $l:ident => $body:expr) => {
        match &mut $self.inner {
            AnyLoop::Two($l) => $body,
            AnyLoop::Three($l) => $body,
        }
    };
}

fn runtime_error(e: RuntimeError) -> PyErr {
    match e {
        RuntimeError::OutsideWorkspace {
            argument,
            capsule,
            excess_m,
        } => value_error(format!(
            "{argument}: capsule {} is outside the workspace by {:.4} m ({} the bound)",
            capsule + 1,
            excess_m.abs(),
            if excess_m < 0.0 { "below" } else { "above" }
        )),
        RuntimeError::NonFinite(a) => value_error(format!("{a}: a value is not finite")),
        RuntimeError::WrongLength(a) => value_error(format!("{a}: wrong number of values")),
        RuntimeError::BadTime(a) => value_error(format!("{a}: time going backwards")),
        RuntimeError::GapBeyondProven { gap_s, max_s } => value_error(format!(
            "tracking + delay of {gap_s:.4} s is beyond the proven range ({max_s} s); \
             regenerate for the longer tracking phase, or reset after a pause"
        )),
        other => value_error(format!("{other:?}")),
    }
}

/// The compiled-in controller for a config (the default two-capsule
/// controller or the three-capsule preset's, chosen by the config's
/// solver hash), driven in the C ABI's call order.
#[pyclass(module = "capsule_mpc._native", name = "Controller", unsendable)]
struct PyController {
    inner: AnyLoop,
}

#[pymethods]
impl PyController {
    #[new]
    #[pyo3(signature = (config, positions))]
    fn new(config: &PyConfig, positions: Vec<f64>) -> PyResult<PyController> {
        use capsule_mpc_runtime::generated::{controller, three_capsules};
        let hash = capsule_mpc_generator::tables::hex(&capsule_mpc_generator::tables::solver_hash(
            &config.inner,
        ));
        let inner = if hash == controller::spec::SOLVER_SHA256 {
            AnyLoop::Two(Box::new(Loop::new(&positions).map_err(runtime_error)?))
        } else if hash == three_capsules::spec::SOLVER_SHA256 {
            AnyLoop::Three(Box::new(Loop::new(&positions).map_err(runtime_error)?))
        } else {
            return Err(ConfigError::new_err(
                "no compiled-in controller was generated for this config: regenerate (`capsule-mpc generate --config`) and rebuild the package",
            ));
        };
        Ok(PyController { inner })
    }
    fn set_sampling(&mut self, sampling: &str) -> PyResult<()> {
        let s = match sampling_of(sampling)? {
            Sampling::Ideal => RtSampling::Ideal,
            Sampling::Constant => RtSampling::Constant,
            Sampling::Variable => RtSampling::Variable,
        };
        each!(self, l => l.set_sampling(s)).map_err(runtime_error)
    }
    fn set_disturbance_bound(&mut self, bound_si: f64) -> PyResult<()> {
        if !bound_si.is_finite() {
            return Err(value_error(format!(
                "disturbance bound {bound_si} is not finite"
            )));
        }
        each!(self, l => l.set_disturbance_bound(bound_si)).map_err(runtime_error)
    }
    fn set_model_factors(
        &mut self,
        capsule: usize,
        gain: f64,
        drag: f64,
        gain_std: f64,
        drag_std: f64,
    ) -> PyResult<()> {
        each!(self, l => l.controller.set_model_factors(capsule, [gain, drag], [gain_std, drag_std]).map_err(runtime_error))
    }
    fn set_target(&mut self, target: Vec<f64>) -> PyResult<()> {
        each!(self, l => {
            let t = target.as_slice().try_into().map_err(|_| value_error(format!("target has {} entries; the controller has {} states", target.len(), l.controller.estimate().len())))?;
            l.controller.set_target(t).map_err(runtime_error)
        })
    }
    #[pyo3(signature = (positions, t_measured_s, lost = false))]
    fn feed_tracking(
        &mut self,
        positions: Vec<f64>,
        t_measured_s: f64,
        lost: bool,
    ) -> PyResult<()> {
        each!(self, l => {
            if l.controller.settings().sampling == RtSampling::Ideal {
                return Err(value_error("feed_tracking under ideal sampling: use feed_state"));
            }
            l.controller.check_measurement_time(t_measured_s).map_err(runtime_error)?;
            l.pending = if lost {
                Pending::Lost(t_measured_s)
            } else {
                let m = l.controller.estimate().len() / 2;
                if positions.len() != m {
                    return Err(value_error(format!("positions has {} entries; the controller has {m} capsules", positions.len())));
                }
                if positions.iter().any(|p| !p.is_finite()) {
                    return Err(value_error(format!("positions {positions:?} is not finite")));
                }
                let mut z = [0.0; 16];
                z[..m].copy_from_slice(&positions);
                Pending::Positions(z, t_measured_s)
            };
            Ok(())
        })
    }
    fn feed_state(&mut self, state: Vec<f64>) -> PyResult<()> {
        each!(self, l => {
            if l.controller.settings().sampling != RtSampling::Ideal {
                return Err(value_error("feed_state outside ideal sampling: use feed_tracking"));
            }
            let x = state.as_slice().try_into().map_err(|_| value_error(format!("state has {} entries", state.len())))?;
            l.pending = Pending::FullState(x);
            Ok(())
        })
    }
    /// (gradients to play, T/m, and the status code).
    fn next_actuation(&mut self, t_actuation_start_s: f64) -> PyResult<(Vec<f64>, i32)> {
        each!(self, l => {
            let out = l.next(t_actuation_start_s).map_err(runtime_error)?;
            Ok((out.gradients_t_per_m[..out.actuation_samples].to_vec(), out.status as i32))
        })
    }
    fn estimate(&mut self) -> Vec<f64> {
        each!(self, l => l.controller.estimate().to_vec())
    }
    fn reset(&mut self, positions: Vec<f64>) -> PyResult<()> {
        each!(self, l => {
            l.pending = Pending::Nothing;
            l.controller.reset(&positions).map_err(runtime_error)
        })
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyConfig>()?;
    m.add_class::<PyController>()?;
    m.add_function(wrap_pyfunction!(simulate_json, m)?)?;
    m.add_function(wrap_pyfunction!(reach_json, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_json, m)?)?;
    m.add_function(wrap_pyfunction!(design_excitation_json, m)?)?;
    m.add("ConfigError", m.py().get_type::<ConfigError>())?;
    Ok(())
}
