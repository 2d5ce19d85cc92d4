//! Table look-ups: the warm-start index (dense cell numbers, the sparse
//! index's kept cells by bisection), the fine end-game plans at rest, the
//! chained legs and the stored plan tails. Shared by the refinement
//! (`refine`) and the explicit tier (`explicit`). Relative states are
//! `e = x - x_target` in SI, `NX = 2 M` entries [x1, v1, x2, v2, ...].

use crate::format::{Axis, Section, NO_SETTLE};
use crate::report::Leg;
use crate::tables::{PlanSet, Tables};

/// The grid point of `axis` nearest `v`; None outside the axis (and for NaN).
#[inline]
pub fn axis_nearest(axis: &Axis, v: f64) -> Option<usize> {
    let f = (v - axis.start) / axis.step;
    // NaN fails both comparisons and is rejected here.
    if !(f > -0.5 && f < axis.count as f64 - 0.5) {
        return None;
    }
    Some(libm::round(f) as usize)
}

/// Bisection probes that find any cell among the kept cells (2^64 > any count).
const INDEX_PROBES: usize = 64;

/// The index axis of state component `j` (positions even, speeds odd).
#[inline]
pub fn index_axis(t: &Tables, j: usize) -> Axis {
    if j.is_multiple_of(2) {
        t.index_position_axis
    } else {
        t.index_speed_axis
    }
}

/// The row-major number of `e`'s cell on the (dense) warm-start index grid
/// (position, speed axes alternating, the last axis fastest); None outside
/// the grid.
pub fn index_flat<const NX: usize>(t: &Tables, e: &[f64; NX]) -> Option<u64> {
    let mut flat = 0u64;
    let mut j = 0;
    while j < NX {
        let axis = index_axis(t, j);
        flat = flat * axis.count as u64 + axis_nearest(&axis, e[j])? as u64;
        j += 1;
    }
    Some(flat)
}

/// The first position among the kept cells `[lo, hi)` whose cell number is
/// not below `flat` (`hi` if none), by bisection: `INDEX_PROBES` probes at most.
pub fn index_lower_bound(t: &Tables, flat: u64, lo: usize, hi: usize) -> usize {
    let cells = t.cell_count;
    let (mut lo, mut hi) = (lo, if hi < cells { hi } else { cells });
    let mut probes = 0;
    while lo < hi && probes < INDEX_PROBES {
        let mid = lo + (hi - lo) / 2;
        if t.u64_at(Section::IndexCells, mid) < flat {
            lo = mid + 1;
        } else {
            hi = mid;
        }
        probes += 1;
    }
    lo
}

/// The slot among the kept cells of the sparse warm-start index of the cell
/// numbered `flat` (see `index_flat`); None when no stored plan passes near
/// that cell (it is not kept).
pub fn kept_slot(t: &Tables, flat: u64) -> Option<usize> {
    let cells = t.cell_count;
    let lo = index_lower_bound(t, flat, 0, cells);
    if lo < cells && t.u64_at(Section::IndexCells, lo) == flat {
        Some(lo)
    } else {
        None
    }
}

/// The slot of `e`'s cell among the kept cells of the sparse warm-start
/// index; None outside the index grid or in a cell no stored plan passes near.
pub fn index_cell<const NX: usize>(t: &Tables, e: &[f64; NX]) -> Option<usize> {
    kept_slot(t, index_flat(t, e)?)
}

/// Centre of the kept index cell in `slot` (its row-major number over
/// e1, v1, e2, v2, ...); None past the kept cells.
pub fn cell_centre<const NX: usize>(t: &Tables, slot: usize) -> Option<[f64; NX]> {
    if slot >= t.cell_count {
        return None;
    }
    let mut flat = t.u64_at(Section::IndexCells, slot) as usize;
    let mut e = [0.0; NX];
    let mut j = NX;
    while j > 0 {
        j -= 1;
        let axis = index_axis(t, j);
        e[j] = axis.start + (flat % axis.count) as f64 * axis.step;
        flat /= axis.count;
    }
    Some(e)
}

/// Most QP iterations measured offline in the index cell of `e` (0: not
/// measured, or outside the index).
pub fn qp_iterations_measured<const NX: usize>(t: &Tables, map: &[u8], e: &[f64; NX]) -> u32 {
    match index_cell(t, e) {
        Some(c) if c < map.len() => map[c] as u32,
        _ => 0,
    }
}

