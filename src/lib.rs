//! capsule-mpc: the command line of the product, and the two tools that
//! need more than the simulation library.
//!
//! Steering several magnetic capsules with one MRI gradient is done by the
//! generated solver and the `no_std` runtime; `capsule_mpc_sim` runs that
//! controller in closed loop against a simulated plant. This crate is the
//! shell around them:
//!
//! * [`cli`]: the arguments of every subcommand (clap);
//! * [`cmd`]: one thin module per subcommand (`inspect`, `simulate`,
//!   `generate`, `bench`, `figures`);
//! * [`bench`](mod@bench): timing of the online step and the peer solvers (clarabel,
//!   OSQP, OpEn) on the same states;
//! * [`figures`]: the report's figures and the plot of one run (plotters);
//! * [`pulseq_export`]: `simulate --pulseq`, the played run of a report
//!   written as a Pulseq sequence (`capsule_mpc_pulseq`).

pub mod bench;
pub mod cli;
pub mod cmd;
pub mod figures;
pub mod out;
pub mod pulseq_export;

/// The Rust host in `docs/embedding.md`, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../docs/embedding.md")]
pub struct EmbeddingDocTests;

/// The Rust snippet in `README.md`, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDocTests;
