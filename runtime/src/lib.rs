//! capsule-mpc runtime: the closed loop that runs at scanner rate.
//!
//! In an MRI scanner the gradient coils both track the capsules and push
//! them, never at once. Each cycle: a tracking phase (u = 0) measures the
//! positions at its start; the measurement arrives after the tracking time
//! plus a compute/transfer delay; the controller fuses it into its state
//! estimate (positions only: velocities are estimated), predicts through
//! the delay, refines its plan with the fixed-size solver (`capsule-mpc-solver`,
//! specialized by a generated module), and
//! decides with the switching rule how many samples to actuate before the
//! next tracking phase. Near the target a terminal hold takes over: a
//! centre law for the group and a station-keeping dither that holds the
//! capsules' relative position through their different drag.
//!
//! `#![no_std]`, no heap, no `unsafe`: all memory lives in [`Controller`].

#![no_std]
#![forbid(unsafe_code)]

pub mod controller;
pub mod estimator;
pub mod factor_fit;
pub mod switching;

pub use capsule_mpc_generated as generated;
pub use capsule_mpc_solver as solver;
pub use controller::{Controller, ControllerSettings, CycleOutput, RuntimeError, RuntimeStatus};

/// The product's default controller for the embedded config.
pub type DefaultController = Controller<
    generated::controller::Solver,
    { generated::controller::spec::NX },
    { generated::controller::spec::K },
>;

/// The controller of the shipped three-capsule preset
/// (`configs/three-capsules.toml`).
pub type ThreeCapsuleController = Controller<
    generated::three_capsules::Solver,
    { generated::three_capsules::spec::NX },
    { generated::three_capsules::spec::K },
>;

/// The paper's NMPC taken literally, for comparison.
pub type PaperController = Controller<
    generated::paper_preset::Solver,
    { generated::paper_preset::spec::NX },
    { generated::paper_preset::spec::K },
>;
