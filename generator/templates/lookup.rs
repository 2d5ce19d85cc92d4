//! Table lookups: the warm-start index (dense cell numbers, the sparse
//! index's kept cells by bisection), the fine end-game plans at rest, the
//! chained legs and the stored plan tails. Shared by the refinement
//! (`solver`) and the explicit tier (`explicit`).

use super::spec::*;
use super::tables::*;
use crate::Leg;

pub fn axis_nearest(axis: &Axis, v: f64) -> Option<usize> {
    let f = (v - axis.start) / axis.step;
    // NaN fails both comparisons and is rejected here.
    if !(f > -0.5 && f < axis.count as f64 - 0.5) {
        return None;
    }
    Some(libm::round(f) as usize)
}

/// Bisection probes that find any cell among `INDEX_CELLS` (2^64 > any count).
const INDEX_PROBES: usize = 64;

/// The row-major number of `e`'s cell on the (dense) warm-start index grid
/// (position, speed axes alternating, the last axis fastest); None outside
/// the grid.
pub fn index_flat(e: &[f64; NX]) -> Option<u64> {
    let mut flat = 0u64;
    let mut j = 0;
    while j < NX {
        let axis = if j % 2 == 0 {
            &INDEX_POSITION_AXIS
        } else {
            &INDEX_SPEED_AXIS
        };
        flat = flat * axis.count as u64 + axis_nearest(axis, e[j])? as u64;
        j += 1;
    }
    Some(flat)
}

/// The first position in `INDEX_CELLS[lo..hi]` whose cell number is not
/// below `flat` (`hi` if none), by bisection: `INDEX_PROBES` probes at most.
pub fn index_lower_bound(flat: u64, lo: usize, hi: usize) -> usize {
    let (mut lo, mut hi) = (lo, if hi < INDEX_CELLS.len() { hi } else { INDEX_CELLS.len() });
    let mut probes = 0;
    while lo < hi && probes < INDEX_PROBES {
        let mid = lo + (hi - lo) / 2;
        if INDEX_CELLS[mid] < flat {
            lo = mid + 1;
        } else {
            hi = mid;
        }
        probes += 1;
    }
    lo
}

/// The slot among the kept cells of the sparse warm-start index
/// (`INDEX_CELLS`) of the cell numbered `flat` (see `index_flat`); None
/// when no stored plan passes near that cell (it is not kept).
pub fn kept_slot(flat: u64) -> Option<usize> {
    let lo = index_lower_bound(flat, 0, INDEX_CELLS.len());
    if lo < INDEX_CELLS.len() && INDEX_CELLS[lo] == flat {
        Some(lo)
    } else {
        None
    }
}

/// The slot of `e`'s cell among the kept cells of the sparse warm-start
/// index (`INDEX_CELLS`); None outside the index grid or in a cell no
/// stored plan passes near.
pub fn index_cell(e: &[f64; NX]) -> Option<usize> {
    kept_slot(index_flat(e)?)
}

/// Most QP iterations measured offline in the index cell of `e` (0: not
/// measured, or outside the index).
pub fn qp_iterations_measured(e: &[f64; NX]) -> u32 {
    match index_cell(e) {
        Some(c) if c < QP_ITERATION_MAP.len() => QP_ITERATION_MAP[c] as u32,
        _ => 0,
    }
}

/// Speed below which a state counts as at rest for the fine plans, m/s.
pub const FINE_REST_SPEED_M_PER_S: f64 = 5.0e-3;

/// The fine grid point nearest relative state `e` when every speed is
/// below `FINE_REST_SPEED_M_PER_S` and every position on the fine grid;
/// None otherwise.
pub fn fine_cell(e: &[f64; NX]) -> Option<usize> {
    fine_cell_reaching(e, 0.0)
}

/// As `fine_cell`, but a position off the fine grid within `reach_m` of
/// the target takes the grid's nearest edge.
fn fine_cell_reaching(e: &[f64; NX], reach_m: f64) -> Option<usize> {
    if FINE_COUNT == 0 {
        return None;
    }
    let mut flat = 0usize;
    let mut i = 0;
    while i < M {
        if !(libm::fabs(e[2 * i + 1]) <= FINE_REST_SPEED_M_PER_S) {
            return None;
        }
        let p = e[2 * i];
        let j = match axis_nearest(&FINE_AXIS, p) {
            Some(j) => j,
            None if libm::fabs(p) <= reach_m => {
                if p < FINE_AXIS.start {
                    0
                } else {
                    FINE_AXIS.count - 1
                }
            }
            None => return None,
        };
        flat = flat * FINE_AXIS.count + j;
        i += 1;
    }
    if flat >= FINE_COUNT {
        return None;
    }
    Some(flat)
}

