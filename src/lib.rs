//! capsule-mpc: closed-loop simulation, metrics and reports around the
//! generated MPC solver.

pub mod bench;
pub mod cli;
pub mod closed_loop;
pub mod figures;
pub mod generate_cmd;
pub mod inspect;
pub mod metrics;
pub mod plant;
pub mod qp_map;
pub mod report;
