//! The explicit tier: a first answer with no model rollout.
//!
//! Every step: (1) look the state up (the fine end-game grid at rest, else
//! the warm-start index) and take the nearest of the stored samples named
//! by its cell, the 2 NX neighbouring cells and the previous step's
//! successor on its plan; (2) the deviation d = e - (the sample's stored
//! state); (3) the window QP's gradient F d from the stored sensitivities,
//! its Hessian and the box of the stored plan's inputs; (4) the box QP,
//! warm-started from the previous step's active set (shifted with the
//! plan), else from the stored solution's; (5) plan =
//! stored inputs + the QP's step, clamped, then the stored tail. The linearization was done
//! offline (`capsule-mpc-generator`'s `explicit`); every loop here has a
//! constant bound, and the QP stops at `QP_MAX_ITERATIONS`, so the
//! operation count is bounded by `EXPLICIT_CERTIFIED_OPS`.

use super::explicit_tables::*;
use super::lookup::{axis_nearest, fine_cell, index_lower_bound};
use super::qp::{clamp_u, BoxQp};
use super::spec::*;
use super::tables::*;

/// What one explicit step produced besides the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplicitOutcome {
    /// The stored sample used (index into `EXPLICIT`).
    pub slot: usize,
    /// Active-set iterations of the QP.
    pub qp_iterations: u32,
    /// Whether the QP converged within `QP_MAX_ITERATIONS`.
    pub converged: bool,
    /// The Gauss-Newton model's prediction of the plan's nonlinear cost
    /// (no rollout; the refinement measures the true cost).
    pub predicted_cost: f64,
}

/// The stored sample for relative state `e`: at rest on the fine grid,
/// the fine plan's (the index's nearest sample there is a finished plan,
/// which cannot separate capsules at rest); otherwise the nearest (in
/// index cells) of the samples named by the cell of `e`, its 2 NX
/// neighbours along the axes (those the sparse index keeps; a cell is
/// found by bisection over `INDEX_CELLS`), and the successor of `last` (the previous
/// step's sample; `usize::MAX`: none). Why not the cell's own sample
/// alone: it was chosen by its cost from the cell's centre, and a cell is
/// 0.1 m/s wide in speed; linearized around it, the deviation reached
/// 0.1 m/s and consecutive steps jumped between plans.
pub fn explicit_slot(e: &[f64; NX], coasted: bool, last: usize) -> Option<usize> {
    if let Some(slot) = fine_slot(e, coasted) {
        return Some(slot);
    }
    let slots = if coasted {
        &COASTED_EXPLICIT_INDEX_SLOT
    } else {
        &EXPLICIT_INDEX_SLOT
    };
    let mut idx = [0usize; NX];
    let mut flat = 0u64;
    let mut j = 0;
    while j < NX {
        let axis = axis_of(j);
        idx[j] = axis_nearest(&axis, e[j])?;
        flat = flat * axis.count as u64 + idx[j] as u64;
        j += 1;
    }
    let mut best = usize::MAX;
    let mut best_distance = f64::INFINITY;
    // The sparse index keeps only cells near stored plans: the cell and its
    // neighbours are found among `INDEX_CELLS` by bisection (cells not kept
    // are skipped). The cell's lower bound splits the kept cells: lower
    // neighbours lie before it, higher ones from it on.
    let cells = INDEX_CELLS.len();
    let split = index_lower_bound(flat, 0, cells);
    consider(e, slot_of_cell(slots, flat, split, cells), &mut best, &mut best_distance);
    // Neighbours: stride of axis j = product of the later axes' counts.
    // Kept cells are distinct integers, so at most `stride` of them lie
    // between a neighbour and the cell: the bisection needs only that span
    // of `INDEX_CELLS` (no probe at all along the last axis).
    let mut stride = 1u64;
    let mut j = NX;
    while j > 0 {
        j -= 1;
        let count = axis_of(j).count;
        let span = if stride < cells as u64 { stride as usize } else { cells };
        if idx[j] > 0 {
            let lo = split.saturating_sub(span);
            let slot = slot_of_cell(slots, flat - stride, lo, split);
            consider(e, slot, &mut best, &mut best_distance);
        }
        if idx[j] + 1 < count {
            let hi = if split + span + 1 < cells { split + span + 1 } else { cells };
            let slot = slot_of_cell(slots, flat + stride, split, hi);
            consider(e, slot, &mut best, &mut best_distance);
        }
        stride *= count as u64;
    }
    if last < EXPLICIT_COUNT {
        consider(e, EXPLICIT[last].next as usize, &mut best, &mut best_distance);
    }
    if best < EXPLICIT_COUNT {
        Some(best)
    } else {
        None
    }
}

fn axis_of(j: usize) -> Axis {
    if j % 2 == 0 {
        INDEX_POSITION_AXIS
    } else {
        INDEX_SPEED_AXIS
    }
}

/// The explicit slot of the cell numbered `flat` (row-major on the dense
/// grid) if it is kept, looked for among `INDEX_CELLS[lo..hi]`;
/// `usize::MAX` otherwise.
fn slot_of_cell(slots: &[u16], flat: u64, lo: usize, hi: usize) -> usize {
    let kept = index_lower_bound(flat, lo, hi);
    if kept >= hi || kept >= INDEX_CELLS.len() || INDEX_CELLS[kept] != flat {
        return usize::MAX;
    }
    match slots.get(kept) {
        Some(&s) if s != NO_SLOT => s as usize,
        _ => usize::MAX,
    }
}

