//! Rendering of a described figure, to SVG and to PNG by one generic
//! drawing routine, with the embedded font.

use super::figure::{Band, Figure, Panel, Series, Stroke, BAND, DARK};
use anyhow::{anyhow, Context, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The embedded font (see `assets/DejaVu-LICENSE`).
const FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
pub(super) const FONT: &str = "sans-serif";

/// Pixel size of every figure (SVG user units and PNG pixels).
const FIGURE_SIZE: (u32, u32) = (1280, 960);

pub(super) fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "the embedded font DejaVuSans.ttf is not a valid font".to_string())
        })
        .clone()
        .map_err(|e| anyhow!(e))
}

pub(super) fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e}")
}

/// Writes `fig` as `<dir>/<stem>.svg` and `<dir>/<stem>.png`.
pub(super) fn render(fig: &Figure, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
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
pub(super) fn fit_range(series: &[Series], bands: &[Band]) -> (f64, f64) {
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
        Stroke::Dots => {
            for &(x, y) in &s.points {
                area.draw(&Circle::new((x, y), 2, s.color.filled()))
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
                Stroke::Solid | Stroke::Stems | Stroke::Dots => (30, 1),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::figure::BLUE;

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
}
