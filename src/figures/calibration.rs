//! The calibration figure (`calibrate --plot`): per capsule, the measured
//! positions, the fitted model's trajectory and the config's model's, from
//! the same fitted start.

use super::figure::{Figure, Panel, Series, BLUE, DARK, RED};
use super::render::render;
use anyhow::Result;
use capsule_mpc_calibrate::fit::simulate_capsule;
use capsule_mpc_calibrate::{Calibration, TrackingLog};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::Model;
use std::path::{Path, PathBuf};

/// Draws `calibration.svg` / `.png` into `dir`.
pub fn plot_calibration(
    log: &TrackingLog,
    cal: &Calibration,
    config: &Config,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let model = Model::from_config(config);
    let t = &log.t_s;
    let mut rows = Vec::new();
    for (i, (fit, cap)) in cal.capsules.iter().zip(&model.capsules).enumerate() {
        let mm = |xs: Vec<f64>| -> Vec<(f64, f64)> {
            t.iter().zip(xs).map(|(&t, x)| (t, 1e3 * x)).collect()
        };
        let fitted_drag = cap.drag.with_coefficient(fit.drag);
        let fitted = simulate_capsule(log, fit.gain, &fitted_drag, fit.x0_m, fit.v0_m_per_s, 1e-3);
        let nominal = simulate_capsule(log, cap.g, &cap.drag, fit.x0_m, fit.v0_m_per_s, 1e-3);
        let measured: Vec<(f64, f64)> = log.measurements(i).map(|(r, x)| (t[r], 1e3 * x)).collect();
        let mut dots = Series::line("measured", measured, DARK);
        dots.width = 1;
        dots.stroke = super::figure::Stroke::Dots;
        let panel = Panel {
            title: format!(
                "{}: gain {:.1} (config {:.1}) m/s^2 per T/m, drag {:.2} (config {:.2}) 1/m",
                fit.name, fit.gain, fit.gain_model, fit.drag, fit.drag_model
            ),
            y_label: "position (mm)".into(),
            series: vec![
                Series::line("fitted model", mm(fitted), BLUE),
                Series::line("config's model", mm(nominal), RED).dashed(),
                dots,
            ],
            legend: i == 0,
            ..Default::default()
        };
        rows.push(vec![panel]);
    }
    let fig = Figure {
        title: format!(
            "Calibration: residual RMS {:.3} mm",
            1e3 * cal.residual_rms_m
        ),
        x_label: "t (s)".into(),
        x_range: (t[0], *t.last().unwrap_or(&1.0)),
        rows,
    };
    render(&fig, dir, "calibration")
}
