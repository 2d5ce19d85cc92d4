//! The fit: per capsule, its gain g_i, its drag coefficient b_i (the
//! configured law's: b for the quadratic law, k for the sphere
//! correlation), and its position and speed at the log's first row, by
//! Levenberg-Marquardt over every measured position of the log, the model
//! integrated with RK4 through the played gradient.

use crate::log::TrackingLog;
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::{Drag, Model};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};
use serde::{Deserialize, Serialize};

/// How the fit runs and what it flags.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSettings {
    /// Largest RK4 step of the fitted model, s.
    pub max_step_s: f64,
    /// A parameter whose standard error exceeds this fraction of its value
    /// is reported as not identified by the log.
    pub max_relative_stderr: f64,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            max_step_s: 1.0e-3,
            max_relative_stderr: 0.01,
        }
    }
}

/// Two-sided 95 % quantile of the normal distribution.
const Z95: f64 = 1.959_963_984_540_054;
/// Parameter scales of the fit (it runs on parameters of order one): the
/// model's gain and drag, 1 mm and 1 cm/s.
const POSITION_SCALE_M: f64 = 1.0e-3;
const SPEED_SCALE_M_PER_S: f64 = 1.0e-2;
/// Relative step of the finite-difference Jacobian (scaled parameters).
const JACOBIAN_STEP: f64 = 1.0e-6;

/// The deviation suggested for telling a fitted factor to a controller
/// built for the config (`CapsuleFit::told_std`): this many of the
/// factor's standard errors (the told value then covers the fit's own 3
/// sigma within one deviation) ...
pub const TOLD_STD_PER_STDERR: f64 = 3.0;
/// ... and at least 1 %: a told factor 2-3 % off the truth with a 1 %
/// deviation already costs far moves time (docs/calibrate.md).
pub const TOLD_STD_MIN: f64 = 0.01;

/// One capsule's fitted constants (SI), with standard errors and 95 %
/// intervals, and the config's values for comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CapsuleFit {
    pub name: String,
    /// Magnetic acceleration per gradient, m/s^2 per T/m.
    pub gain: f64,
    pub gain_stderr: f64,
    pub gain_ci95: [f64; 2],
    /// Drag coefficient of the configured law, 1/m.
    pub drag: f64,
    pub drag_stderr: f64,
    pub drag_ci95: [f64; 2],
    /// The config's values (before calibration).
    pub gain_model: f64,
    pub drag_model: f64,
    /// Fitted position (m) and speed (m/s) at the log's first row.
    pub x0_m: f64,
    pub v0_m_per_s: f64,
    pub measurements: usize,
    pub residual_rms_m: f64,
    /// What to tell a controller built for the config without
    /// regenerating (`Controller::set_model_factors`): the [gain, drag]
    /// factors over the config's values ...
    #[serde(default)]
    pub told_factors: [f64; 2],
    /// ... and their deviations ([`TOLD_STD_PER_STDERR`] of the factor's
    /// standard errors, at least [`TOLD_STD_MIN`], at most 1).
    #[serde(default)]
    pub told_std: [f64; 2],
}

/// The deviation to tell for a factor (fitted value over the config's)
/// fitted with standard error `factor_stderr` (1 where the log did not
/// identify it).
pub fn told_std(factor_stderr: f64) -> f64 {
    if factor_stderr.is_finite() {
        (TOLD_STD_PER_STDERR * factor_stderr).clamp(TOLD_STD_MIN, 1.0)
    } else {
        1.0
    }
}

/// What `calibrate` reports (`--json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    pub capsules: Vec<CapsuleFit>,
    /// Over every measurement of every capsule, m.
    pub residual_rms_m: f64,
    /// The drag law the fitted coefficients belong to.
    pub drag_law: String,
    pub warnings: Vec<String>,
}

/// Positions of one capsule at every row of `log` from (x0, v0) at the
/// first row, with gain `g` and drag `drag`.
pub fn simulate_capsule(
    log: &TrackingLog,
    g: f64,
    drag: &Drag,
    x0: f64,
    v0: f64,
    max_step_s: f64,
) -> Vec<f64> {
    let f = |v: f64, u: f64| drag.accel_and_slope(v).0 + g * u;
    let mut out = Vec::with_capacity(log.t_s.len());
    let (mut x, mut v) = (x0, v0);
    out.push(x);
    for r in 0..log.t_s.len().saturating_sub(1) {
        let dt = log.t_s[r + 1] - log.t_s[r];
        let u = log.gradient_t_per_m[r];
        let steps = (dt / max_step_s).ceil().max(1.0) as usize;
        let h = dt / steps as f64;
        for _ in 0..steps {
            let (k1x, k1v) = (v, f(v, u));
            let (k2x, k2v) = (v + 0.5 * h * k1v, f(v + 0.5 * h * k1v, u));
            let (k3x, k3v) = (v + 0.5 * h * k2v, f(v + 0.5 * h * k2v, u));
            let (k4x, k4v) = (v + h * k3v, f(v + h * k3v, u));
            x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        }
        out.push(x);
    }
    out
}

/// The least-squares problem of one capsule, on scaled parameters
/// [g / g_model, c / c_model, x0 / 1 mm, v0 / 1 cm/s].
struct CapsuleProblem<'a> {
    log: &'a TrackingLog,
    rows: Vec<usize>,
    measured: Vec<f64>,
    g_model: f64,
    drag_model: Drag,
    p: DVector<f64>,
    max_step_s: f64,
}

