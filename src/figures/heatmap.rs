//! Heatmaps of a reach map (`capsule-mpc reach --plot`): one cell per
//! target of a two-capsule grid, coloured by a value, with the value
//! printed in the cell; refused targets are grey with "refused",
//! targets that never settled black with "never".

use super::figure::DARK;
use super::render::{plot_err, register_font, FONT};
use anyhow::{bail, Context, Result};
use capsule_mpc_sim::reach::ReachPoint;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Pixel size of a heatmap (SVG user units and PNG pixels).
const HEATMAP_SIZE: (u32, u32) = (1100, 1000);

/// What a heatmap shows of each point.
#[derive(Debug, Clone, Copy)]
pub enum HeatmapValue {
    /// Settle time, s.
    SettleTime,
    /// Settle time over the minimum-time bound.
    SettleOverBound,
}

impl HeatmapValue {
    fn of(self, p: &ReachPoint) -> Option<f64> {
        match self {
            HeatmapValue::SettleTime => p.settle_time_s,
            HeatmapValue::SettleOverBound => p.settle_over_bound,
        }
    }

    fn label(self) -> &'static str {
        match self {
            HeatmapValue::SettleTime => "settle time (s)",
            HeatmapValue::SettleOverBound => "settle time / minimum-time bound",
        }
    }
}

/// Writes `<dir>/<stem>.svg` and `.png` for a two-capsule reach map.
pub fn plot_heatmap(
    points: &[ReachPoint],
    value: HeatmapValue,
    title: &str,
    dir: &Path,
    stem: &str,
) -> Result<Vec<PathBuf>> {
    if points.iter().any(|p| p.target_m.len() != 2) {
        bail!("reach heatmaps need two capsules (one axis each)");
    }
    register_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    {
        let root = SVGBackend::new(&svg, HEATMAP_SIZE).into_drawing_area();
        draw(&root, points, value, title).with_context(|| format!("drawing {}", svg.display()))?;
        root.present().map_err(plot_err)?;
    }
    {
        let root = BitMapBackend::new(&png, HEATMAP_SIZE).into_drawing_area();
        draw(&root, points, value, title).with_context(|| format!("drawing {}", png.display()))?;
        root.present().map_err(plot_err)?;
    }
    Ok(vec![svg, png])
}

/// Sorted distinct values of one coordinate (cm), for the cell layout.
fn axis_values(points: &[ReachPoint], i: usize) -> Vec<f64> {
    let mut v: Vec<f64> = points.iter().map(|p| p.target_m[i] * 100.0).collect();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    v
}

/// White (low) to dark red (high) through orange.
fn colour(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    let lerp = |a: f64, b: f64, s: f64| (a + (b - a) * s).round() as u8;
    if t < 0.5 {
        let s = t / 0.5;
        RGBColor(255, lerp(255.0, 170.0, s), lerp(235.0, 60.0, s))
    } else {
        let s = (t - 0.5) / 0.5;
        RGBColor(
            lerp(255.0, 150.0, s),
            lerp(170.0, 20.0, s),
            lerp(60.0, 30.0, s),
        )
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[ReachPoint],
    value: HeatmapValue,
    title: &str,
) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let (xs, ys) = (axis_values(points, 0), axis_values(points, 1));
    let step = |v: &[f64]| {
        v.windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min)
            .min(1e9)
    };
    let (dx, dy) = (step(&xs).min(2.0), step(&ys).min(2.0));
    let (dx, dy) = (
        if dx.is_finite() { dx } else { 1.0 },
        if dy.is_finite() { dy } else { 1.0 },
    );
    let (x0, x1) = (xs[0] - dx / 2.0, xs[xs.len() - 1] + dx / 2.0);
    let (y0, y1) = (ys[0] - dy / 2.0, ys[ys.len() - 1] + dy / 2.0);
    let values: Vec<f64> = points.iter().filter_map(|p| value.of(p)).collect();
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut chart = ChartBuilder::on(root)
        .margin(20)
        .caption(title, (FONT, 24).into_font().color(&DARK))
        .x_label_area_size(60)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("target of capsule 1 (small), cm")
        .y_desc("target of capsule 2 (large), cm")
        .label_style((FONT, 16).into_font().color(&DARK))
        .axis_desc_style((FONT, 18).into_font().color(&DARK))
        .draw()
        .map_err(plot_err)?;
    let font_px =
        (((HEATMAP_SIZE.0 as f64 - 150.0) / xs.len().max(1) as f64) / 3.6).clamp(9.0, 20.0);
    for p in points {
        let (cx, cy) = (p.target_m[0] * 100.0, p.target_m[1] * 100.0);
        let (fill, text, text_colour) = match (&p.refused, value.of(p)) {
            (Some(_), _) => (RGBColor(190, 190, 190), "refused".to_string(), DARK),
            (None, None) if p.settle_time_s.is_none() => (DARK, "never".to_string(), WHITE),
            (None, None) => (WHITE, "-".to_string(), DARK),
            (None, Some(v)) => {
                let c = colour((v - lo) / span);
                let dark_cell = (v - lo) / span > 0.7;
                (c, format!("{v:.2}"), if dark_cell { WHITE } else { DARK })
            }
        };
        let rect = [
            (cx - dx / 2.0, cy - dy / 2.0),
            (cx + dx / 2.0, cy + dy / 2.0),
        ];
        chart
            .draw_series(std::iter::once(Rectangle::new(rect, fill.filled())))
            .map_err(plot_err)?;
        chart
            .draw_series(std::iter::once(Rectangle::new(rect, WHITE.stroke_width(1))))
            .map_err(plot_err)?;
        let style = (FONT, font_px).into_font().color(&text_colour).pos(
            plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Center,
                plotters::style::text_anchor::VPos::Center,
            ),
        );
        chart
            .draw_series(std::iter::once(Text::new(text, (cx, cy), style)))
            .map_err(plot_err)?;
    }
    let legend = format!(
        "{}: {:.2} (white) to {:.2} (dark red)",
        value.label(),
        lo,
        hi
    );
    root.draw(&Text::new(
        legend,
        (30, HEATMAP_SIZE.1 as i32 - 24),
        (FONT, 16).into_font().color(&DARK),
    ))
    .map_err(plot_err)?;
    Ok(())
}
