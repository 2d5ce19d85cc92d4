//! criterion benches of the online step: the full controller step
//! (`DefaultController::cycle_full_state`), the generated solver's `solve`
//! (plain, and with the active-set engine in the bench's timing wrapper),
//! and one window QP of the active-set engine. Each starts from the warm case
//! of `capsule-mpc bench` (a first solve, `shift(1)`, the predicted next
//! state), on states of scenario C's closed loop and one uniform state.

use capsule_mpc::bench::engine::Timed;
use capsule_mpc::bench::harness::prototype_controller;
use capsule_mpc::bench::peers::PeerSolver;
use capsule_mpc_runtime::generated::controller::{spec, Solver};
use capsule_mpc_runtime::solver::qp::{ActiveSet, QpEngine};
use capsule_mpc_runtime::solver::PlanSolver;
use criterion::{black_box, criterion_group, criterion_main, BatchSize, Criterion};

/// Relative states: early in scenario C's manoeuvre (fast), and a uniform one.
const STATES: [(&str, [f64; spec::NX]); 3] = [
    ("rest_C", [-0.02, 0.0, 0.01, 0.0]),
    ("moving", [-0.012, 0.12, 0.006, 0.05]),
    ("uniform", [0.031, -0.21, -0.044, 0.17]),
];

fn benches(c: &mut Criterion) {
    let proto = prototype_controller().expect("controller");
    for (name, e) in STATES {
        // Warm case: first solve, then the next state after one sample.
        let mut warm_solver = Solver::new();
        warm_solver.solve(&e);
        let e1 = Solver::predict_plan(&e, warm_solver.plan(), 1);
        warm_solver.shift(1);
        let mut warm_ctl = proto.clone();
        warm_ctl.cycle_full_state(&e).expect("cycle");
        // The same warm case in the solver with the wrapped engine (its
        // cold solve goes to the active-set method while disarmed).
        let mut wrapped = PeerSolver::with_engine(Timed::new(ActiveSet));
        wrapped.solve(&e);
        wrapped.shift(1);
        wrapped.engine().arm();

        c.bench_function(&format!("controller_step/{name}"), |b| {
            b.iter_batched_ref(
                || warm_ctl.clone(),
                |ctl| ctl.cycle_full_state(black_box(&e1)),
                BatchSize::SmallInput,
            )
        });
        c.bench_function(&format!("solver_solve/{name}"), |b| {
            b.iter_batched_ref(
                || warm_solver.clone(),
                |s| s.solve(black_box(&e1)),
                BatchSize::SmallInput,
            )
        });
        c.bench_function(&format!("solver_solve_timed_engine/{name}"), |b| {
            b.iter_batched_ref(
                || wrapped.clone(),
                |s| s.solve(black_box(&e1)),
                BatchSize::SmallInput,
            )
        });
        // The last window QP of that warm step (`Solver::window_qp`).
        let mut after = warm_solver.clone();
        after.solve(&e1);
        let mut qp = after.window_qp().clone();
        c.bench_function(&format!("qp_solve/{name}"), |b| {
            b.iter(|| ActiveSet.solve(black_box(&mut qp)))
        });
    }
}

criterion_group!(step, benches);
criterion_main!(step);
