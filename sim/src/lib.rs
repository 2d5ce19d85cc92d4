//! capsule-mpc-sim: the closed loop of the product, simulated.
//!
//! A controller that steers magnetic capsules with one shared MRI gradient
//! cannot be tried on a scanner for every change, so this crate runs the
//! `no_std` runtime controller against a simulated plant on the scanner's
//! timeline and measures the result:
//!
//! * [`plant`]: the true nonlinear capsule dynamics, a bounded disturbance
//!   and noisy position measurements;
//! * [`closed_loop`]: what a run needs ([`closed_loop::RunOptions`],
//!   sampling mode, scenario, preset) and the driver that runs it;
//! * [`metrics`] and [`report`]: settling time, duty cycle and errors of a
//!   run, and the JSON run report;
//! * [`reach`]: the reach map, the closed loop run to every target of a
//!   grid (settle time against the minimum-time bound);
//! * [`qp_map`]: the per-cell QP iteration map, measured with the compiled
//!   solver for `capsule-mpc generate`.
//!
//! It depends on the generator (config, model), the runtime and the
//! generated solver only: no command line, no plotting.

pub mod closed_loop;
pub mod metrics;
pub mod mismatch;
pub mod plant;
pub mod qp_map;
pub mod reach;
pub mod report;
pub mod request;
