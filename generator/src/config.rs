//! The capsule/scanner/controller configuration (TOML), in SI units.
//!
//! Parsing is strict (`deny_unknown_fields`): a misspelt key is an error, not a
//! silently ignored value. [`Config::validate`] checks every physical value and
//! names the offending field and its allowed range in the error.

use serde::{Deserialize, Serialize};
use std::path::Path;

mod validate;

/// The embedded default: Table I of the paper with the product's controller.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../configs/paper.toml");
/// The shipped three-capsule preset (spheres of 1.5, 2.2 and 3.0 mm).
pub const THREE_CAPSULES_CONFIG_TOML: &str = include_str!("../../configs/three-capsules.toml");

/// Largest number of capsules a config may describe (the emitted solver is
/// fixed-size; more capsules than this is almost certainly a typo).
pub const MAX_CAPSULES: usize = 8;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// One entry per capsule, M >= 1.
    pub capsule: Vec<CapsuleConfig>,
    pub fluid: FluidConfig,
    pub drag: DragConfig,
    pub scanner: ScannerConfig,
    pub controller: ControllerConfig,
    #[serde(default)]
    pub grid: GridConfig,
    #[serde(default)]
    pub disturbance: DisturbanceConfig,
    #[serde(default)]
    pub measurement: MeasurementConfig,
    #[serde(default)]
    pub workspace: WorkspaceConfig,
}

/// Where targets and starts may lie: a box in scanner coordinates, the same
/// interval for every capsule's position. Every target inside is reached
/// from every start inside (chaining stored plans where one is not enough).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkspaceConfig {
    /// Lowest position of any capsule, m.
    pub position_min_m: f64,
    /// Highest position of any capsule, m.
    pub position_max_m: f64,
}

/// Default workspace half-width around the scanner's origin, m.
pub const DEFAULT_WORKSPACE_HALF_WIDTH_M: f64 = 0.06;

impl Default for WorkspaceConfig {
    fn default() -> Self {
        WorkspaceConfig {
            position_min_m: -DEFAULT_WORKSPACE_HALF_WIDTH_M,
            position_max_m: DEFAULT_WORKSPACE_HALF_WIDTH_M,
        }
    }
}

impl WorkspaceConfig {
    /// Width of the box, m: the largest displacement of one capsule.
    pub fn span_m(&self) -> f64 {
        self.position_max_m - self.position_min_m
    }

