//! criterion benches of the online step: the full controller step
//! (`DefaultController::cycle_full_state`), the generated solver's `solve`
//! (plain, and with the active-set engine in the bench's timing wrapper),
//! and one window QP of the active-set engine. Each starts from the warm case
//! of `capsule-mpc bench` (a first solve, `shift(1)`, the predicted next
//! state), on states of scenario C's closed loop and one uniform state.
//! Last, the factor fit's worst case: every capsule refitted to a full
//! window of frames (what one accepted frame can cost at most).

use capsule_mpc::bench::engine::Timed;
use capsule_mpc::bench::harness::prototype_controller;
use capsule_mpc::bench::peers::PeerSolver;
use capsule_mpc_runtime::factor_fit::{FactorWindow, FitNoise, FitPrior, ModelStep, FIT_FRAMES};
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

/// A full window (`FIT_FRAMES` frames, two segments between frames:
/// actuation, then the tracking gap, which fills `FIT_SEGMENTS` too):
/// bang-bang out and back, on a plant whose gain and drag are
/// 10 % and 20 % off the model so that the fit has to move.
fn full_window() -> FactorWindow<{ spec::NX }> {
    let mut window = FactorWindow::new();
    window.clear();
    let prior = FitPrior {
        state: [0.0; 2],
        state_cov: [1e-8, 0.0, 0.0, 1e-8],
        factors: [1.0; 2],
        factors_cov: [0.01, 0.0, 0.0, 0.04],
        bias: [0.0; 2],
        bias_var: [1e-6; 2],
    };
    let truth = [1.1, 1.2];
    let mut xv = [[0.0; 2]; spec::M];
    for i in 0..spec::M {
        window.start_capsule(i, prior);
    }
    for frame in 0..FIT_FRAMES {
        let u = if frame < FIT_FRAMES / 2 { 1.0 } else { -1.0 } * spec::U_MAX_T_PER_M;
        for (gradient, duration_s) in [(u, spec::DT_S), (0.0, spec::TRACKING_TIME_S)] {
            for (i, state) in xv.iter_mut().enumerate() {
                *state =
                    Solver::capsule_transition_scaled(i, *state, gradient, duration_s, truth).0;
            }
            window.record_segment(gradient, duration_s);
        }
        let mut z = [0.0; spec::NX];
        for (zi, state) in z.iter_mut().zip(&xv) {
            *zi = state[0];
        }
        window.record_frame(&z);
    }
    assert!(window.is_full() && window.frames() == FIT_FRAMES);
    window
}

fn factor_fit(c: &mut Criterion) {
    let window = full_window();
    let noise = FitNoise {
        r_m2: 1e-8,
        accel_psd: 0.05 * 0.05 * spec::DT_S,
    };
    c.bench_function("factor_fit/full_window", |b| {
        b.iter_batched_ref(
            || window.clone(),
            |w| {
                for i in 0..spec::M {
                    w.fit_capsule(
                        i,
                        &ModelStep::<Solver, { spec::NX }, { spec::K }>::new(),
                        noise,
                        [0.25, 4.0],
                    );
                }
            },
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(step, benches, factor_fit);
criterion_main!(step);
