//! capsule-mpc calibrate: measure the capsules before controlling them.
//!
//! Nobody knows a real capsule's drag coefficient, its effective mass with
//! the shell or its magnetization to better than 10-20 %, and the
//! controller's tables are solved for the config's values. Scanner practice
//! is to measure first: play a known gradient sequence ([`design`]), track
//! the capsules, fit each capsule's gain g_i (m/s^2 per T/m) and drag
//! coefficient b_i (1/m) to the tracked positions by nonlinear least
//! squares over the whole trajectory ([`fit`]), write a config with the
//! fitted values ([`fitted_config`]) and regenerate.
//!
//! The capsules are coupled only through the known gradient, so each is
//! fitted alone: four parameters (g_i, b_i and its initial position and
//! speed) against its own frames.

pub mod design;
pub mod fit;
pub mod log;

pub use design::{design_excitation, Excitation};
pub use fit::{
    fit, fitted_config, told_std, Calibration, CapsuleFit, FitSettings, TOLD_STD_MIN,
    TOLD_STD_PER_STDERR,
};
pub use log::{LogError, TrackingLog};
