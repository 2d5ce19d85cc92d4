//! Figures of the report (`capsule-mpc figures`, `simulate --plot`): the
//! paper's figures 3-7 re-made from real closed-loop runs, plus figure 8
//! (the paper's NMPC preset against the default controller).
//!
//! Each figure is first described as data ([`Figure`]: rows of panels, each
//! with its series) and then rendered twice by one generic drawing routine,
//! to SVG and to PNG. Text uses an embedded DejaVu Sans, so no system font
//! or fontconfig is needed.

use crate::cli::{Sampling, Scenario};
use crate::closed_loop::{run, Preset, RunOptions};
use crate::metrics::SETTLE_POSITION_TOL_M;
use crate::plant::{DisturbanceLevel, Phase};
use crate::report::RunReport;
use anyhow::{anyhow, bail, Context, Result};
use capsule_mpc_generator::config::{Config, DisturbanceConfig};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::SwitchingRule;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The embedded font (see `assets/DejaVu-LICENSE`).
const FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const FONT: &str = "sans-serif";

/// Pixel size of every figure (SVG user units and PNG pixels).
const FIGURE_SIZE: (u32, u32) = (1280, 960);
/// Time window of figure 5 (close-up of the separating manoeuvre), s.
const CLOSE_UP_S: f64 = 0.6;
/// Seed of every figure run (disturbance and measurement noise).
const SEED: u64 = 1;

const BLUE: RGBColor = RGBColor(31, 90, 200);
const RED: RGBColor = RGBColor(210, 40, 40);
const DARK: RGBColor = RGBColor(20, 20, 20);
const GREEN: RGBColor = RGBColor(20, 140, 60);
const BAND: RGBColor = RGBColor(200, 200, 200);

/// Summary of one closed-loop run shown in a figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Legend label of the run ("nominal", "variable sampling", ...).
    pub label: String,
    /// Settling time (see [`crate::metrics::Metrics`]), s; `None` if never.
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
    fn new(label: &str, report: &RunReport) -> RunSummary {
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
    fn describe(&self) -> String {
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

// ---------------------------------------------------------------------------
// Figure description

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stroke {
    Solid,
    Dashed,
    /// A vertical stem from 0 to each point, with a dot on top.
    Stems,
}

#[derive(Debug, Clone)]
struct Series {
    label: Option<String>,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    width: u32,
    stroke: Stroke,
}

impl Series {
    fn line(label: impl Into<String>, points: Vec<(f64, f64)>, color: RGBColor) -> Series {
        Series {
            label: Some(label.into()),
            points,
            color,
            width: 2,
            stroke: Stroke::Solid,
        }
    }

    fn unlabelled(mut self) -> Series {
        self.label = None;
        self
    }

    fn dashed(mut self) -> Series {
        self.stroke = Stroke::Dashed;
        self.width = 1;
        self
    }
}

/// A horizontal band (the settling tolerance around a target).
#[derive(Debug, Clone)]
struct Band {
    label: Option<String>,
    y_lo: f64,
    y_hi: f64,
}

#[derive(Debug, Clone, Default)]
struct Panel {
    title: String,
    y_label: String,
    series: Vec<Series>,
    bands: Vec<Band>,
    /// Series on a right-hand axis: (axis label, series).
    secondary: Option<(String, Vec<Series>)>,
    /// Fixed y range instead of one fitted to the data.
    y_range: Option<(f64, f64)>,
    legend: bool,
    /// Where the legend goes (lower right when `None`).
    legend_pos: Option<SeriesLabelPosition>,
}

#[derive(Debug, Clone)]
struct Figure {
    title: String,
    x_label: String,
    x_range: (f64, f64),
    /// Rows of panels, each row split evenly between its panels.
    rows: Vec<Vec<Panel>>,
}

// ---------------------------------------------------------------------------
// Rendering

fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "the embedded font DejaVuSans.ttf is not a valid font".to_string())
        })
        .clone()
        .map_err(|e| anyhow!(e))
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e}")
}

/// Writes `fig` as `<dir>/<stem>.svg` and `<dir>/<stem>.png`.
fn render(fig: &Figure, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    register_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    {
        let root = SVGBackend::new(&svg, FIGURE_SIZE).into_drawing_area();
        draw_figure(&root, fig).with_context(|| format!("drawing {}", svg.display()))?;
        root.present()
            .map_err(plot_err)
            .with_context(|| format!("cannot write {}", svg.display()))?;
    }
    {
        let root = BitMapBackend::new(&png, FIGURE_SIZE).into_drawing_area();
        draw_figure(&root, fig).with_context(|| format!("drawing {}", png.display()))?;
        root.present()
            .map_err(plot_err)
            .with_context(|| format!("cannot write {}", png.display()))?;
    }
    Ok(vec![svg, png])
}

