//! The report's figures: the paper's figures 3-7 re-made from real
//! closed-loop runs, figure 8 (the paper's NMPC preset against the default
//! controller), and their index (`figures.json`, `index.md`).

use super::figure::{Figure, Panel, Series, Stroke, BLUE, DARK, GREEN, RED};
use super::render::render;
use super::series::{
    capsule_count, clip, comparison_rows, end_time, gradient_mt_per_m, gradient_row, positions_mm,
};
use super::summary::{FigureSummary, RunSummary};
use anyhow::{bail, Context, Result};
use capsule_mpc_generator::config::{Config, DisturbanceConfig};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::SwitchingRule;
use capsule_mpc_sim::closed_loop::{run, Preset, RunOptions, Sampling, Scenario};
use capsule_mpc_sim::plant::DisturbanceLevel;
use capsule_mpc_sim::report::RunReport;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// Time window of figure 5 (close-up of the separating manoeuvre), s.
const CLOSE_UP_S: f64 = 0.6;
/// Seed of every figure run (disturbance and measurement noise).
const SEED: u64 = 1;

/// Runs the closed loop for one figure.
struct Runner {
    config: Config,
    model: Model,
    duration_s: f64,
}

impl Runner {
    fn run(
        &self,
        scenario: Scenario,
        sampling: Sampling,
        disturbance: DisturbanceLevel,
        preset: Preset,
    ) -> Result<RunReport> {
        let mut opts = RunOptions::new(&self.config, scenario.target_state(), sampling);
        opts.duration_s = self.duration_s;
        opts.seed = SEED;
        opts.preset = preset;
        opts.switching = SwitchingRule::Tight;
        opts.disturbance = match disturbance {
            DisturbanceLevel::None => DisturbanceConfig::default(),
            level => level.config(&self.model, SEED),
        };
        let mut report = run(&self.config, &opts).with_context(|| {
            format!(
                "scenario {} ({} sampling, {preset:?} preset, disturbance {disturbance:?})",
                scenario.name(),
                sampling.name()
            )
        })?;
        report.scenario = Some(scenario.name().to_string());
        report.disturbance = Some(format!("{disturbance:?}").to_lowercase());
        Ok(report)
    }
}

/// Runs the closed loop for every figure and writes `fig3`..`fig8` (SVG and
/// PNG) into `out`, plus `figures.json` and `index.md` with one line per
/// figure (caption and numbers). `duration_s` is the simulated time per run.
pub fn all_figures(out: &Path, duration_s: f64) -> Result<Vec<FigureSummary>> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        bail!("duration {duration_s} s is not a positive, finite number");
    }
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let runner = Runner {
        config,
        model,
        duration_s,
    };
    use DisturbanceLevel::{None as Nominal, Paper as Disturbed};
    use Sampling::{Constant, Ideal, Variable};

    let a_nom = runner.run(Scenario::A, Ideal, Nominal, Preset::Default)?;
    let a_dist = runner.run(Scenario::A, Ideal, Disturbed, Preset::Default)?;
    let c_nom = runner.run(Scenario::C, Ideal, Nominal, Preset::Default)?;
    let c_dist = runner.run(Scenario::C, Ideal, Disturbed, Preset::Default)?;
    let a_const = runner.run(Scenario::A, Constant, Disturbed, Preset::Default)?;
    let a_var = runner.run(Scenario::A, Variable, Disturbed, Preset::Default)?;
    let c_paper = runner.run(Scenario::C, Ideal, Nominal, Preset::Paper)?;

    let mut figures = vec![
        fig_nominal_vs_disturbed(out, "fig3", "A", &a_nom, &a_dist)?,
        fig_nominal_vs_disturbed(out, "fig4", "C", &c_nom, &c_dist)?,
        fig5_close_up(out, &c_nom)?,
        fig6_sampling(out, &a_const, &a_var)?,
        fig7_instants(out, &a_const, &a_var)?,
        fig8_paper_preset(out, &c_nom, &c_paper)?,
    ];
    for f in &mut figures {
        f.caption = f.caption.trim().to_string();
    }
    write_index(out, &figures, duration_s)?;
    Ok(figures)
}

