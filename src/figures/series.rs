//! Series and panels from run reports: positions, velocities, the gradient
//! as a staircase, targets with their settling bands, tracking instants.

use super::figure::{Band, Panel, Series, Stroke, DARK};
use capsule_mpc_sim::metrics::SETTLE_POSITION_TOL_M;
use capsule_mpc_sim::plant::Phase;
use capsule_mpc_sim::report::RunReport;
use plotters::prelude::*;

pub(super) fn capsule_count(report: &RunReport) -> usize {
    report.target.len() / 2
}

/// Position (mm) of capsule `i` over time.
pub(super) fn positions_mm(report: &RunReport, i: usize) -> Vec<(f64, f64)> {
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
pub(super) fn gradient_mt_per_m(report: &RunReport) -> Vec<(f64, f64)> {
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
pub(super) fn clip(points: Vec<(f64, f64)>, t_end: f64) -> Vec<(f64, f64)> {
    let keep = points.iter().take_while(|p| p.0 <= t_end).count();
    points.into_iter().take(keep + 1).collect()
}

pub(super) fn end_time(report: &RunReport) -> f64 {
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
pub(super) fn comparison_rows(
    runs: &[(&str, &RunReport, RGBColor)],
    t_end: f64,
) -> Vec<Vec<Panel>> {
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
pub(super) fn gradient_row(runs: &[(&str, &RunReport, RGBColor)], t_end: f64) -> Vec<Panel> {
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

/// Stems at the tracking instants, scaled to the gradient axis (only when the
/// run has tracking phases, i.e. not ideal sampling).
pub(super) fn tracking_series(report: &RunReport, label: &str, color: RGBColor) -> Option<Series> {
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

#[cfg(test)]
mod tests {
    use super::*;
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
        use capsule_mpc_sim::metrics::Metrics;
        RunReport {
            t: vec![0.0],
            x: vec![vec![0.0; 4]],
            u: vec![0.0],
            phase: vec![Phase::Actuate],
            measurements: vec![],
            params: capsule_mpc_sim::report::ModelParams {
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
                min_time_bound_s: None,
                settle_over_bound: None,
                held_settle_over_bound: None,
                schedule_min_time_s: None,
                settle_over_schedule_bound: None,
                workspace_excursion_m: 0.0,
                settle_held_s: None,
                first_in_band_s: None,
                time_in_band_after_entry: None,
            },
            scenario: None,
            sampling: None,
            disturbance: None,
            seed: None,
            d: None,
            fallback_cycles: None,
            tier_cycles: None,
            plant: None,
            calibrated: None,
            retarget: None,
            frames: None,
            timing: None,
            modes: None,
            estimated_factors: None,
        }
    }
}
