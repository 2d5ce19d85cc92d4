//! capsule-mpc solver: the online algorithm, hand-written once and
//! specialized by each generated module.
//!
//! Several magnetic capsules share one input, the MRI gradient; offline
//! the generator solves minimum-time plans over grids of target-relative
//! states and writes them to a table file. Online, every control step,
//! this crate turns the current state into a plan: the explicit tier (a
//! stored sample's window QP at the state's deviation, no rollout) and the
//! SQP refinement (Gauss-Newton on the nonlinear RK4 rollout, a dense box
//! QP over the window solved by a primal active-set method).
//!
//! Everything is generic over the sizes with const generics (`M`
//! capsules, `NX = 2 M` states, window `N`, plan length `K`) and over a
//! [`Spec`] that holds one module's constants and its tables. A generated
//! module is data and a thin binding:
//!
//! ```ignore
//! pub struct Spec;
//! impl capsule_mpc_solver::Spec<2, 4> for Spec { /* constants, TABLES */ }
//! pub type Solver = capsule_mpc_solver::Solver<Spec, 2, 4, 10, 80>;
//! ```
//!
//! Tables are read in place from the little-endian file the generator
//! writes ([`format`], [`tables`]): parsed at compile time, checked by
//! SHA-256 once at run time. `#![no_std]`, no heap, no `unsafe`.

#![no_std]
#![forbid(unsafe_code)]
// Comparisons that must reject NaN are written `!(a > b)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod drag;
pub mod explicit;
pub mod format;
pub mod lookup;
pub mod plan_solver;
pub mod qp;
pub mod refine;
pub mod report;
pub mod rollout;
pub mod shooting;
pub mod spec;
pub mod tables;
#[cfg(feature = "write")]
pub mod write;

pub use drag::DragLaw;
pub use plan_solver::PlanSolver;
pub use refine::Solver;
pub use report::{Leg, SolveReport, SolveStatus, Tier};
pub use rollout::Schedule;
pub use spec::Spec;
pub use tables::{Dims, TableError, Tables};
