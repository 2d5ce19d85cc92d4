//! The numbers behind each figure: one summary per run drawn, one per
//! figure written (`figures.json`).

use capsule_mpc_sim::report::RunReport;
use serde::Serialize;
use std::path::PathBuf;

/// Summary of one closed-loop run shown in a figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Legend label of the run ("nominal", "variable sampling", ...).
    pub label: String,
    /// Settling time (see [`capsule_mpc_sim::metrics::Metrics`]), s; `None` if never.
    pub settle_time_s: Option<f64>,
    /// Fraction of the run spent actuating.
    pub duty_cycle: f64,
    /// Largest position error at the end of the run, m.
    pub final_position_error_m: f64,
    /// Largest |u| applied, T/m.
    pub max_abs_u_t_per_m: f64,
    /// Number of position measurements (tracking phases) in the run.
    pub measurements: usize,
}

impl RunSummary {
    pub(super) fn new(label: &str, report: &RunReport) -> RunSummary {
        RunSummary {
            label: label.to_string(),
            settle_time_s: report.metrics.settle_time_s,
            duty_cycle: report.metrics.duty_cycle,
            final_position_error_m: report.metrics.final_position_error_m,
            max_abs_u_t_per_m: report.metrics.max_abs_u,
            measurements: report.measurements.len(),
        }
    }

    /// "label: settle 1.000 s, duty 0.50, final error 0.02 mm".
    pub(super) fn describe(&self) -> String {
        format!(
            "{}: settle {}, duty {:.2}, final error {:.2} mm",
            self.label,
            self.settle_time_s
                .map_or("never".to_string(), |t| format!("{t:.3} s")),
            self.duty_cycle,
            self.final_position_error_m * 1e3
        )
    }
}

/// One written figure and the numbers behind it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FigureSummary {
    /// File stem, e.g. "fig3".
    pub name: String,
    /// The SVG and PNG files written.
    pub files: Vec<PathBuf>,
    /// The runs drawn, in legend order.
    pub runs: Vec<RunSummary>,
    pub caption: String,
}

impl FigureSummary {
    /// One line: name, caption, numbers of each run.
    pub fn describe(&self) -> String {
        let runs: Vec<String> = self.runs.iter().map(RunSummary::describe).collect();
        format!("{}: {} [{}]", self.name, self.caption, runs.join("; "))
    }
}
