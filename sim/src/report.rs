//! The `simulate --json` output contract ([`RunReport`]) and an atomic writer,
//! so a reader (plot script, CI check) never sees a half-written file.

use crate::metrics::Metrics;
use crate::plant::{Phase, Record};
use anyhow::{Context, Result};
use capsule_mpc_generator::model::Model;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Speed at which the effective quadratic drag coefficient b is reported, m/s
/// (only matters for the sphere-correlation law).
pub const B_REFERENCE_SPEED_M_PER_S: f64 = 0.1;

/// One position measurement as the controller received it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasurementRecord {
    /// Time the measured state refers to, s.
    pub t_s: f64,
    /// Time the measurement reached the controller (after tracking and delay), s.
    pub available_s: f64,
    pub positions_m: Vec<f64>,
    /// True when the measurement was dropped (the controller never saw it).
    pub lost: bool,
}

/// Model constants the run used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelParams {
    /// Magnetic acceleration per gradient, m/s^2 per T/m, per capsule.
    pub g: Vec<f64>,
    /// Quadratic drag coefficient, 1/m, per capsule (effective at
    /// [`B_REFERENCE_SPEED_M_PER_S`] for the sphere-correlation law).
    pub b: Vec<f64>,
}

impl ModelParams {
    pub fn from_model(model: &Model) -> ModelParams {
        ModelParams {
            g: model.capsules.iter().map(|c| c.g).collect(),
            b: model
                .capsules
                .iter()
                .map(|c| c.drag.effective_b_per_m(B_REFERENCE_SPEED_M_PER_S))
                .collect(),
        }
    }
}

/// The simulated capsules when they differ from the model the controller
/// was generated for (`--plant-drag-scale`, `--plant-gain-scale`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantReport {
    /// Factor on each capsule's drag and gain.
    pub drag_scale: Vec<f64>,
    pub gain_scale: Vec<f64>,
    /// The plant's constants (`params` holds the model's).
    pub params: ModelParams,
}

/// The factors the controller was told at the start
/// (`--calibrated-drag-scale`, `--calibrated-gain-scale`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibratedReport {
    pub drag_scale: Vec<f64>,
    pub gain_scale: Vec<f64>,
    /// Standard deviation given with each.
    pub std: f64,
}

/// Everything `simulate --json` writes. Arrays `t`, `x`, `u`, `phase` are
/// row-aligned with the plant records (`u[k]` and `phase[k]` hold from `t[k]`
/// to `t[k+1]`); `x[k]` is the true state [x1, v1, x2, v2, ...] in m, m/s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    pub t: Vec<f64>,
    pub x: Vec<Vec<f64>>,
    pub u: Vec<f64>,
    pub phase: Vec<Phase>,
    pub measurements: Vec<MeasurementRecord>,
    pub params: ModelParams,
    /// Target state [x1, v1, x2, v2, ...], m and m/s.
    pub target: Vec<f64>,
    pub metrics: Metrics,
    /// The plant when it differs from the model (None: the plant is the model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant: Option<PlantReport>,
    /// Factors the controller was told (None: it started from the model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated: Option<CalibratedReport>,
    /// The target the run started towards and when the host changed it
    /// to `target` (None: the target never changed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retarget: Option<RetargetReport>,
    /// Scenario name ("A", "C", "custom", ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<String>,
    /// Sampling scheme ("ideal", "constant", "variable").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling: Option<String>,
    /// Disturbance level name ("none", "paper", "stress").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disturbance: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Disturbance actually applied per row (SI), for audits of the bound.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d: Option<Vec<Vec<f64>>>,
    /// Cycles in which the controller applied its fallback braking law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback_cycles: Option<usize>,
    /// Cycles whose plan each solver tier produced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tier_cycles: Option<TierCycles>,
    /// How the controller took the tracking frames (scanner-cycle samplings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<FrameCounts>,
    /// The scanner cycle's timing as simulated (scanner-cycle samplings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<ScannerTiming>,
    /// The controller's mode timeline: the cycle start time at which each
    /// mode began (`Controller::mode`: no_target, hold, brake, plan,
    /// fallback), in order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modes: Option<Vec<ModeChange>>,
    /// The controller's estimate of each capsule's gain and drag factors
    /// against the model at the end of the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_factors: Option<Vec<FactorEstimate>>,
}

/// A target change during the run: the settle metrics refer to the
/// final target (`RunReport::target`) and count from the run's start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RetargetReport {
    /// When the host set the final target, s.
    pub at_s: f64,
    /// The target before it, [x1, v1, x2, v2, ...], m and m/s.
    pub first_target: Vec<f64>,
}

