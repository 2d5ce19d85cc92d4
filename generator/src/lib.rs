//! capsule-mpc generator: the offline half of the product.
//!
//! Reads a capsule/scanner config, derives the capsule model, solves the
//! nonconvex optimal-control problems offline over a grid of target-relative
//! states, stores the results as tables and emits a specialized fixed-size
//! solver crate (`generated/`) that the `no_std` runtime links.

pub mod config;
pub mod emit;
pub mod explicit;
pub mod generate;
pub mod grid;
pub mod index;
pub mod legs;
pub mod mintime;
pub mod model;
pub mod ocp;
pub mod shard;
pub mod table_file;
pub mod tables;