/// Keeps `slot` in `best` if its stored state is nearer to `e` (squared
/// distance in index cells) than the best so far.
fn consider(e: &[f64; NX], slot: usize, best: &mut usize, best_distance: &mut f64) {
    if slot >= EXPLICIT_COUNT {
        return;
    }
    let state = &EXPLICIT_STATE[slot];
    let mut dist = 0.0;
    let mut j = 0;
    while j < NX {
        let r = (e[j] - state[j]) / axis_of(j).step;
        dist += r * r;
        j += 1;
    }
    if dist < *best_distance {
        *best_distance = dist;
        *best = slot;
    }
}

fn fine_slot(e: &[f64; NX], coasted: bool) -> Option<usize> {
    let flat = fine_cell(e)?;
    let slots = if coasted {
        &COASTED_FINE_EXPLICIT_SLOT
    } else {
        &FINE_EXPLICIT_SLOT
    };
    let slot = *slots.get(flat)?;
    if slot == NO_SLOT || slot as usize >= EXPLICIT_COUNT {
        return None;
    }
    Some(slot as usize)
}

/// The stored inputs of sample `s`'s plan from its offset on, zero-padded.
fn stored_tail(s: &ExplicitSample, out: &mut [f64; K]) {
    let p = s.plan as usize;
    let row: &[f64; K] = match s.source {
        0 => &PLAN_U[p],
        1 => &COASTED_PLAN_U[p],
        2 => &FINE_PLAN_U[p],
        _ => &COASTED_FINE_PLAN_U[p],
    };
    let offset = s.offset as usize;
    let mut i = 0;
    while i < K {
        out[i] = if offset + i < K { row[offset + i] } else { 0.0 };
        i += 1;
    }
}

/// Loads sample `s`'s window QP at deviation `d` into `qp`, with the box
/// around the stored window inputs `u`.
pub fn load_qp(s: &ExplicitSample, d: &[f64; NX], u: &[f64; K], qp: &mut BoxQp) {
    let mut idx = 0;
    let mut a = 0;
    while a < N {
        let mut b = a;
        while b < N {
            qp.h[a][b] = s.hessian[idx];
            qp.h[b][a] = s.hessian[idx];
            idx += 1;
            b += 1;
        }
        let mut g = 0.0;
        let mut j = 0;
        while j < NX {
            g += s.sensitivity[a][j] * d[j];
            j += 1;
        }
        qp.g[a] = g;
        qp.lo[a] = -U_MAX_T_PER_M - u[a];
        qp.hi[a] = U_MAX_T_PER_M - u[a];
        a += 1;
    }
}

/// The explicit plan for relative state `e` into `out` (`coasted`:
/// constant sampling's tables; `last`: the previous step's slot, or
/// `usize::MAX`; `warm`: the QP's starting active set, None for the stored
/// sample's); None outside the index and the fine grid.
pub fn explicit_plan(
    e: &[f64; NX],
    coasted: bool,
    last: usize,
    warm: Option<&[i8; N]>,
    qp: &mut BoxQp,
    out: &mut [f64; K],
) -> Option<ExplicitOutcome> {
    let slot = explicit_slot(e, coasted, last)?;
    let s = &EXPLICIT[slot];
    stored_tail(s, out);
    let state = &EXPLICIT_STATE[slot];
    let mut d = [0.0; NX];
    let mut j = 0;
    while j < NX {
        d[j] = e[j] - state[j];
        j += 1;
    }
    load_qp(s, &d, out, qp);
    let start = match warm {
        Some(active) => active,
        None => &s.active,
    };
    let (iterations, converged) = qp.solve_from(start);
    let mut a = 0;
    while a < N {
        out[a] = clamp_u(out[a] + qp.x[a]);
        a += 1;
    }
    Some(ExplicitOutcome {
        slot,
        qp_iterations: iterations,
        converged,
        predicted_cost: predicted_cost(s, &d, qp),
    })
}

/// The Gauss-Newton model of the plan's cost: the stored tail's cost plus
/// the first and second order terms in the deviation and the step (the
/// model is of half the cost, as the QP, hence the factor 2).
fn predicted_cost(s: &ExplicitSample, d: &[f64; NX], qp: &BoxQp) -> f64 {
    let mut half = 0.0;
    let mut r = 0;
    while r < NX {
        let mut hd = 0.0;
        let mut c = 0;
        while c < NX {
            hd += s.cost_hessian[r][c] * d[c];
            c += 1;
        }
        half += d[r] * (s.cost_gradient[r] + 0.5 * hd);
        r += 1;
    }
    let mut a = 0;
    while a < N {
        let mut hx = 0.0;
        let mut b = 0;
        while b < N {
            hx += qp.h[a][b] * qp.x[b];
            b += 1;
        }
        half += qp.x[a] * (s.gradient[a] + qp.g[a] + 0.5 * hx);
        a += 1;
    }
    let c = s.cost + 2.0 * half;
    if c > 0.0 {
        c
    } else {
        0.0
    }
}
