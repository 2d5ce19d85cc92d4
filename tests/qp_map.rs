//! The committed QP iteration map describes the compiled solver cell by
//! cell: a cold solve from any cell centre, under any schedule the runtime
//! uses, never needs more iterations than the map says for that cell (the
//! map is a maximum over exactly these solves), and the map's cell layout
//! is the solver's own index layout.

use capsule_mpc_runtime::generated::controller::{Solver, TABLES};
use capsule_mpc_runtime::generated::qp_iteration_map;
use capsule_mpc_runtime::solver::{lookup, PlanSolver, SolveStatus};
use capsule_mpc_sim::qp_map::{cell_centre, schedules};

#[test]
fn cold_solves_at_cell_centres_stay_within_the_map() {
    assert_eq!(qp_iteration_map::CONTROLLER.len(), TABLES.cell_count);
    let mut checked = 0;
    // Every 5th cell: a spread over the whole index, under a second.
    for c in (0..TABLES.cell_count).step_by(5) {
        let e = cell_centre(c);
        assert_eq!(
            lookup::index_cell(&TABLES, &e),
            Some(c),
            "cell {c}: centre {e:?}"
        );
        for (samples, coast) in schedules() {
            let mut s = Solver::new();
            s.set_schedule(samples, coast);
            let r = s.solve(&e);
            if r.status == SolveStatus::OutOfRange {
                continue;
            }
            let map = Solver::qp_iterations_measured(&e);
            assert!(
                r.max_qp_iterations <= map,
                "cell {c}, schedule ({samples}, {coast}): {} iterations, map {map}",
                r.max_qp_iterations
            );
            checked += 1;
        }
    }
    assert!(checked > 1000, "only {checked} solves checked");
}