fn target_text(report: &RunReport) -> String {
    let cm: Vec<String> = report
        .target
        .iter()
        .map(|v| format!("{}", (v * 1e2 * 1e6).round() / 1e6))
        .collect();
    format!("[{}] (cm, cm/s)", cm.join(", "))
}

fn fig_nominal_vs_disturbed(
    out: &Path,
    name: &str,
    scenario: &str,
    nominal: &RunReport,
    disturbed: &RunReport,
) -> Result<FigureSummary> {
    let t_end = end_time(nominal);
    let runs = [
        ("nominal", nominal, BLUE),
        ("disturbed (||d|| ≤ 0.05)", disturbed, RED),
    ];
    let mut rows = comparison_rows(&runs, t_end);
    rows.push(gradient_row(&runs, t_end));
    let fig = Figure {
        title: format!(
            "Scenario {scenario}: target {} · ideal sampling · nominal vs disturbed",
            target_text(nominal)
        ),
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows,
    };
    let files = render(&fig, out, name)?;
    Ok(FigureSummary {
        name: name.into(),
        files,
        runs: vec![
            RunSummary::new("nominal", nominal),
            RunSummary::new("disturbed", disturbed),
        ],
        caption: format!(
            "Scenario {scenario}, target {}: positions and velocities of both capsules, ideal sampling, \
             without disturbance (blue) and with the paper's bounded disturbance ||d|| <= 0.05 (red).",
            target_text(nominal)
        ),
    })
}

fn fig5_close_up(out: &Path, report: &RunReport) -> Result<FigureSummary> {
    let t_end = CLOSE_UP_S.min(end_time(report));
    let n = capsule_count(report);
    let colors = [BLUE, RED, GREEN, DARK];
    let mut series = Vec::new();
    for i in 0..n {
        let name = match (n, i) {
            (2, 0) => "small capsule position".to_string(),
            (2, 1) => "large capsule position".to_string(),
            _ => format!("capsule {} position", i + 1),
        };
        series.push(Series::line(
            name,
            clip(positions_mm(report, i), t_end),
            colors[i % colors.len()],
        ));
    }
    let mut gradient = Series::line(
        "gradient (right axis)",
        clip(gradient_mt_per_m(report), t_end),
        DARK,
    );
    gradient.width = 1;
    let panel = Panel {
        title: "positions (left axis) and the one shared gradient (right axis)".into(),
        y_label: "position (mm)".into(),
        series,
        secondary: Some(("gradient (mT/m)".into(), vec![gradient])),
        legend: true,
        ..Panel::default()
    };
    let fig = Figure {
        title: format!(
            "Scenario C close-up: one input separates the capsules (first {t_end:.2} s, nominal)"
        ),
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows: vec![vec![panel]],
    };
    let files = render(&fig, out, "fig5")?;
    let (x1, x2) = report
        .t
        .iter()
        .position(|&t| t >= t_end - 1e-9)
        .and_then(|k| report.x.get(k))
        .map_or((f64::NAN, f64::NAN), |x| {
            (x[0] * 1e3, x.get(2).copied().unwrap_or(f64::NAN) * 1e3)
        });
    Ok(FigureSummary {
        name: "fig5".into(),
        files,
        runs: vec![RunSummary::new("nominal", report)],
        caption: format!(
            "Close-up of figure 4 (scenario C, nominal): the first {t_end:.2} s with the gradient on the \
             right axis; one input drives the capsules apart through their different drag \
             (positions at {t_end:.2} s: {x1:.1} mm and {x2:.1} mm)."
        ),
    })
}

fn fig6_sampling(out: &Path, constant: &RunReport, variable: &RunReport) -> Result<FigureSummary> {
    let t_end = end_time(constant);
    let runs = [
        ("constant sampling", constant, BLUE),
        ("variable sampling", variable, DARK),
    ];
    let mut rows = comparison_rows(&runs, t_end);
    rows.push(gradient_row(&runs, t_end));
    let fig = Figure {
        title: "Scenario A: constant vs variable sampling (disturbed, tight switching rule)".into(),
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows,
    };
    let files = render(&fig, out, "fig6")?;
    Ok(FigureSummary {
        name: "fig6".into(),
        files,
        runs: vec![
            RunSummary::new("constant", constant),
            RunSummary::new("variable", variable),
        ],
        caption: format!(
            "Scenario A, target {}, with the paper's disturbance and measurement noise: constant \
             sampling (blue) vs variable sampling with the tight switching rule (black).",
            target_text(constant)
        ),
    })
}

