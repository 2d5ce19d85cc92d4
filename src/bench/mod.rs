//! `capsule-mpc bench`: timing of the online step, and peers on the same states.
//!
//! # What is timed
//!
//! For every benchmark state `e` (relative to the target, SI):
//!
//! * **cold** — a fresh controller (resp. solver) with no plan solves from
//!   `e`: the table lookup picks a stored plan tail, then the SQP iterations
//!   refine it. This is what the first step after `set_target` costs.
//! * **warm** — the step that follows, the way the closed loop does it with
//!   ideal sampling: the plan of the cold solve has its first input applied
//!   (`shift(1)`), and the solve runs from the *predicted* next state
//!   `e1 = predict(e, plan, 1)`. Only this second call is timed. It still
//!   compares the shifted plan with the table's plan from `e1` and runs the
//!   full `SQP_ITERATIONS` (there is no early exit), so warm and cold differ
//!   mostly in how good the starting plan is.
//!
//! "controller step" is `DefaultController::cycle_full_state(&x)` (estimate
//! overwrite, relative state, shift, solve, clamp and copy of the plan into
//! the output; `set_target` is done once on a prototype that is cloned per
//! state, not timed). "solver only" is `Solver::solve(&e)` of the generated
//! crate. Each call is timed alone with `std::time::Instant` (its own overhead,
//! about 20-40 ns, is reported as `timer_overhead_ns` and not subtracted),
//! inputs and outputs pass through `std::hint::black_box`, on one thread
//! pinned to one core, after an untimed warm-up pass.
//!
//! # States
//!
//! The states visited by closed-loop runs of scenarios A and C (ideal
//! sampling, 3 s, one row per 20 ms sample), plus states drawn uniformly over
//! the admissible region: each relative position over the warm-start index
//! range (`tables::INDEX_POSITION_AXIS`), each speed in +-0.3 m/s, kept when
//! they fall in a kept cell of the sparse warm-start index (the others
//! have no stored plan: the runtime's fallback handles them, not the solver).
//!
//! # Peers
//!
//! The peers run inside the generated solver itself: its refinement's
//! window-QP engine is a type parameter (`capsule_mpc_solver::qp::QpEngine`),
//! so each QP peer is an engine plugged into
//! `capsule_mpc_solver::Solver::<Spec, M, NX, N, K, Timed<E>>::with_engine`
//! and the timed call is that solver's own `solve` (same table selection,
//! rollouts, tail cost-to-go, condensing and line search as the product).
//! [`Timed`] wraps every engine alike, the reference row's active-set
//! method ([`ActiveSet`]) included, and records each QP's time,
//! iterations and convergence and the first QP's step: ratios compare like
//! with like. The engines are the active-set method, clarabel and OSQP
//! (feature `peers-osqp`). The cold solve that sets a warm case up goes to
//! the active-set method for every engine, so all of them refine the same
//! start plan from the same state; that the wrapped active-set solver
//! reproduces the plain `Solver` bit for bit is checked (JSON
//! `peers.reference_check`). OpEn (PANOC) solves the nonlinear window
//! problem itself: the N window inputs in the box, the nonlinear cost over
//! the whole plan with the tail fixed (the solver crate's rollout), the
//! exact gradient by the adjoint of its RK4 Jacobians. All peers start
//! from the same state and plan as the warm step above.
//!
//! [`Timed`]: engine::Timed
//! [`ActiveSet`]: capsule_mpc_runtime::solver::qp::ActiveSet
//!
//! # Layout
//!
//! [`states`] draws the states, [`timing`] holds the timer and percentiles,
//! [`harness`] times the controller step and the solver and prints the
//! tables, [`engine`] is the timing wrapper around a QP engine,
//! [`peers`] runs the peers ([`clarabel_peer`], `osqp_peer` with feature
//! `peers-osqp`, [`open_peer`]) on the warm case, [`tiers`] times the two
//! tiers and the explicit QP against the peers, and
//! [`reference`](mod@reference) checks the config against the generated
//! spec; [`module_steps`] times the controller step of another compiled
//! module (`bench --config`, e.g. three capsules).

// Index loops mirror the math (S[k][j], H[a][b]), as in the template.
#![allow(clippy::needless_range_loop)]

pub mod clarabel_peer;
pub mod engine;
pub mod harness;
pub mod module_steps;
pub mod open_peer;
#[cfg(feature = "peers-osqp")]
pub mod osqp_peer;
pub mod peers;
pub mod reference;
pub mod states;
pub mod tiers;
pub mod timing;
