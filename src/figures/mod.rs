//! Figures of the report (`capsule-mpc figures`, `simulate --plot`): the
//! paper's figures 3-7 re-made from real closed-loop runs, plus figure 8
//! (the paper's NMPC preset against the default controller).
//!
//! Each figure is first described as data (`Figure`: rows of panels, each
//! with its series) and then rendered twice by one generic drawing routine,
//! to SVG and to PNG. Text uses an embedded DejaVu Sans, so no system font
//! or fontconfig is needed.
//!
//! `figure` holds the description types, `render` draws them, `series`
//! turns run reports into series and panels, [`run`] is the plot of one run
//! (`simulate --plot`), [`paper`] the report's figures 3-8 and [`summary`]
//! the numbers written beside them.

pub mod calibration;
mod figure;
pub mod heatmap;
pub mod paper;
mod render;
pub mod run;
mod series;
pub mod summary;

pub use paper::all_figures;
pub use run::plot_run;
pub use summary::{FigureSummary, RunSummary};