fn draw_figure<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let body = root
        .titled(&fig.title, (FONT, 26).into_font().color(&DARK))
        .map_err(plot_err)?;
    let rows = body.split_evenly((fig.rows.len().max(1), 1));
    for (row, area) in fig.rows.iter().zip(&rows) {
        let cells = area.split_evenly((1, row.len().max(1)));
        for (panel, cell) in row.iter().zip(&cells) {
            draw_panel(cell, panel, fig)?;
        }
    }
    Ok(())
}

/// (min, max) of the y values of `series` and `bands`, padded by 6 %.
fn fit_range(series: &[Series], bands: &[Band]) -> (f64, f64) {
    let ys = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .chain(bands.iter().flat_map(|b| [b.y_lo, b.y_hi]))
        .chain(
            series
                .iter()
                .filter(|s| s.stroke == Stroke::Stems)
                .map(|_| 0.0),
        )
        .filter(|y| y.is_finite());
    let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
        (lo.min(y), hi.max(y))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let span = (hi - lo).max(1e-9 + 1e-3 * hi.abs().max(lo.abs()));
    let pad = 0.06 * span.max(1e-3);
    (lo - pad, hi + pad)
}

type Area<DB> = DrawingArea<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn draw_panel<DB: DrawingBackend>(
    cell: &DrawingArea<DB, Shift>,
    panel: &Panel,
    fig: &Figure,
) -> Result<()> {
    let (x0, x1) = fig.x_range;
    let (y0, y1) = panel
        .y_range
        .unwrap_or_else(|| fit_range(&panel.series, &panel.bands));
    let mut builder = ChartBuilder::on(cell);
    builder
        .margin(10)
        .x_label_area_size(42)
        .y_label_area_size(70)
        .caption(&panel.title, (FONT, 18).into_font().color(&DARK));
    if panel.secondary.is_some() {
        builder.right_y_label_area_size(70);
    }
    let mut chart = builder
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    match &panel.secondary {
        None => {
            draw_primary(&mut chart, panel, fig)?;
            draw_legend(&mut chart, panel)?;
        }
        Some((label, secondary)) => {
            // The secondary coordinate takes over the right label area, so it
            // is attached before the primary mesh is drawn.
            let (s0, s1) = fit_range(secondary, &[]);
            let mut dual = chart.set_secondary_coord(x0..x1, s0..s1);
            draw_primary(&mut dual, panel, fig)?;
            dual.configure_secondary_axes()
                .y_desc(label)
                .axis_desc_style((FONT, 15).into_font())
                .label_style((FONT, 13).into_font())
                .draw()
                .map_err(plot_err)?;
            let area = dual.secondary_plotting_area().clone();
            for s in secondary {
                draw_series(&area, s)?;
                if panel.legend {
                    add_legend(&mut dual, s)?;
                }
            }
            draw_legend(&mut dual, panel)?;
        }
    }
    Ok(())
}

/// Mesh, axis labels, bands and series of the primary (left) axis.
fn draw_primary<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    panel: &Panel,
    fig: &Figure,
) -> Result<()> {
    let (x0, x1) = fig.x_range;
    chart
        .configure_mesh()
        .x_desc(&fig.x_label)
        .y_desc(&panel.y_label)
        .axis_desc_style((FONT, 15).into_font())
        .label_style((FONT, 13).into_font())
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;

    let area = chart.plotting_area().clone();
    for band in &panel.bands {
        area.draw(&Rectangle::new(
            [(x0, band.y_lo), (x1, band.y_hi)],
            BAND.mix(0.45).filled(),
        ))
        .map_err(plot_err)?;
        if let (true, Some(label)) = (panel.legend, &band.label) {
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(plot_err)?
                .label(label)
                .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], BAND.filled()));
        }
    }
    for s in &panel.series {
        draw_series(&area, s)?;
        if panel.legend {
            add_legend(chart, s)?;
        }
    }
    Ok(())
}

fn draw_series<DB: DrawingBackend>(area: &Area<DB>, s: &Series) -> Result<()> {
    let style = ShapeStyle::from(&s.color).stroke_width(s.width);
    match s.stroke {
        Stroke::Solid => area
            .draw(&PathElement::new(s.points.clone(), style))
            .map_err(plot_err),
        Stroke::Dashed => area
            .draw(&DashedPathElement::new(
                s.points.iter().copied(),
                8,
                6,
                style,
            ))
            .map_err(plot_err),
        Stroke::Stems => {
            for &(x, y) in &s.points {
                area.draw(&PathElement::new(vec![(x, 0.0), (x, y)], style))
                    .map_err(plot_err)?;
                area.draw(&Circle::new((x, y), 3, s.color.filled()))
                    .map_err(plot_err)?;
            }
            Ok(())
        }
    }
}