    /// How far `position_m` lies outside the box (negative below, positive
    /// above), or None inside.
    pub fn excess_m(&self, position_m: f64) -> Option<f64> {
        if position_m < self.position_min_m {
            Some(position_m - self.position_min_m)
        } else if position_m > self.position_max_m {
            Some(position_m - self.position_max_m)
        } else {
            None
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CapsuleConfig {
    #[serde(default)]
    pub name: String,
    /// Radius of the ferrous sphere, m.
    pub sphere_radius_m: f64,
    /// Outer radius of the capsule (sets the frontal area for drag), m.
    pub capsule_radius_m: f64,
    /// Density of the ferrous sphere, kg/m^3.
    pub sphere_density_kg_per_m3: f64,
    /// Saturation magnetization of the sphere, A/m.
    pub saturation_magnetization_a_per_m: f64,
    /// Mass of the shell and payload, added to the sphere's mass, kg.
    #[serde(default)]
    pub shell_mass_kg: f64,
    /// Measured magnetic acceleration per gradient, m/s^2 per T/m: when
    /// given (`capsule-mpc calibrate --out` writes it), it overrides the
    /// value derived from the sphere, its magnetization and the masses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_m_per_s2_per_t_per_m: Option<f64>,
    /// Measured drag coefficient of the configured law, 1/m (the quadratic
    /// law's b in a = -b v|v|; the sphere correlation's k in
    /// a = -k C_d(Re) v|v|): when given, it overrides the value derived
    /// from the fluid, the capsule's area and the masses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drag_per_m: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FluidConfig {
    pub density_kg_per_m3: f64,
    pub dynamic_viscosity_pa_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DragLaw {
    /// F = 1/2 rho C_d A v|v| with a constant C_d (the paper's model).
    Quadratic,
    /// C_d(Re) from the Clift-Gauvin sphere correlation: Stokes drag at low
    /// Reynolds number, Newton regime at high.
    SphereCorrelation,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DragConfig {
    pub law: DragLaw,
    /// Constant drag coefficient for the `quadratic` law (dimensionless).
    #[serde(default = "default_drag_coefficient")]
    pub drag_coefficient: f64,
}

fn default_drag_coefficient() -> f64 {
    0.47
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScannerConfig {
    /// Largest gradient magnitude |u|, T/m.
    pub max_gradient_t_per_m: f64,
    /// Duration of one tracking phase (u = 0 while tracking), s.
    pub tracking_time_s: f64,
    /// Compute/transfer delay after tracking before a measurement is usable, s.
    #[serde(default)]
    pub extra_delay_s: f64,
    /// Gradient slew-rate limit, T/m/s. The simulation plays ideal steps; the
    /// Pulseq export ramps within this limit (default
    /// [`DEFAULT_SLEW_RATE_T_PER_M_PER_S`] when absent).
    #[serde(default)]
    pub slew_rate_t_per_m_per_s: Option<f64>,
    /// Gradient raster of the scanner, s, used by the Pulseq export (default
    /// [`DEFAULT_GRADIENT_RASTER_S`]). Absent from the canonical JSON (and so
    /// from the config hash) unless set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradient_raster_s: Option<f64>,
    /// Length of the RF excitation of the placeholder tracking event in the
    /// Pulseq export, s (default [`DEFAULT_TRACKING_RF_DURATION_S`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking_rf_duration_s: Option<f64>,
    /// Length of the ADC readout of the placeholder tracking event in the
    /// Pulseq export, s (default [`DEFAULT_TRACKING_ADC_DURATION_S`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking_adc_duration_s: Option<f64>,
}

/// Slew-rate limit assumed when `scanner.slew_rate_t_per_m_per_s` is absent, T/m/s.
pub const DEFAULT_SLEW_RATE_T_PER_M_PER_S: f64 = 200.0;
/// Gradient raster assumed when `scanner.gradient_raster_s` is absent, s.
pub const DEFAULT_GRADIENT_RASTER_S: f64 = 10e-6;
/// Placeholder tracking RF length when `scanner.tracking_rf_duration_s` is absent, s.
pub const DEFAULT_TRACKING_RF_DURATION_S: f64 = 1e-3;
/// Placeholder tracking ADC length when `scanner.tracking_adc_duration_s` is absent, s.
pub const DEFAULT_TRACKING_ADC_DURATION_S: f64 = 10.24e-3;

impl ScannerConfig {
    /// The slew-rate limit, T/m/s: the configured one or the default.
    pub fn slew_rate_or_default_t_per_m_per_s(&self) -> f64 {
        self.slew_rate_t_per_m_per_s
            .unwrap_or(DEFAULT_SLEW_RATE_T_PER_M_PER_S)
    }

    /// The gradient raster, s: the configured one or the default.
    pub fn gradient_raster_or_default_s(&self) -> f64 {
        self.gradient_raster_s.unwrap_or(DEFAULT_GRADIENT_RASTER_S)
    }

    /// The placeholder tracking RF length, s: the configured one or the default.
    pub fn tracking_rf_duration_or_default_s(&self) -> f64 {
        self.tracking_rf_duration_s
            .unwrap_or(DEFAULT_TRACKING_RF_DURATION_S)
    }

    /// The placeholder tracking ADC length, s: the configured one or the default.
    pub fn tracking_adc_duration_or_default_s(&self) -> f64 {
        self.tracking_adc_duration_s
            .unwrap_or(DEFAULT_TRACKING_ADC_DURATION_S)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Long-horizon plans from offline tables, refined online.
    Default,
    /// The paper's NMPC taken literally: horizon N only, shifted warm start.
    Paper,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CostUnits {
    /// Weights apply to states in m, m/s.
    Si,
    /// Weights apply to states in cm, cm/s (the paper's reading).
    Cm,
}

impl CostUnits {
    /// Factor that converts an SI length into the cost's length unit.
    pub fn length_scale(self) -> f64 {
        match self {
            CostUnits::Si => 1.0,
            CostUnits::Cm => 100.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerConfig {
    pub preset: Preset,
    /// Controller sample (zero-order-hold) time, s.
    pub sample_time_s: f64,
    /// Online refinement window N (inputs re-optimized every step).
    pub horizon_steps: usize,
    /// Length K of the long plans stored in the tables (>= N).
    pub plan_steps: usize,
    /// RK4 sub-steps per sample in the controller's model.
    pub rk4_substeps: usize,
    pub cost_units: CostUnits,
    /// Stage weights on [x1, v1, x2, v2, ...] in `cost_units`.
    pub q: Vec<f64>,
    /// Input weight, per (T/m)^2.
    pub r: f64,
    /// Terminal weights on the state in `cost_units`.
    pub p: Vec<f64>,
    /// State bound alpha on each position error, m.
    pub position_bound_m: f64,
    /// State bound alpha on each speed, m/s.
    pub speed_bound_m_per_s: f64,
    /// Online SQP iterations per control step.
    #[serde(default = "default_sqp_iterations")]
    pub sqp_iterations: usize,
    /// sigma of the switching rule (17), 0 < sigma < 1.
    #[serde(default = "default_sigma")]
    pub switching_sigma: f64,
    /// When the runtime's SQP refinement runs after the explicit tier.
    /// Skipped in the serialized form at its default, so configs that do
    /// not set it hash (and match their tables) as before.
    #[serde(default, skip_serializing_if = "RefineMode::is_default")]
    pub refine: RefineMode,
}

/// `controller.refine`: `none` (the explicit tier alone), `once` (one
/// refinement per cycle) or `per-sample` (one per sample the coming
/// actuation phase plays; the default).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RefineMode {
    None,
    Once,
    #[default]
    PerSample,
}

impl RefineMode {
    pub fn is_default(&self) -> bool {
        *self == RefineMode::default()
    }
}

fn default_sqp_iterations() -> usize {
    2
}
/// Default sigma of the switching rules. Any 0 < sigma < 1 keeps the
/// decrease (18): the optimal cost falls by at least (1 - sigma) of the cost
/// earned while actuating. 0.9 keeps a 10 % margin; with the plan refined
/// once per played sample it lets the tight rule extend actuation through
/// the end game (seeds 1-8: A settles in 1.08 s and C in 1.44 s on average,
/// duty until settled >= 0.88), where 0.5 cut phases to one sample near the
/// target (A 1.21 s, C 1.57 s, duty down to 0.74). The paper's rule (17)
/// never extends at either value on this problem.
pub const DEFAULT_SWITCHING_SIGMA: f64 = 0.9;

fn default_sigma() -> f64 {
    DEFAULT_SWITCHING_SIGMA
}

/// The generator's grid over target-relative positions (tables are built for
/// starts at rest at every grid point; see the generator docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridConfig {
    /// Half-width of the grid in each relative position, m.
    pub position_range_m: f64,
    /// Grid spacing, m.
    pub position_step_m: f64,
    /// Number of starting guesses per grid point for the offline solver.
    pub starts: usize,
    /// SQP iterations per start.
    pub sqp_iterations: usize,
    /// Half-width of the end game's fine grid of small moves from rest, m
    /// ([`DEFAULT_FINE_RANGE_M`] when absent). Absent fields are not
    /// serialized, so configs without them keep their hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_range_m: Option<f64>,
    /// Spacing of the fine grid, m ([`DEFAULT_FINE_STEP_M`] when absent).
    /// The fine grid has (2 range / step + 1)^M plans per schedule: coarser
    /// for M >= 3 keeps generation short.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fine_step_m: Option<f64>,
}

/// Fine grid half-width by default, m: the end game covers errors up to
/// 3 mm, three times the settle band.
pub const DEFAULT_FINE_RANGE_M: f64 = 3.0e-3;
/// Fine grid spacing by default, m.
pub const DEFAULT_FINE_STEP_M: f64 = 0.5e-3;

impl GridConfig {
    /// The fine grid's half-width, m.
    pub fn fine_range_m(&self) -> f64 {
        self.fine_range_m.unwrap_or(DEFAULT_FINE_RANGE_M)
    }
    /// The fine grid's spacing, m.
    pub fn fine_step_m(&self) -> f64 {
        self.fine_step_m.unwrap_or(DEFAULT_FINE_STEP_M)
    }
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            position_range_m: 0.04,
            position_step_m: 0.005,
            starts: 12,
            sqp_iterations: 40,
            fine_range_m: None,
            fine_step_m: None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DisturbanceKind {
    None,
    /// Piecewise-constant random vector, redrawn every controller sample,
    /// uniform in the ball of radius `bound`.
    Random,
    /// A constant vector of norm `bound` (worst-case bias), direction from the seed.
    Constant,
    /// A slowly varying drift: per component a sum of sinusoids with periods
    /// of 1-5 s and random phases (from the seed), scaled so that
    /// ||d|| <= `bound` at every instant. Simulation only.
    Drift,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceConfig {
    /// Bound on ||d|| (Euclidean, on the state derivative).
    pub bound: f64,
    /// Units of `bound`: "cm" reads it as cm/s and cm/s^2 (the paper's), "si" as m/s, m/s^2.
    pub units: CostUnits,
    pub kind: DisturbanceKind,
    pub seed: u64,
}

impl Default for DisturbanceConfig {
    fn default() -> Self {
        DisturbanceConfig {
            bound: 0.0,
            units: CostUnits::Si,
            kind: DisturbanceKind::None,
            seed: 1,
        }
    }
}

impl DisturbanceConfig {
    /// The bound in SI units (m/s and m/s^2).
    pub fn bound_si(&self) -> f64 {
        self.bound / self.units.length_scale()
    }

    /// The bound a controller assumes by default, SI: the configured one,
    /// 0 when the kind is `none`.
    pub fn design_bound_si(&self) -> f64 {
        if self.kind == DisturbanceKind::None {
            0.0
        } else {
            self.bound_si()
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementConfig {
    /// Standard deviation of the tracked positions, m.
    pub position_noise_m: f64,
}

impl Default for MeasurementConfig {
    fn default() -> Self {
        MeasurementConfig {
            position_noise_m: 2.0e-4,
        }
    }
}

/// A config error: which field, and what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config file {path}: {reason}")]
    Io { path: String, reason: String },
    #[error("config: {0}")]
    Parse(String),
    #[error("config field `{field}`: {reason}")]
    Invalid { field: String, reason: String },
}

/// ` (line L: `key = value`)` for the line holding byte `at` of `text`:
/// trimmed, control characters blanked, at most 80 characters.
fn source_line(text: &str, at: usize) -> String {
    let bytes = text.as_bytes();
    let at = at.min(bytes.len());
    let start = bytes[..at]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |i| i + 1);
    let end = bytes[at..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(bytes.len(), |i| at + i);
    let number = 1 + bytes[..start].iter().filter(|&&b| b == b'\n').count();
    let line: String = String::from_utf8_lossy(&bytes[start..end])
        .trim()
        .chars()
        .take(80)
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    format!(" (line {number}: `{line}`)")
}

impl Config {
    /// Parses and validates TOML text.
    pub fn from_toml_str(text: &str) -> Result<Config, ConfigError> {
        let config: Config = toml::from_str(text).map_err(|e| {
            // toml's message names unknown, missing and duplicate keys, but
            // not the key of a value of the wrong type or of an unreadable
            // number: quote the line, which does. Keep it on one line.
            ConfigError::Parse(
                e.message().replace('\n', " ").trim().to_string()
                    + &e.span()
                        .map(|s| source_line(text, s.start))
                        .unwrap_or_default(),
            )
        })?;
        config.validate()?;
        Ok(config)
    }

    /// Reads, parses and validates a TOML file.
    pub fn from_file(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Config::from_toml_str(&text)
    }

    /// The embedded default config.
    pub fn embedded_three_capsules() -> Config {
        Config::from_toml_str(THREE_CAPSULES_CONFIG_TOML)
            .expect("embedded three-capsule config is valid")
    }

    pub fn embedded_default() -> Config {
        Config::from_toml_str(DEFAULT_CONFIG_TOML).expect("embedded default config is valid")
    }

    /// Number of capsules M.
    pub fn capsule_count(&self) -> usize {
        self.capsule.len()
    }

    /// Number of states 2M: [x1, v1, x2, v2, ...].
    pub fn state_count(&self) -> usize {
        2 * self.capsule.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(edit: impl Fn(&str) -> String) -> Result<Config, ConfigError> {
        Config::from_toml_str(&edit(DEFAULT_CONFIG_TOML))
    }

    #[test]
    fn embedded_default_parses() {
        let c = Config::embedded_default();
        assert_eq!(c.capsule_count(), 2);
    }

    #[test]
    fn negative_radius_names_the_field() {
        let e = with(|t| t.replacen("sphere_radius_m = 0.0015", "sphere_radius_m = -0.0015", 1))
            .unwrap_err();
        assert!(e.to_string().contains("capsule[0].sphere_radius_m"), "{e}");
    }

    #[test]
    fn capsule_smaller_than_sphere_is_refused() {
        let e = with(|t| t.replacen("capsule_radius_m = 0.0045", "capsule_radius_m = 0.001", 1))
            .unwrap_err();
        assert!(e.to_string().contains("capsule[0].capsule_radius_m"), "{e}");
    }

    #[test]
    fn nan_is_refused() {
        let e = with(|t| t.replacen("density_kg_per_m3 = 1000.0", "density_kg_per_m3 = nan", 1))
            .unwrap_err();
        assert!(e.to_string().contains("fluid.density_kg_per_m3"), "{e}");
    }

    #[test]
    fn unknown_field_is_named() {
        let e = with(|t| t.replacen("[fluid]", "[fluid]\ntemperature_k = 310.0", 1)).unwrap_err();
        assert!(e.to_string().contains("temperature_k"), "{e}");
    }

    #[test]
    fn wrong_type_and_unreadable_number_name_the_key() {
        for (from, to) in [
            ("sphere_radius_m = 0.0015", "sphere_radius_m = \"abc\""),
            ("horizon_steps = 10", "horizon_steps = -3"),
            ("position_bound_m = 0.1", "position_bound_m = 1e400"),
            ("preset = \"default\"", "preset = 3"),
        ] {
            let e = with(|t| t.replacen(from, to, 1)).unwrap_err().to_string();
            assert!(e.contains(to), "{e}");
            assert!(!e.contains('\n'), "{e}");
        }
    }

    #[test]
    fn zero_capsules_is_refused() {
        let text: String = DEFAULT_CONFIG_TOML
            .split("[fluid]")
            .nth(1)
            .map(|rest| format!("capsule = []\n[fluid]{rest}"))
            .unwrap();
        let e = Config::from_toml_str(&text).unwrap_err();
        assert!(e.to_string().contains("`capsule`"), "{e}");
    }

    #[test]
    fn scanner_export_fields_default_without_changing_the_canonical_json() {
        let c = Config::embedded_default();
        let s = &c.scanner;
        assert_eq!(s.gradient_raster_s, None);
        assert_eq!(s.slew_rate_or_default_t_per_m_per_s(), 200.0);
        assert_eq!(s.gradient_raster_or_default_s(), 10e-6);
        assert_eq!(s.tracking_rf_duration_or_default_s(), 1e-3);
        assert_eq!(s.tracking_adc_duration_or_default_s(), 10.24e-3);
        let json = serde_json::to_string(&c).unwrap();
        for key in [
            "gradient_raster_s",
            "tracking_rf_duration_s",
            "tracking_adc_duration_s",
        ] {
            assert!(!json.contains(key), "{key} in {json}");
        }

        let set = with(|t| {
            t.replacen(
                "extra_delay_s = 0.0",
                "extra_delay_s = 0.0\nslew_rate_t_per_m_per_s = 150.0\ngradient_raster_s = 4e-6\ntracking_rf_duration_s = 5e-4\ntracking_adc_duration_s = 8e-3",
                1,
            )
        })
        .unwrap();
        let s = &set.scanner;
        assert_eq!(s.slew_rate_or_default_t_per_m_per_s(), 150.0);
        assert_eq!(s.gradient_raster_or_default_s(), 4e-6);
        assert_eq!(s.tracking_rf_duration_or_default_s(), 5e-4);
        assert_eq!(s.tracking_adc_duration_or_default_s(), 8e-3);
        assert!(serde_json::to_string(&set)
            .unwrap()
            .contains("\"gradient_raster_s\":4e-6"));
    }

    #[test]
    fn scanner_export_fields_are_validated_by_name() {
        for (line, field) in [
            ("gradient_raster_s = 0.0", "scanner.gradient_raster_s"),
            ("gradient_raster_s = 0.01", "scanner.gradient_raster_s"),
            (
                "tracking_rf_duration_s = -1e-3",
                "scanner.tracking_rf_duration_s",
            ),
            (
                "tracking_adc_duration_s = nan",
                "scanner.tracking_adc_duration_s",
            ),
            (
                "tracking_adc_duration_s = 0.019",
                "scanner.tracking_adc_duration_s",
            ),
            (
                "tracking_rf_duration_s = 0.015",
                "scanner.tracking_rf_duration_s",
            ),
        ] {
            let e = with(|t| {
                t.replacen(
                    "extra_delay_s = 0.0",
                    &format!("extra_delay_s = 0.0\n{line}"),
                    1,
                )
            })
            .unwrap_err()
            .to_string();
            assert!(e.contains(field), "{line}: {e}");
        }
    }

    #[test]
    fn weight_count_must_match_states() {
        let e =
            with(|t| t.replacen("q = [0.02, 0.0001, 0.02, 0.0001]", "q = [0.02]", 1)).unwrap_err();
        assert!(e.to_string().contains("controller.q"), "{e}");
    }
}