/// Fills `out` with the fine plan from rest nearest relative state `e`
/// (see `fine_cell`); None off the fine grid, or where it has no plan.
///
/// Positions beyond the fine grid but within half a main grid step of the
/// target, where the main grid's nearest plan is the target's own, empty
/// one, take the grid's edge (for three capsules: fine grid +-2 mm, main
/// step 1 cm; at rest 2.8 mm off, the refinement from the empty plan
/// played zero gradient for 2.3 s). That edge plan is a rest-to-rest leg
/// into the fine grid (legs compose exactly: the dynamics do not depend on
/// position); the refinement and the next fine plan finish the move.
pub fn lookup_fine(e: &[f64; NX], out: &mut [f64; K], coasted: bool) -> Option<()> {
    let flat = fine_cell_reaching(e, 0.5 * PLAN_AXIS.step)?;
    if !FINE_REACHED[flat] {
        return None;
    }
    *out = if coasted {
        COASTED_FINE_PLAN_U[flat]
    } else {
        FINE_PLAN_U[flat]
    };
    Some(())
}

/// The leg lattice cell of displacement `d = x_start - x_target` (positions;
/// speeds ignored); None outside the lattice.
fn leg_cell(d: &[f64; NX]) -> Option<usize> {
    let mut flat = 0usize;
    let mut i = 0;
    while i < M {
        flat = flat * LEG_AXIS.count + axis_nearest(&LEG_AXIS, d[2 * i])?;
        i += 1;
    }
    Some(flat)
}

/// The first leg from rest at displacement `d = x_start - x_target` toward
/// the target (see `Leg`); None where no chain of stored plans gets there.
/// Without tables every displacement is one direct leg.
pub fn first_leg(d: &[f64; NX]) -> Option<Leg<NX>> {
    let mut direct = Leg {
        start_offset_m: [0.0; NX],
        last: true,
    };
    let mut i = 0;
    while i < M {
        direct.start_offset_m[2 * i] = d[2 * i];
        i += 1;
    }
    if !USE_TABLES {
        return Some(direct);
    }
    let cell = leg_cell(d)?;
    if CHAIN_TIME_S[cell] == 0.0 {
        // Within half a lattice step of the target: the final leg.
        return Some(direct);
    }
    let plan = FIRST_LEG[cell] as usize;
    if plan >= PLAN_COUNT {
        return None;
    }
    // The plan's grid point, and whether it is the displacement's own.
    let mut leg = Leg {
        start_offset_m: [0.0; NX],
        last: true,
    };
    let (mut rest_plan, mut rest_cell) = (plan, cell);
    let mut i = M;
    while i > 0 {
        i -= 1;
        let offset = PLAN_AXIS.start + (rest_plan % PLAN_AXIS.count) as f64 * PLAN_AXIS.step;
        let lattice = LEG_AXIS.start + (rest_cell % LEG_AXIS.count) as f64 * LEG_AXIS.step;
        leg.start_offset_m[2 * i] = offset;
        if libm::fabs(offset - lattice) > 0.5 * LEG_AXIS.step {
            leg.last = false;
        }
        rest_plan /= PLAN_AXIS.count;
        rest_cell /= LEG_AXIS.count;
    }
    if leg.last {
        return Some(direct);
    }
    Some(leg)
}

/// Summed minimum rest-to-rest time (s) of the chain of stored plans from
/// displacement `d` (nearest lattice point); infinite without a chain or
/// without tables.
pub fn chain_time_s(d: &[f64; NX]) -> f64 {
    if !USE_TABLES {
        return f64::INFINITY;
    }
    match leg_cell(d) {
        Some(cell) => CHAIN_TIME_S[cell],
        None => f64::INFINITY,
    }
}

/// Fills `out` with the stored plan tail for relative state `e` from the
/// back-to-back tables; None when `e` is outside the index or its cell has
/// no plan.
pub fn lookup_tail(e: &[f64; NX], out: &mut [f64; K]) -> Option<()> {
    lookup_tail_for(e, out, false)
}

/// As `lookup_tail`, from the tables solved for one sample per actuation
/// phase followed by the coast `COAST_S` (constant sampling) when `coasted`.
pub fn lookup_tail_for(e: &[f64; NX], out: &mut [f64; K], coasted: bool) -> Option<()> {
    let flat = index_cell(e)?;
    let (cell, plans) = if coasted {
        (COASTED_INDEX[flat], &COASTED_PLAN_U)
    } else {
        (INDEX[flat], &PLAN_U)
    };
    let plan = (cell >> 16) as usize;
    let offset = (cell & 0xffff) as usize;
    if plan >= PLAN_COUNT {
        return None;
    }
    let mut i = 0;
    while i < K {
        out[i] = if offset + i < K {
            plans[plan][offset + i]
        } else {
            0.0
        };
        i += 1;
    }
    Some(())
}