/// One capsule's estimated factors on its gain and drag (1 = the model),
/// with their standard deviations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FactorEstimate {
    pub gain: f64,
    pub gain_std: f64,
    pub drag: f64,
    pub drag_std: f64,
}

/// One entry of the mode timeline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModeChange {
    /// Start of the cycle that entered the mode, s (plant time).
    pub t_s: f64,
    pub mode: String,
}

/// Tracking frames by what the controller did with them: `rejected` counts
/// frames it ignored (gated out, part of a glitch, or invalid; the plant
/// simulator's frames are all true ones plus noise), `reacquired` the
/// cycles in which its estimate jumped to the frames.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameCounts {
    pub received: usize,
    pub rejected: usize,
    pub reacquired: usize,
}

/// The scanner cycle's timing: each tracking phase lasts
/// `tracking_time_s`, then `extra_delay_s` pass before the frame reaches
/// the controller; every `lose_every`-th frame is lost (None: none).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScannerTiming {
    pub tracking_time_s: f64,
    pub extra_delay_s: f64,
    pub lose_every: Option<usize>,
}

/// Cycles per solver tier (`explicit`: the explicit tier's plan was played;
/// `refined`: the SQP refinement found a cheaper one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TierCycles {
    pub explicit: usize,
    pub refined: usize,
}

impl RunReport {
    /// Builds the row arrays from plant records; the optional extras are left
    /// `None` for the caller to fill.
    pub fn from_records(
        records: &[Record],
        measurements: Vec<MeasurementRecord>,
        model: &Model,
        target: Vec<f64>,
        metrics: Metrics,
    ) -> RunReport {
        RunReport {
            t: records.iter().map(|r| r.t_s).collect(),
            x: records.iter().map(|r| r.x.clone()).collect(),
            u: records.iter().map(|r| r.u_t_per_m).collect(),
            phase: records.iter().map(|r| r.phase).collect(),
            measurements,
            params: ModelParams::from_model(model),
            target,
            metrics,
            plant: None,
            calibrated: None,
            retarget: None,
            scenario: None,
            sampling: None,
            fallback_cycles: None,
            tier_cycles: None,
            modes: None,
            estimated_factors: None,
            frames: None,
            timing: None,
            disturbance: None,
            seed: None,
            d: None,
        }
    }

    /// Writes the report as JSON to `path` atomically.
    pub fn write_json(&self, path: &Path) -> Result<()> {
        write_json_atomic(path, self)
    }
}

/// Serializes `value` as JSON into a temporary file next to `path`, flushes it
/// to disk, then renames it over `path` (atomic on one file system).
pub fn write_json_atomic<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    let bytes = serde_json::to_vec(value).context("serializing JSON")?;
    write_atomic(path, &bytes)
}

/// Writes `bytes` to `path` via a temporary file in the same directory + rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let file_name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".tmp.{}", std::process::id()));
    let tmp_path = dir.join(tmp_name);
    let result = (|| -> Result<()> {
        let mut f = std::fs::File::create(&tmp_path)
            .with_context(|| format!("cannot create {}", tmp_path.display()))?;
        f.write_all(bytes)
            .with_context(|| format!("cannot write {}", tmp_path.display()))?;
        f.sync_all()
            .with_context(|| format!("cannot flush {}", tmp_path.display()))?;
        std::fs::rename(&tmp_path, path).with_context(|| {
            format!("cannot rename {} to {}", tmp_path.display(), path.display())
        })?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp_path);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::Plant;
    use capsule_mpc_generator::config::{Config, DisturbanceConfig};

    #[test]
    fn report_round_trips_through_an_atomic_write() {
        let model = Model::from_config(&Config::embedded_default());
        let mut plant = Plant::new(
            model.clone(),
            vec![0.0; 4],
            DisturbanceConfig::default(),
            0.0,
            1,
        )
        .unwrap();
        plant.advance(0.02, 0.04, Phase::Actuate).unwrap();
        let target = vec![0.02, 0.0, 0.03, 0.0];
        let metrics = Metrics::compute(plant.records(), &target, 0.1, 0.5, 10).unwrap();
        let mut report = RunReport::from_records(plant.records(), vec![], &model, target, metrics);
        report.scenario = Some("A".into());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.json");
        report.write_json(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(value["phase"][0], "actuate");
        assert!(value.get("seed").is_none());
        let back: RunReport = serde_json::from_str(&text).unwrap();
        assert_eq!(back, report);
        // Only the final file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