/// Registers a legend entry for `s` (drawn by [`draw_series`]) with an empty
/// series, so that primary and secondary series share one legend.
fn add_legend<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    s: &Series,
) -> Result<()> {
    let Some(label) = &s.label else {
        return Ok(());
    };
    let (color, width, stroke) = (s.color, s.width, s.stroke);
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
        .map_err(plot_err)?
        .label(label)
        .legend(move |(x, y)| {
            // One element type for both strokes: a solid line is a single
            // dash longer than the 22 px sample.
            let (dash, gap) = match stroke {
                Stroke::Dashed => (5, 3),
                Stroke::Solid | Stroke::Stems => (30, 1),
            };
            let style = ShapeStyle::from(&color).stroke_width(width.max(2));
            DashedPathElement::new(vec![(x, y), (x + 22, y)], dash, gap, style)
        });
    Ok(())
}

fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    panel: &Panel,
) -> Result<()> {
    if !panel.legend {
        return Ok(());
    }
    chart
        .configure_series_labels()
        .position(
            panel
                .legend_pos
                .clone()
                .unwrap_or(SeriesLabelPosition::LowerRight),
        )
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(150, 150, 150))
        .label_font((FONT, 14).into_font())
        .draw()
        .map_err(plot_err)
}

// ---------------------------------------------------------------------------
// Series from run reports

fn capsule_count(report: &RunReport) -> usize {
    report.target.len() / 2
}

/// Position (mm) of capsule `i` over time.
fn positions_mm(report: &RunReport, i: usize) -> Vec<(f64, f64)> {
    report
        .t
        .iter()
        .zip(&report.x)
        .map(|(&t, x)| (t, x[2 * i] * 1e3))
        .collect()
}

/// Velocity (mm/s) of capsule `i` over time.
fn velocities_mm_s(report: &RunReport, i: usize) -> Vec<(f64, f64)> {
    report
        .t
        .iter()
        .zip(&report.x)
        .map(|(&t, x)| (t, x[2 * i + 1] * 1e3))
        .collect()
}

/// The gradient (mT/m) as a staircase: `u[k]` holds from `t[k]` to `t[k+1]`.
fn gradient_mt_per_m(report: &RunReport) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = Vec::new();
    for (k, (&t, &u)) in report.t.iter().zip(&report.u).enumerate() {
        let Some(&next) = report.t.get(k + 1) else {
            break;
        };
        let u = u * 1e3;
        match points.last_mut() {
            // Same level as the step before: extend it (rows are 1 ms apart
            // while u changes every sample; keeps the SVGs small).
            Some(last) if last.1 == u => last.0 = next,
            _ => points.extend([(t, u), (next, u)]),
        }
    }
    points
}

/// Keeps the points with x <= `t_end` (plus one beyond, for continuity).
fn clip(points: Vec<(f64, f64)>, t_end: f64) -> Vec<(f64, f64)> {
    let keep = points.iter().take_while(|p| p.0 <= t_end).count();
    points.into_iter().take(keep + 1).collect()
}

fn end_time(report: &RunReport) -> f64 {
    report.t.last().copied().unwrap_or(0.0).max(1e-3)
}

/// The dashed target line of capsule `i` (mm) and its ±1 mm settling band.
fn target_decor(report: &RunReport, i: usize, t_end: f64, labelled: bool) -> (Series, Band) {
    let target_mm = report.target[2 * i] * 1e3;
    let tol_mm = SETTLE_POSITION_TOL_M * 1e3;
    let mut line =
        Series::line("target", vec![(0.0, target_mm), (t_end, target_mm)], DARK).dashed();
    let mut band = Band {
        label: Some(format!("target ±{tol_mm:.0} mm")),
        y_lo: target_mm - tol_mm,
        y_hi: target_mm + tol_mm,
    };
    if !labelled {
        line.label = None;
        band.label = None;
    }
    (line, band)
}

/// Name of capsule `i` for panel titles ("capsule 1 (small)").
fn capsule_name(i: usize, n: usize) -> String {
    match (n, i) {
        (2, 0) => "capsule 1 (small sphere)".to_string(),
        (2, 1) => "capsule 2 (large sphere)".to_string(),
        _ => format!("capsule {}", i + 1),
    }
}

