//! A figure described as data: rows of panels, each with its series, bands
//! and axes; the colours every figure uses.

use plotters::prelude::*;

pub(super) const BLUE: RGBColor = RGBColor(31, 90, 200);
pub(super) const RED: RGBColor = RGBColor(210, 40, 40);
pub(super) const DARK: RGBColor = RGBColor(20, 20, 20);
pub(super) const GREEN: RGBColor = RGBColor(20, 140, 60);
pub(super) const BAND: RGBColor = RGBColor(200, 200, 200);

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Stroke {
    Solid,
    Dashed,
    /// A vertical stem from 0 to each point, with a dot on top.
    Stems,
    /// A small dot at each point (measurements).
    Dots,
}

#[derive(Debug, Clone)]
pub(super) struct Series {
    pub(super) label: Option<String>,
    pub(super) points: Vec<(f64, f64)>,
    pub(super) color: RGBColor,
    pub(super) width: u32,
    pub(super) stroke: Stroke,
}

impl Series {
    pub(super) fn line(
        label: impl Into<String>,
        points: Vec<(f64, f64)>,
        color: RGBColor,
    ) -> Series {
        Series {
            label: Some(label.into()),
            points,
            color,
            width: 2,
            stroke: Stroke::Solid,
        }
    }

    pub(super) fn unlabelled(mut self) -> Series {
        self.label = None;
        self
    }

    pub(super) fn dashed(mut self) -> Series {
        self.stroke = Stroke::Dashed;
        self.width = 1;
        self
    }
}

/// A horizontal band (the settling tolerance around a target).
#[derive(Debug, Clone)]
pub(super) struct Band {
    pub(super) label: Option<String>,
    pub(super) y_lo: f64,
    pub(super) y_hi: f64,
}

#[derive(Debug, Clone, Default)]
pub(super) struct Panel {
    pub(super) title: String,
    pub(super) y_label: String,
    pub(super) series: Vec<Series>,
    pub(super) bands: Vec<Band>,
    /// Series on a right-hand axis: (axis label, series).
    pub(super) secondary: Option<(String, Vec<Series>)>,
    /// Fixed y range instead of one fitted to the data.
    pub(super) y_range: Option<(f64, f64)>,
    pub(super) legend: bool,
    /// Where the legend goes (lower right when `None`).
    pub(super) legend_pos: Option<SeriesLabelPosition>,
}

#[derive(Debug, Clone)]
pub(super) struct Figure {
    pub(super) title: String,
    pub(super) x_label: String,
    pub(super) x_range: (f64, f64),
    /// Rows of panels, each row split evenly between its panels.
    pub(super) rows: Vec<Vec<Panel>>,
}