impl CapsuleProblem<'_> {
    fn residuals_at(&self, p: &DVector<f64>) -> DVector<f64> {
        let c = self.drag_model.coefficient() * p[1];
        let drag = self.drag_model.with_coefficient(c);
        let x = simulate_capsule(
            self.log,
            self.g_model * p[0],
            &drag,
            p[2] * POSITION_SCALE_M,
            p[3] * SPEED_SCALE_M_PER_S,
            self.max_step_s,
        );
        DVector::from_iterator(
            self.rows.len(),
            self.rows
                .iter()
                .zip(&self.measured)
                .map(|(&r, &z)| x[r] - z),
        )
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for CapsuleProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.p.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.p.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = self.residuals_at(&self.p);
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let n = self.p.len();
        let mut j = DMatrix::zeros(self.rows.len(), n);
        for k in 0..n {
            let h = JACOBIAN_STEP * self.p[k].abs().max(1.0);
            let (mut plus, mut minus) = (self.p.clone(), self.p.clone());
            plus[k] += h;
            minus[k] -= h;
            let d = (self.residuals_at(&plus) - self.residuals_at(&minus)) / (2.0 * h);
            j.set_column(k, &d);
        }
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

/// Fits every capsule of `config` to `log` (see the module docs).
pub fn fit(
    log: &TrackingLog,
    config: &Config,
    settings: &FitSettings,
) -> Result<Calibration, String> {
    let model = Model::from_config(config);
    let m = model.capsule_count();
    if log.capsule_count() != m {
        return Err(format!(
            "the log has {} capsules, the config {m}",
            log.capsule_count()
        ));
    }
    let mut capsules = Vec::with_capacity(m);
    let mut warnings = Vec::new();
    let (mut sq_sum, mut count) = (0.0, 0usize);
    for (i, cap) in model.capsules.iter().enumerate() {
        let name = match config.capsule[i].name.as_str() {
            "" => format!("capsule {}", i + 1),
            n => n.to_string(),
        };
        let (rows, measured): (Vec<usize>, Vec<f64>) = log.measurements(i).unzip();
        let problem = CapsuleProblem {
            log,
            p: DVector::from_vec(vec![1.0, 1.0, measured[0] / POSITION_SCALE_M, 0.0]),
            rows,
            measured,
            g_model: cap.g,
            drag_model: cap.drag,
            max_step_s: settings.max_step_s,
        };
        let (problem, report) = LevenbergMarquardt::new().minimize(problem);
        if !report.termination.was_successful() {
            warnings.push(format!(
                "{name}: the fit did not converge ({:?})",
                report.termination
            ));
        }
        let r = problem
            .residuals()
            .ok_or_else(|| format!("{name}: the fitted model is not finite"))?;
        let j = problem
            .jacobian()
            .ok_or_else(|| format!("{name}: the fitted model is not finite"))?;
        let n = r.len();
        let dof = n.saturating_sub(4).max(1);
        let ssr = r.norm_squared();
        let sigma2 = ssr / dof as f64;
        let jtj = j.transpose() * &j;
        let cov = jtj.try_inverse().ok_or_else(|| {
            format!("{name}: the log does not identify the parameters (singular normal matrix)")
        })? * sigma2;
        let p = &problem.p;
        let c_model = cap.drag.coefficient();
        let (gain, drag) = (cap.g * p[0], c_model * p[1]);
        let gain_stderr = cap.g * cov[(0, 0)].max(0.0).sqrt();
        let drag_stderr = c_model * cov[(1, 1)].max(0.0).sqrt();
        for (what, value, stderr) in [("gain", gain, gain_stderr), ("drag", drag, drag_stderr)] {
            // NaN (no information at all) counts as not identified.
            if stderr.is_nan() || stderr > settings.max_relative_stderr * value.abs() {
                warnings.push(format!(
                    "{name}: the log does not excite the {what} enough to identify it (standard error {:.2} % of the value, more than {:.2} %): play a longer or stronger excitation (`calibrate --design`)",
                    100.0 * stderr / value.abs(),
                    100.0 * settings.max_relative_stderr
                ));
            }
        }
        sq_sum += ssr;
        count += n;
        capsules.push(CapsuleFit {
            name,
            gain,
            gain_stderr,
            gain_ci95: [gain - Z95 * gain_stderr, gain + Z95 * gain_stderr],
            drag,
            drag_stderr,
            drag_ci95: [drag - Z95 * drag_stderr, drag + Z95 * drag_stderr],
            gain_model: cap.g,
            drag_model: c_model,
            x0_m: p[2] * POSITION_SCALE_M,
            v0_m_per_s: p[3] * SPEED_SCALE_M_PER_S,
            measurements: n,
            residual_rms_m: (ssr / n as f64).sqrt(),
            told_factors: [p[0], p[1]],
            told_std: [
                told_std(cov[(0, 0)].max(0.0).sqrt()),
                told_std(cov[(1, 1)].max(0.0).sqrt()),
            ],
        });
    }
    Ok(Calibration {
        capsules,
        residual_rms_m: (sq_sum / count.max(1) as f64).sqrt(),
        drag_law: match model.capsules.first().map(|c| c.drag) {
            Some(Drag::SphereCorrelation { .. }) => "sphere-correlation".into(),
            _ => "quadratic".into(),
        },
        warnings,
    })
}

/// `base` with the fitted gain and drag of every capsule as explicit
/// overrides (`gain_m_per_s2_per_t_per_m`, `drag_per_m`); everything else
/// as it was.
pub fn fitted_config(base: &Config, calibration: &Calibration) -> Config {
    let mut c = base.clone();
    for (cap, fit) in c.capsule.iter_mut().zip(&calibration.capsules) {
        cap.gain_m_per_s2_per_t_per_m = Some(fit.gain);
        cap.drag_per_m = Some(fit.drag);
    }
    c
}
