//! A plant that is not quite the model: per-capsule factors on the drag
//! and on the magnetic gain of the simulated capsules, while the
//! controller keeps the model it was generated for. Nobody knows a real
//! capsule's drag coefficient, effective mass or magnetization to better
//! than 10-20 %, so this is how a controller meets real capsules.

use anyhow::{bail, Result};
use capsule_mpc_generator::model::Model;
use serde::{Deserialize, Serialize};

/// Smallest and largest factor accepted: beyond these the "capsule" is
/// another capsule, and the config should say so.
pub const MIN_SCALE: f64 = 0.25;
pub const MAX_SCALE: f64 = 4.0;

/// Factors on the simulated capsules' drag and gain (empty: 1 for all).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PlantMismatch {
    /// Drag factor per capsule (one value: the same for all).
    pub drag_scale: Vec<f64>,
    /// Gain (magnetic acceleration per gradient) factor per capsule.
    pub gain_scale: Vec<f64>,
}

impl PlantMismatch {
    /// The same factors for every capsule.
    pub fn uniform(drag_scale: f64, gain_scale: f64) -> PlantMismatch {
        PlantMismatch {
            drag_scale: vec![drag_scale],
            gain_scale: vec![gain_scale],
        }
    }

    /// From optional per-capsule lists (absent: the model's 1 for all), as
    /// the CLI's and Python's `*_drag_scale` / `*_gain_scale` arguments give
    /// them.
    pub fn from_scales(
        drag_scale: Option<Vec<f64>>,
        gain_scale: Option<Vec<f64>>,
    ) -> PlantMismatch {
        PlantMismatch {
            drag_scale: drag_scale.unwrap_or_default(),
            gain_scale: gain_scale.unwrap_or_default(),
        }
    }

    /// Whether the plant is the model.
    pub fn is_nominal(&self) -> bool {
        self.drag_scale
            .iter()
            .chain(&self.gain_scale)
            .all(|&s| s == 1.0)
    }

    /// Per-capsule factors of `values` for `m` capsules (one value or m),
    /// checked; `name` is the option that gave them.
    fn expand(name: &str, values: &[f64], m: usize) -> Result<Vec<f64>> {
        let all = match values.len() {
            0 => vec![1.0; m],
            1 => vec![values[0]; m],
            n if n == m => values.to_vec(),
            n => {
                bail!("{name} has {n} factors; give one for all capsules or one per capsule ({m})")
            }
        };
        for (i, &s) in all.iter().enumerate() {
            if !(s.is_finite() && (MIN_SCALE..=MAX_SCALE).contains(&s)) {
                bail!(
                    "{name}: factor {s} for capsule {} is outside [{MIN_SCALE}, {MAX_SCALE}]",
                    i + 1
                );
            }
        }
        Ok(all)
    }

    /// Per-capsule drag and gain factors for `m` capsules.
    pub fn factors(&self, m: usize) -> Result<(Vec<f64>, Vec<f64>)> {
        self.factors_named(m, "plant")
    }

    /// As `factors`, errors naming the options `--{what}-drag-scale` and
    /// `--{what}-gain-scale` ("plant", "calibrated").
    pub fn factors_named(&self, m: usize, what: &str) -> Result<(Vec<f64>, Vec<f64>)> {
        Ok((
            Self::expand(&format!("{what} drag scale"), &self.drag_scale, m)?,
            Self::expand(&format!("{what} gain scale"), &self.gain_scale, m)?,
        ))
    }

    /// The plant's model: `model` with the factors applied.
    pub fn apply(&self, model: &Model) -> Result<Model> {
        let (drag, gain) = self.factors(model.capsule_count())?;
        let mut plant = model.clone();
        for ((c, d), g) in plant.capsules.iter_mut().zip(drag).zip(gain) {
            c.g *= g;
            c.drag = c.drag.with_coefficient(c.drag.coefficient() * d);
        }
        Ok(plant)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use capsule_mpc_generator::config::Config;

    #[test]
    fn factors_scale_drag_and_gain_per_capsule() {
        let model = Model::from_config(&Config::embedded_default());
        let m = PlantMismatch {
            drag_scale: vec![1.2, 0.8],
            gain_scale: vec![0.9],
        };
        let plant = m.apply(&model).unwrap();
        for i in 0..2 {
            let (a, _) = model.capsules[i].drag.accel_and_slope(0.1);
            let (b, _) = plant.capsules[i].drag.accel_and_slope(0.1);
            assert!((b / a - [1.2, 0.8][i]).abs() < 1e-12);
            assert!((plant.capsules[i].g / model.capsules[i].g - 0.9).abs() < 1e-12);
        }
        assert!(!m.is_nominal());
        assert!(PlantMismatch::default().is_nominal());
        assert_eq!(PlantMismatch::default().apply(&model).unwrap(), model);
    }

    #[test]
    fn bad_factors_are_refused_by_name() {
        let model = Model::from_config(&Config::embedded_default());
        for (m, needle) in [
            (
                PlantMismatch {
                    drag_scale: vec![1.0, 1.0, 1.0],
                    gain_scale: vec![],
                },
                "plant drag scale has 3 factors",
            ),
            (
                PlantMismatch {
                    drag_scale: vec![f64::NAN],
                    gain_scale: vec![],
                },
                "plant drag scale: factor NaN",
            ),
            (
                PlantMismatch {
                    drag_scale: vec![],
                    gain_scale: vec![1.0, 0.0],
                },
                "plant gain scale: factor 0 for capsule 2",
            ),
            (
                PlantMismatch {
                    drag_scale: vec![9.0],
                    gain_scale: vec![],
                },
                "outside [0.25, 4]",
            ),
        ] {
            let err = m.apply(&model).unwrap_err().to_string();
            assert!(err.contains(needle), "{err}");
        }
    }
}