fn fig7_instants(out: &Path, constant: &RunReport, variable: &RunReport) -> Result<FigureSummary> {
    let t_end = end_time(constant);
    let panel = |label: &str, report: &RunReport, color: RGBColor| -> Panel {
        let points = report
            .measurements
            .iter()
            .map(|m| (m.t_s, if m.lost { 0.5 } else { 1.0 }))
            .collect();
        Panel {
            title: format!(
                "{label}: {} tracking instants, duty cycle {:.2}",
                report.measurements.len(),
                report.metrics.duty_cycle
            ),
            y_label: "tracking (1) / actuating (0)".into(),
            series: vec![Series {
                label: Some(format!("{label}: tracking instants")),
                points,
                color,
                width: 1,
                stroke: Stroke::Stems,
            }],
            y_range: Some((0.0, 1.6)),
            legend: true,
            legend_pos: Some(SeriesLabelPosition::UpperRight),
            ..Panel::default()
        }
    };
    let fig = Figure {
        title: "Scenario A: tracking instants (stems); gaps are actuation periods".into(),
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows: vec![
            vec![panel("variable sampling", variable, DARK)],
            vec![panel("constant sampling", constant, BLUE)],
        ],
    };
    let files = render(&fig, out, "fig7")?;
    Ok(FigureSummary {
        name: "fig7".into(),
        files,
        runs: vec![
            RunSummary::new("variable", variable),
            RunSummary::new("constant", constant),
        ],
        caption: format!(
            "Tracking instants of figure 6: variable sampling ({} measurements) vs constant sampling \
             ({} measurements); between stems the gradient actuates.",
            variable.measurements.len(),
            constant.measurements.len()
        ),
    })
}

fn fig8_paper_preset(out: &Path, default: &RunReport, paper: &RunReport) -> Result<FigureSummary> {
    let t_end = end_time(default);
    let runs = [
        ("default controller", default, BLUE),
        ("paper NMPC (N = 10)", paper, RED),
    ];
    let mut rows = comparison_rows(&runs, t_end);
    rows.push(gradient_row(&runs, t_end));
    let fig = Figure {
        title: "Scenario C: default controller vs the paper's NMPC taken literally (nominal, ideal sampling)"
            .into(),
        x_label: "time (s)".into(),
        x_range: (0.0, t_end),
        rows,
    };
    let files = render(&fig, out, "fig8")?;
    Ok(FigureSummary {
        name: "fig8".into(),
        files,
        runs: vec![
            RunSummary::new("default", default),
            RunSummary::new("paper preset", paper),
        ],
        caption: format!(
            "Scenario C, target {}, nominal, ideal sampling: the default controller (blue) vs the \
             paper's NMPC with N = 10 (red), which moves both capsules together and stalls.",
            target_text(default)
        ),
    })
}

fn write_index(out: &Path, figures: &[FigureSummary], duration_s: f64) -> Result<()> {
    let json = serde_json::json!({
        "duration_s": duration_s,
        "seed": SEED,
        "figures": figures,
    });
    let text = serde_json::to_string_pretty(&json).context("serializing figures.json")?;
    let path = out.join("figures.json");
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;

    let mut md = format!(
        "# Figures\n\nMade by `capsule-mpc figures --duration {duration_s}` (seed {SEED}). \
         One line per figure: caption, then settle time, duty cycle and final position error of each run.\n\n"
    );
    for f in figures {
        let runs: Vec<String> = f.runs.iter().map(RunSummary::describe).collect();
        let _ = writeln!(
            md,
            "- [{name}]({name}.svg): {caption} {runs}.",
            name = f.name,
            caption = f.caption,
            runs = runs.join("; ")
        );
    }
    let path = out.join("index.md");
    std::fs::write(&path, md).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}