/// Speed below which a state counts as at rest for the fine plans, m/s.
pub const FINE_REST_SPEED_M_PER_S: f64 = 5.0e-3;

/// The fine grid point nearest relative state `e` when every speed is
/// below `FINE_REST_SPEED_M_PER_S` and every position on the fine grid;
/// None otherwise.
pub fn fine_cell<const NX: usize>(t: &Tables, e: &[f64; NX]) -> Option<usize> {
    fine_cell_reaching(t, e, 0.0)
}

/// As `fine_cell`, but a position off the fine grid within `reach_m` of
/// the target takes the grid's nearest edge.
fn fine_cell_reaching<const NX: usize>(t: &Tables, e: &[f64; NX], reach_m: f64) -> Option<usize> {
    if t.fine_count == 0 {
        return None;
    }
    let axis = t.fine_axis;
    let mut flat = 0usize;
    let mut i = 0;
    while i < NX / 2 {
        if !(libm::fabs(e[2 * i + 1]) <= FINE_REST_SPEED_M_PER_S) {
            return None;
        }
        let p = e[2 * i];
        let j = match axis_nearest(&axis, p) {
            Some(j) => j,
            None if libm::fabs(p) <= reach_m => {
                if p < axis.start {
                    0
                } else {
                    axis.count - 1
                }
            }
            None => return None,
        };
        flat = flat * axis.count + j;
        i += 1;
    }
    if flat >= t.fine_count {
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
pub fn lookup_fine<const NX: usize, const K: usize>(
    t: &Tables,
    e: &[f64; NX],
    out: &mut [f64; K],
    coasted: bool,
) -> Option<()> {
    let flat = fine_cell_reaching(t, e, 0.5 * t.plan_axis.step)?;
    if t.u8_at(Section::FineReached, flat) == 0 {
        return None;
    }
    let set = if coasted {
        PlanSet::CoastedFine
    } else {
        PlanSet::Fine
    };
    let mut k = 0;
    while k < K {
        out[k] = t.plan_u(set, flat, k);
        k += 1;
    }
    Some(())
}

/// The row-major cell of the positions of `d` (speeds ignored) on the
/// lattice `axis` per capsule, each position at its nearest point; None
/// outside the lattice, or, with `on_grid_m`, when a position lies farther
/// than that from its point.
fn nearest_cell<const NX: usize>(
    axis: &Axis,
    d: &[f64; NX],
    on_grid_m: Option<f64>,
) -> Option<usize> {
    let mut flat = 0usize;
    let mut i = 0;
    while i < NX / 2 {
        let j = axis_nearest(axis, d[2 * i])?;
        if on_grid_m
            .is_some_and(|tol| libm::fabs(axis.start + j as f64 * axis.step - d[2 * i]) > tol)
        {
            return None;
        }
        flat = flat * axis.count + j;
        i += 1;
    }
    Some(flat)
}

/// The leg lattice cell of displacement `d = x_start - x_target` (positions;
/// speeds ignored); None outside the lattice.
fn leg_cell<const NX: usize>(t: &Tables, d: &[f64; NX]) -> Option<usize> {
    nearest_cell(&t.leg_axis, d, None)
}

/// The first leg from rest at displacement `d = x_start - x_target` toward
/// the target (see `Leg`); None where no chain of stored plans gets there.
/// Without tables (`use_tables` false) every displacement is one direct leg.
pub fn first_leg<const NX: usize>(t: &Tables, use_tables: bool, d: &[f64; NX]) -> Option<Leg<NX>> {
    let mut direct = Leg {
        start_offset_m: [0.0; NX],
        last: true,
    };
    let mut i = 0;
    while i < NX / 2 {
        direct.start_offset_m[2 * i] = d[2 * i];
        i += 1;
    }
    if !use_tables {
        return Some(direct);
    }
    let cell = leg_cell(t, d)?;
    if t.f64_at(Section::ChainTime, cell) == 0.0 {
        // Within half a lattice step of the target: the final leg.
        return Some(direct);
    }
    let plan = t.u16_at(Section::FirstLeg, cell) as usize;
    if plan >= t.plan_count {
        return None;
    }
    // The plan's grid point, and whether it is the displacement's own.
    let mut leg = Leg {
        start_offset_m: [0.0; NX],
        last: true,
    };
    let (plan_axis, leg_axis) = (t.plan_axis, t.leg_axis);
    let (mut rest_plan, mut rest_cell) = (plan, cell);
    let mut i = NX / 2;
    while i > 0 {
        i -= 1;
        let offset = plan_axis.start + (rest_plan % plan_axis.count) as f64 * plan_axis.step;
        let lattice = leg_axis.start + (rest_cell % leg_axis.count) as f64 * leg_axis.step;
        leg.start_offset_m[2 * i] = offset;
        if libm::fabs(offset - lattice) > 0.5 * leg_axis.step {
            leg.last = false;
        }
        rest_plan /= plan_axis.count;
        rest_cell /= leg_axis.count;
    }
    if leg.last {
        return Some(direct);
    }
    Some(leg)
}

/// Summed minimum rest-to-rest time (s) of the chain of stored plans from
/// displacement `d` (nearest lattice point); infinite without a chain or
/// without tables.
pub fn chain_time_s<const NX: usize>(t: &Tables, use_tables: bool, d: &[f64; NX]) -> f64 {
    if !use_tables {
        return f64::INFINITY;
    }
    match leg_cell(t, d) {
        Some(cell) => t.f64_at(Section::ChainTime, cell),
        None => f64::INFINITY,
    }
}

/// Most legs a chain of stored plans takes (the generator's chains stay
/// well below; a bound keeps the walk finite on any table).
pub const MAX_CHAIN_LEGS: usize = 8;

/// One plan through a chain of stored legs into `out` (zero after): the
/// samples `head` plays first (a shot in flight to the chain's first
/// waypoint; none from rest), then the chain from displacement `d =
/// x_start - x_target` (positions; speeds ignored), each leg's plan cut at
/// its stored settle sample (`Section::PlanSettle`: from there its rollout
/// from rest, on the model and the set's own schedule, stays in the settle
/// band), the whole compressed in time into `K` samples when longer
/// (nearest sample). Returns the chain's length in samples (the plan holds
/// all of it, or the whole compressed). A start for one shot to the final
/// target: rest-to-rest legs compose (the dynamics do not depend on
/// position), so on the model the uncompressed plan ends in the band of
/// the chain's end, within half a leg lattice step of the target; the
/// compressed one is a guess the shot corrects. None without tables or a
/// chain, where a leg's plan does not settle, or where the plan would be a
/// single stored plan from rest (no head, one leg).
pub fn chain_plan<const NX: usize, const K: usize>(
    t: &Tables,
    use_tables: bool,
    head: (&[f64; K], usize),
    d: &[f64; NX],
    coasted: bool,
    out: &mut [f64; K],
) -> Option<usize> {
    if !use_tables {
        return None;
    }
    let (set, min_time, settle) = if coasted {
        (
            PlanSet::Coasted,
            Section::CoastedPlanMinTime,
            Section::CoastedPlanSettle,
        )
    } else {
        (
            PlanSet::BackToBack,
            Section::PlanMinTime,
            Section::PlanSettle,
        )
    };
    if t.elements(min_time) == 0 || t.elements(settle) != t.plan_count {
        return None;
    }
    let (head, head_samples) = (head.0, head.1.min(K));
    // The chain's legs: each one's plan and samples.
    let mut legs = [(0usize, 0usize); MAX_CHAIN_LEGS];
    let mut count = 0;
    let mut total = head_samples;
    let mut rest = *d;
    loop {
        let cell = leg_cell(t, &rest)?;
        if t.f64_at(Section::ChainTime, cell) == 0.0 {
            // Within half a lattice step of the target: the chain ends.
            break;
        }
        let plan = t.u16_at(Section::FirstLeg, cell) as usize;
        if plan >= t.plan_count || count == MAX_CHAIN_LEGS {
            return None;
        }
        if !t.f64_at(min_time, plan).is_finite() {
            return None;
        }
        // The plan's grid point, the last capsule fastest.
        let axis = t.plan_axis;
        let mut flat = plan;
        let mut i = NX / 2;
        while i > 0 {
            i -= 1;
            rest[2 * i] -= axis.start + (flat % axis.count) as f64 * axis.step;
            flat /= axis.count;
        }
        let samples = t.u16_at(settle, plan) as usize;
        if samples > K {
            return None;
        }
        legs[count] = (plan, samples);
        count += 1;
        total += samples;
    }
    if total == 0 || (head_samples == 0 && count < 2) {
        return None;
    }
    let n = total.min(K);
    let mut k = 0;
    while k < K {
        out[k] = 0.0;
        if k < n {
            // Sample k of the (compressed) plan is sample `at` of the chain.
            let mut at = if total > K {
                (k * total + total / 2) / n
            } else {
                k
            };
            out[k] = if at < head_samples {
                head[at]
            } else {
                at -= head_samples;
                let mut leg = 0;
                while leg + 1 < count && at >= legs[leg].1 {
                    at -= legs[leg].1;
                    leg += 1;
                }
                let (plan, samples) = legs[leg];
                t.plan_u(set, plan, at.min(samples.saturating_sub(1)))
            };
        }
        k += 1;
    }
    Some(total)
}

/// How far a displacement may lie from a plan grid point and still count
/// as that point's move, m (rounding of lattice targets such as 0.03).
const ON_PLAN_GRID_M: f64 = 1e-9;

/// Minimum rest-to-rest time (s) of the stored constant-sampling plan
/// (one sample per actuation phase, then the coast) for displacement `d`
/// (positions; speeds ignored): the bound of the schedule constant
/// sampling plays. Infinite off the plan grid, for a plan that does not
/// arrive, and without coasted tables.
pub fn coasted_time_s<const NX: usize>(t: &Tables, use_tables: bool, d: &[f64; NX]) -> f64 {
    if !use_tables || t.elements(Section::CoastedPlanMinTime) == 0 {
        return f64::INFINITY;
    }
    let Some(flat) = nearest_cell(&t.plan_axis, d, Some(ON_PLAN_GRID_M)) else {
        return f64::INFINITY;
    };
    if t.u8_at(Section::CoastedPlanReached, flat) == 0 {
        return f64::INFINITY;
    }
    t.f64_at(Section::CoastedPlanMinTime, flat)
}

/// Whether a start at rest at relative position `e` (speeds ignored) is
/// covered by a stored plan that reaches its target.
pub fn covers_from_rest<const NX: usize>(t: &Tables, use_tables: bool, e: &[f64; NX]) -> bool {
    if !use_tables {
        return true;
    }
    nearest_cell(&t.plan_axis, e, None).is_some_and(|flat| t.u8_at(Section::PlanReached, flat) != 0)
}

/// The stored plan tail for relative state `e`: (plan, offset) of the
/// index cell's entry, back to back or coasted; None outside the index or
/// where its cell has no plan.
fn index_entry<const NX: usize>(
    t: &Tables,
    e: &[f64; NX],
    coasted: bool,
) -> Option<(usize, usize)> {
    let flat = index_cell(t, e)?;
    let section = if coasted {
        Section::CoastedIndex
    } else {
        Section::Index
    };
    let cell = t.u32_at(section, flat);
    let plan = (cell >> 16) as usize;
    let offset = (cell & 0xffff) as usize;
    (plan < t.plan_count).then_some((plan, offset))
}

/// Fills `out` with the stored plan tail for relative state `e` from the
/// back-to-back tables; None when `e` is outside the index or its cell has
/// no plan.
pub fn lookup_tail<const NX: usize, const K: usize>(
    t: &Tables,
    e: &[f64; NX],
    out: &mut [f64; K],
) -> Option<()> {
    lookup_tail_for(t, e, out, false).map(|_| ())
}

/// As `lookup_tail`, from the tables solved for one sample per actuation
/// phase followed by the coast (constant sampling) when `coasted`. Returns
/// the samples after which the tail settles (its plan's stored settle
/// sample less the tail's offset; above `K` where the plan does not
/// settle).
pub fn lookup_tail_for<const NX: usize, const K: usize>(
    t: &Tables,
    e: &[f64; NX],
    out: &mut [f64; K],
    coasted: bool,
) -> Option<usize> {
    let (plan, offset) = index_entry(t, e, coasted)?;
    let (set, settle) = if coasted {
        (PlanSet::Coasted, Section::CoastedPlanSettle)
    } else {
        (PlanSet::BackToBack, Section::PlanSettle)
    };
    let mut i = 0;
    while i < K {
        out[i] = if offset + i < K {
            t.plan_u(set, plan, offset + i)
        } else {
            0.0
        };
        i += 1;
    }
    let settles_at = if t.elements(settle) == t.plan_count {
        t.u16_at(settle, plan)
    } else {
        NO_SETTLE
    };
    Some(if settles_at == NO_SETTLE {
        K + 1
    } else {
        (settles_at as usize).saturating_sub(offset)
    })
}
