//! The per-cell QP iteration map: the most active-set iterations one QP
//! takes in the solves run at every warm-start index cell, measured with
//! the compiled solver and emitted as `generated/src/qp_iteration_map.rs`.
//!
//! Why measured, not derived: a primal active-set method has no useful
//! a-priori iteration bound (the hard cap 3N only stops it). Solving at
//! every cell, cold from the table and warm one sample later, under every
//! schedule the runtime uses, gives the count the runtime can compare
//! against: a solve above its cell's measured count is flagged, never
//! silent. It is a measurement over cell centres, not a proof for every
//! state inside a cell.

use anyhow::Result;
use capsule_mpc_generator::generate::GeneratedFiles;
use capsule_mpc_runtime::controller::Sampling;
use capsule_mpc_runtime::generated::controller::{spec, Solver, TABLES};
use capsule_mpc_runtime::solver::format::Section;
use capsule_mpc_runtime::solver::lookup;
use capsule_mpc_runtime::solver::{PlanSolver, SolveStatus};
use capsule_mpc_runtime::DefaultController;
use rayon::prelude::*;

/// The controller module this binary was compiled with: its binding and
/// its table file (the algorithm is the solver crate compiled in).
const COMPILED_CONTROLLER: &str = include_str!("../../generated/src/controller.rs");

/// Measures the map into `files` when their controller is the one compiled
/// into this binary (same binding, same table file: the map describes that
/// solver); returns false, leaving the unmeasured placeholder, otherwise.
pub fn fill_if_compiled(files: &mut GeneratedFiles) -> Result<bool> {
    if files.file("src/controller.rs") != Some(COMPILED_CONTROLLER.as_bytes())
        || files.file(spec::TABLE_FILE_NAME) != Some(spec::TABLE_FILE)
    {
        return Ok(false);
    }
    files.set_qp_iteration_map(&measure())?;
    Ok(true)
}

/// The schedules the runtime sets: ideal (back to back), constant sampling
/// (one sample per phase) and variable sampling at its longest phase, each
/// with the default settings' tracking + delay as the coast.
pub fn schedules() -> [(usize, f64); 3] {
    [Sampling::Ideal, Sampling::Constant, Sampling::Variable].map(|sampling| {
        let mut settings = DefaultController::default_settings();
        settings.sampling = sampling;
        settings.schedule(settings.max_actuation_samples)
    })
}

/// Centre of the kept index cell in `slot` (its row-major number over e1,
/// v1, e2, v2, ... is the table file's `index_cells[slot]`).
pub fn cell_centre(slot: usize) -> [f64; spec::NX] {
    lookup::cell_centre(&TABLES, slot).unwrap_or([f64::NAN; spec::NX])
}

/// Measures the map over every cell (both cores): per cell, the most
/// iterations any QP took in a cold solve from its centre or in the warm
/// solve one sample later (counted in the cell that state falls into).
pub fn measure() -> Vec<u8> {
    let cells = TABLES.elements(Section::Index);
    let hits: Vec<Vec<(usize, u32)>> = (0..cells)
        .into_par_iter()
        .map(|c| {
            let e = cell_centre(c);
            let mut out = Vec::with_capacity(2 * schedules().len());
            for (samples, coast_s) in schedules() {
                let mut s = Solver::new();
                s.set_schedule(samples, coast_s);
                let cold = s.solve(&e);
                if cold.status == SolveStatus::OutOfRange {
                    continue;
                }
                out.push((c, cold.max_qp_iterations));
                let e1 = Solver::predict_plan(&e, s.plan(), 1);
                s.shift(1);
                let warm = s.solve(&e1);
                if let Some(c1) = lookup::index_cell(&TABLES, &e1) {
                    out.push((c1, warm.max_qp_iterations));
                }
            }
            out
        })
        .collect();
    let mut map = vec![0u8; cells];
    for (c, iters) in hits.into_iter().flatten() {
        let v = u8::try_from(iters).unwrap_or(u8::MAX);
        map[c] = map[c].max(v);
    }
    dilate(&map)
}

/// Each cell's count becomes the largest over the cell and its kept
/// neighbours (+-1 along every axis): states inside a cell lie between its
/// centre and its neighbours' centres, and the count varies from centre to
/// centre.
fn dilate(map: &[u8]) -> Vec<u8> {
    let step = [
        TABLES.index_position_axis.step,
        TABLES.index_speed_axis.step,
    ];
    (0..map.len())
        .map(|slot| {
            let centre = cell_centre(slot);
            let mut most = map[slot];
            // Every offset in {-1, 0, 1}^NX, as a base-3 counter.
            for k in 0..3usize.pow(spec::NX as u32) {
                let mut e = centre;
                let mut rest = k;
                for (j, x) in e.iter_mut().enumerate() {
                    *x += (rest % 3) as f64 * step[j % 2] - step[j % 2];
                    rest /= 3;
                }
                if let Some(n) = lookup::index_cell(&TABLES, &e) {
                    most = most.max(map[n]);
                }
            }
            most
        })
        .collect()
}
