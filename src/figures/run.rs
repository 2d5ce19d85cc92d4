//! The plot of one run (`simulate --plot`).

use super::figure::{Figure, BLUE, DARK, GREEN};
use super::render::render;
use super::series::{comparison_rows, end_time, gradient_row, tracking_series};
use anyhow::{bail, Result};
use capsule_mpc_sim::report::RunReport;
use std::path::{Path, PathBuf};

/// Plots one run: positions (mm) and velocities (mm/s) of each capsule with
/// the targets (dashed) and ±1 mm settling bands, and the gradient (mT/m)
/// below. Writes `run.svg` and `run.png` into `dir` and returns their paths.
pub fn plot_run(report: &RunReport, dir: &Path) -> Result<Vec<PathBuf>> {
    if report.t.is_empty() {
        bail!("the run has no records to plot");
    }
    let t_end = end_time(report);
    let mut rows = comparison_rows(&[("run", report, BLUE)], t_end);
    let mut grad = gradient_row(&[("gradient", report, DARK)], t_end);
    if let Some(tracking) = tracking_series(report, "tracking", GREEN) {
        grad[0].series.push(tracking);
        grad[0].legend = true;
        grad[0].series[0].label = Some("gradient".into());
    }
    rows.push(grad);
    let m = &report.metrics;
    let title = format!(
        "Scenario {} · {} sampling · disturbance {} · settle {} · duty {:.2}",
        report.scenario.as_deref().unwrap_or("?"),
        report.sampling.as_deref().unwrap_or("?"),
        report.disturbance.as_deref().unwrap_or("?"),
        m.settle_time_s
            .map_or("never".to_string(), |t| format!("{t:.3} s")),
        m.duty_cycle
    );
    let fig = Figure {
        title,
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows,
    };
    render(&fig, dir, "run")
}