/// Position and velocity rows comparing several runs (same target), one
/// column per capsule. The first panel holds the legend.
fn comparison_rows(runs: &[(&str, &RunReport, RGBColor)], t_end: f64) -> Vec<Vec<Panel>> {
    let Some((_, first, _)) = runs.first() else {
        return vec![];
    };
    let n = capsule_count(first);
    let mut pos_row = Vec::new();
    let mut vel_row = Vec::new();
    for i in 0..n {
        let legend = i == 0;
        let (target, band) = target_decor(first, i, t_end, legend);
        let mut pos = Panel {
            title: format!("{}: position", capsule_name(i, n)),
            y_label: "position (mm)".into(),
            bands: vec![band],
            legend,
            ..Panel::default()
        };
        let mut vel = Panel {
            title: format!("{}: velocity", capsule_name(i, n)),
            y_label: "velocity (mm/s)".into(),
            ..Panel::default()
        };
        for (label, report, color) in runs {
            let s = Series::line(*label, clip(positions_mm(report, i), t_end), *color);
            pos.series.push(if legend { s } else { s.unlabelled() });
            vel.series.push(
                Series::line(*label, clip(velocities_mm_s(report, i), t_end), *color).unlabelled(),
            );
        }
        pos.series.push(target);
        vel.series.push(
            Series::line("", vec![(0.0, 0.0), (t_end, 0.0)], DARK)
                .dashed()
                .unlabelled(),
        );
        pos_row.push(pos);
        vel_row.push(vel);
    }
    vec![pos_row, vel_row]
}

/// A full-width gradient panel for the given runs.
fn gradient_row(runs: &[(&str, &RunReport, RGBColor)], t_end: f64) -> Vec<Panel> {
    let series = runs
        .iter()
        .map(|(label, report, color)| {
            let mut s = Series::line(*label, clip(gradient_mt_per_m(report), t_end), *color);
            s.width = 1;
            s
        })
        .collect();
    vec![Panel {
        title: "gradient input (shared by all capsules)".into(),
        y_label: "gradient (mT/m)".into(),
        series,
        legend: runs.len() > 1,
        ..Panel::default()
    }]
}

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

/// Stems at the tracking instants, scaled to the gradient axis (only when the
/// run has tracking phases, i.e. not ideal sampling).
fn tracking_series(report: &RunReport, label: &str, color: RGBColor) -> Option<Series> {
    if !report.phase.contains(&Phase::Track) {
        return None;
    }
    let height = (report.metrics.max_abs_u * 1e3 * 0.25).max(1.0);
    Some(Series {
        label: Some(label.into()),
        points: report
            .measurements
            .iter()
            .filter(|m| !m.lost)
            .map(|m| (m.t_s, height))
            .collect(),
        color,
        width: 1,
        stroke: Stroke::Stems,
    })
}

// ---------------------------------------------------------------------------
// The report's figures

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
    let config = crate::cli::load_config(None)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_range_pads_and_handles_empty_and_flat_data() {
        assert_eq!(fit_range(&[], &[]), (-1.0, 1.0));
        let flat = Series::line("x", vec![(0.0, 2.0), (1.0, 2.0)], BLUE);
        let (lo, hi) = fit_range(&[flat], &[]);
        assert!(lo < 2.0 && hi > 2.0);
        let band = Band {
            label: None,
            y_lo: -1.0,
            y_hi: 5.0,
        };
        let (lo, hi) = fit_range(&[], &[band]);
        assert!(lo < -1.0 && hi > 5.0);
    }

    #[test]
    fn gradient_is_a_staircase_in_mt_per_m() {
        let mut report = sample_report();
        report.t = vec![0.0, 0.01, 0.02, 0.04];
        report.u = vec![0.04, 0.04, -0.01, 0.0];
        // Equal consecutive levels merge; the last row has no duration.
        let g = gradient_mt_per_m(&report);
        assert_eq!(g, [(0.0, 40.0), (0.02, 40.0), (0.02, -10.0), (0.04, -10.0)]);
    }

    fn sample_report() -> RunReport {
        use crate::metrics::Metrics;
        RunReport {
            t: vec![0.0],
            x: vec![vec![0.0; 4]],
            u: vec![0.0],
            phase: vec![Phase::Actuate],
            measurements: vec![],
            params: crate::report::ModelParams {
                g: vec![],
                b: vec![],
            },
            target: vec![0.02, 0.0, 0.03, 0.0],
            metrics: Metrics {
                settle_time_s: None,
                final_position_error_m: 0.0,
                max_abs_u: 0.0,
                duty_cycle: 1.0,
                duty_cycle_until_settled: 1.0,
                state_bound_violations: 0,
                max_step_compute_ns: 0,
            },
            scenario: None,
            sampling: None,
            disturbance: None,
            seed: None,
            d: None,
            fallback_cycles: None,
        }
    }
}
