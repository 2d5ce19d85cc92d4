//! The explicit tier: a first answer with no model rollout.
//!
//! Every step: (1) look the state up (the fine end-game grid at rest, else
//! the warm-start index) and take the nearest of the stored samples named
//! by its cell, the 2 NX neighbouring cells and the previous step's
//! successor on its plan; (2) the deviation d = e - (the sample's stored
//! state); (3) the window QP's gradient F d from the stored sensitivities,
//! its Hessian and the box of the stored plan's inputs; (4) the box QP,
//! warm-started from the previous step's active set (shifted with the
//! plan), else from the stored solution's; (5) plan = stored inputs + the
//! QP's step, clamped, then the stored tail. The linearization was done
//! offline (`capsule-mpc-generator`'s `explicit`); every loop here has a
//! constant bound, and the QP stops at its iteration cap, so the operation
//! count is bounded by [`explicit_step_ops`].

use crate::format::{Section, NO_SLOT};
use crate::lookup::{axis_nearest, fine_cell, index_axis, index_lower_bound};
use crate::qp::{clamp_u, BoxQp};
use crate::tables::{PlanSet, Tables};

/// What one explicit step produced besides the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplicitOutcome {
    /// The stored sample used (its slot).
    pub slot: usize,
    /// Active-set iterations of the QP.
    pub qp_iterations: u32,
    /// Whether the QP converged within its iteration cap.
    pub converged: bool,
    /// The Gauss-Newton model's prediction of the plan's nonlinear cost
    /// (no rollout; the refinement measures the true cost).
    pub predicted_cost: f64,
}

/// One stored sample's window QP as a function of the deviation
/// d = e - state: min 1/2 x'Hx + (sensitivity d)'x over the window's input
/// changes x (tracking the stored trajectory; SI, the cost halved as in the
/// refinement's QP). Reads its record in the table file.
#[derive(Debug, Clone, Copy)]
pub struct ExplicitSample<'t, 'a> {
    tables: &'t Tables<'a>,
    at: usize,
}

impl<'t, 'a> ExplicitSample<'t, 'a> {
    /// Sample `slot`; None past the stored samples.
    pub fn get(tables: &'t Tables<'a>, slot: usize) -> Option<Self> {
        Some(ExplicitSample {
            tables,
            at: tables.explicit_record(slot)?,
        })
    }
    /// Plan table: 0 back to back, 1 constant sampling, 2 fine, 3 fine with the coast.
    pub fn source(&self) -> u8 {
        self.tables
            .record_u8(self.at, self.tables.explicit_layout.source())
    }
    pub fn plan(&self) -> u16 {
        self.tables
            .record_u16(self.at, self.tables.explicit_layout.plan())
    }
    /// Plan sample the window starts at (its relative state, the
    /// linearization point, is `explicit_state`).
    pub fn offset(&self) -> u16 {
        self.tables
            .record_u16(self.at, self.tables.explicit_layout.offset())
    }
    /// Condensed Hessian, upper triangle row by row, entry `idx`.
    #[inline(always)]
    pub fn hessian(&self, idx: usize) -> f64 {
        self.tables
            .record_f64(self.at, self.tables.explicit_layout.hessian(), idx)
    }
    /// Gradient of the online cost in the window inputs at zero deviation.
    #[inline(always)]
    pub fn gradient(&self, a: usize) -> f64 {
        self.tables
            .record_f64(self.at, self.tables.explicit_layout.gradient(), a)
    }
    /// Hessian entries `idx..idx + out.len()` of the upper triangle (a row
    /// from its diagonal on, read as one run).
    #[inline(always)]
    pub fn hessian_run(&self, idx: usize, out: &mut [f64]) {
        self.tables
            .record_f64s(self.at, self.tables.explicit_layout.hessian(), idx, out)
    }
    /// Row `a` of the sensitivity: d gradient_a / d deviation_j for every j.
    #[inline(always)]
    pub fn sensitivity_row(&self, a: usize, out: &mut [f64]) {
        let l = self.tables.explicit_layout;
        self.tables
            .record_f64s(self.at, l.sensitivity(), a * l.nx, out)
    }
    /// d gradient_a / d deviation_j.
    #[inline(always)]
    pub fn sensitivity(&self, a: usize, j: usize) -> f64 {
        let l = self.tables.explicit_layout;
        self.tables
            .record_f64(self.at, l.sensitivity(), a * l.nx + j)
    }
    /// Nonlinear cost of the stored tail from its state.
    pub fn cost(&self) -> f64 {
        self.tables
            .record_f64(self.at, self.tables.explicit_layout.cost(), 0)
    }
    /// Gauss-Newton model of that cost in d (halved, as the QP).
    #[inline(always)]
    pub fn cost_gradient(&self, r: usize) -> f64 {
        self.tables
            .record_f64(self.at, self.tables.explicit_layout.cost_gradient(), r)
    }
    /// Row `r` of the cost model's Hessian.
    #[inline(always)]
    pub fn cost_hessian_row(&self, r: usize, out: &mut [f64]) {
        let l = self.tables.explicit_layout;
        self.tables
            .record_f64s(self.at, l.cost_hessian(), r * l.nx, out)
    }
    /// Active set of the solution at zero deviation (-1, 0, +1).
    pub fn active<const N: usize>(&self) -> [i8; N] {
        let base = self.tables.explicit_layout.active();
        let mut out = [0i8; N];
        let mut a = 0;
        while a < N {
            out[a] = self.tables.record_u8(self.at, base + a) as i8;
            a += 1;
        }
        out
    }
}

/// How many samples along the previous step's plan the explicit tier
/// looks for the nearest stored state: the longest actuation phase.
pub const EXPLICIT_SUCCESSORS: usize = 10;

/// Sample `slot`'s relative state component `j` (its linearization point).
#[inline(always)]
pub fn explicit_state(t: &Tables, slot: usize, j: usize) -> f64 {
    t.f64_at(Section::ExplicitState, slot * t.dims.nx + j)
}

/// Sample `slot`'s relative state (its linearization point), read as one
/// run; NaN past the stored samples.
#[inline(always)]
pub fn explicit_state_row<const NX: usize>(t: &Tables, slot: usize) -> [f64; NX] {
    let mut out = [f64::NAN; NX];
    if let Some(first) = slot.checked_mul(t.dims.nx) {
        t.f64_run(Section::ExplicitState, first, &mut out);
    }
    out
}

/// The stored sample for relative state `e`: at rest on the fine grid,
/// the fine plan's (the index's nearest sample there is a finished plan,
/// which cannot separate capsules at rest); otherwise the nearest (in
/// index cells) of the samples named by the cell of `e`, its 2 NX
/// neighbours along the axes (those the sparse index keeps; a cell is
/// found by bisection over the kept cells), and the `EXPLICIT_SUCCESSORS`
/// samples after `last` on its plan (the previous step's sample;
/// `usize::MAX`: none); outside the index, those successors alone. Why not
/// the cell's own
/// sample alone: it was chosen by its cost from the cell's centre, and a
/// cell is 0.1 m/s wide in speed; linearized around it, the deviation
/// reached 0.1 m/s and consecutive steps jumped between plans.
pub fn explicit_slot<const NX: usize>(
    t: &Tables,
    e: &[f64; NX],
    coasted: bool,
    last: usize,
) -> Option<usize> {
    if let Some(slot) = fine_slot(t, e, coasted) {
        return Some(slot);
    }
    let slots = if coasted {
        Section::CoastedExplicitIndexSlot
    } else {
        Section::ExplicitIndexSlot
    };
    let mut best = usize::MAX;
    let mut best_distance = f64::INFINITY;
    let mut idx = [0usize; NX];
    let mut flat = 0u64;
    let mut in_range = true;
    let mut j = 0;
    while j < NX {
        let axis = index_axis(t, j);
        match axis_nearest(&axis, e[j]) {
            Some(i) => idx[j] = i,
            None => {
                // Outside the index (a plan's excursion can reach beyond
                // it): the previous sample's successors are the candidates.
                in_range = false;
                break;
            }
        }
        flat = flat * axis.count as u64 + idx[j] as u64;
        j += 1;
    }
    if in_range {
        index_candidates(t, e, slots, &idx, flat, &mut best, &mut best_distance);
    }
    // The previous sample's successors along its plan (the generator
    // numbers a plan's samples consecutively; past a plan's last sample the
    // next plan's are candidates like any other): a phase of several
    // samples moves the state that many samples on.
    if last < t.explicit_count {
        let mut k = 1;
        while k <= EXPLICIT_SUCCESSORS {
            consider(t, e, last + k, &mut best, &mut best_distance);
            k += 1;
        }
    }
    if best < t.explicit_count {
        Some(best)
    } else {
        None
    }
}

/// The samples named by the kept cell `flat` (multi-index `idx`) and its
/// 2 NX axis neighbours, nearest kept in `best`.
fn index_candidates<const NX: usize>(
    t: &Tables,
    e: &[f64; NX],
    slots: Section,
    idx: &[usize; NX],
    flat: u64,
    best: &mut usize,
    best_distance: &mut f64,
) {
    // The sparse index keeps only cells near stored plans: the cell and its
    // neighbours are found among the kept cells by bisection (cells not
    // kept are skipped). The cell's lower bound splits the kept cells:
    // lower neighbours lie before it, higher ones from it on.
    let cells = t.cell_count;
    let split = index_lower_bound(t, flat, 0, cells);
    consider(
        t,
        e,
        slot_of_cell(t, slots, flat, split, cells),
        best,
        best_distance,
    );
    // Neighbours: stride of axis j = product of the later axes' counts.
    // Kept cells are distinct integers, so at most `stride` of them lie
    // between a neighbour and the cell: the bisection needs only that span
    // of the kept cells (no probe at all along the last axis).
    let mut stride = 1u64;
    let mut j = NX;
    while j > 0 {
        j -= 1;
        let count = index_axis(t, j).count;
        let span = if stride < cells as u64 {
            stride as usize
        } else {
            cells
        };
        if idx[j] > 0 {
            let lo = split.saturating_sub(span);
            let slot = slot_of_cell(t, slots, flat - stride, lo, split);
            consider(t, e, slot, best, best_distance);
        }
        if idx[j] + 1 < count {
            let hi = if split + span + 1 < cells {
                split + span + 1
            } else {
                cells
            };
            let slot = slot_of_cell(t, slots, flat + stride, split, hi);
            consider(t, e, slot, best, best_distance);
        }
        stride *= count as u64;
    }
}

/// The explicit slot of the cell numbered `flat` (row-major on the dense
/// grid) if it is kept, looked for among the kept cells `[lo, hi)`;
/// `usize::MAX` otherwise.
fn slot_of_cell(t: &Tables, slots: Section, flat: u64, lo: usize, hi: usize) -> usize {
    let kept = index_lower_bound(t, flat, lo, hi);
    if kept >= hi || kept >= t.cell_count || t.u64_at(Section::IndexCells, kept) != flat {
        return usize::MAX;
    }
    if kept >= t.elements(slots) {
        return usize::MAX;
    }
    match t.u16_at(slots, kept) {
        NO_SLOT => usize::MAX,
        s => s as usize,
    }
}

/// Keeps `slot` in `best` if its stored state is nearer to `e` (squared
/// distance in index cells) than the best so far.
fn consider<const NX: usize>(
    t: &Tables,
    e: &[f64; NX],
    slot: usize,
    best: &mut usize,
    best_distance: &mut f64,
) {
    if slot >= t.explicit_count {
        return;
    }
    let state = explicit_state_row::<NX>(t, slot);
    let mut dist = 0.0;
    let mut j = 0;
    while j < NX {
        let r = (e[j] - state[j]) / index_axis(t, j).step;
        dist += r * r;
        j += 1;
    }
    if dist < *best_distance {
        *best_distance = dist;
        *best = slot;
    }
}

fn fine_slot<const NX: usize>(t: &Tables, e: &[f64; NX], coasted: bool) -> Option<usize> {
    let flat = fine_cell(t, e)?;
    let slots = if coasted {
        Section::CoastedFineExplicitSlot
    } else {
        Section::FineExplicitSlot
    };
    if flat >= t.elements(slots) {
        return None;
    }
    let slot = t.u16_at(slots, flat);
    if slot == NO_SLOT || slot as usize >= t.explicit_count {
        return None;
    }
    Some(slot as usize)
}

/// The stored inputs of sample `s`'s plan from its offset on, zero-padded.
fn stored_tail<const K: usize>(t: &Tables, s: &ExplicitSample, out: &mut [f64; K]) {
    let p = s.plan() as usize;
    let set = match s.source() {
        0 => PlanSet::BackToBack,
        1 => PlanSet::Coasted,
        2 => PlanSet::Fine,
        _ => PlanSet::CoastedFine,
    };
    let offset = s.offset() as usize;
    // The plan's inputs from the offset on are one run of its row.
    let stored = K.saturating_sub(offset);
    t.plan_u_run(set, p, offset, &mut out[..stored]);
    out[stored..].fill(0.0);
}

/// Loads sample `s`'s window QP at deviation `d` into `qp`, with the box
/// around the stored window inputs `u`.
pub fn load_qp<const NX: usize, const N: usize, const K: usize>(
    s: &ExplicitSample,
    u_max: f64,
    d: &[f64; NX],
    u: &[f64; K],
    qp: &mut BoxQp<N>,
) {
    let mut idx = 0;
    let mut row = [0.0; N];
    let mut sensitivity = [0.0; NX];
    let mut a = 0;
    while a < N {
        // Row a of the upper triangle, from the diagonal on, is one run.
        let run = &mut row[..N - a];
        s.hessian_run(idx, run);
        let mut b = a;
        while b < N {
            let h = run[b - a];
            qp.h[a][b] = h;
            qp.h[b][a] = h;
            b += 1;
        }
        idx += N - a;
        s.sensitivity_row(a, &mut sensitivity);
        let mut g = 0.0;
        let mut j = 0;
        while j < NX {
            g += sensitivity[j] * d[j];
            j += 1;
        }
        qp.g[a] = g;
        qp.lo[a] = -u_max - u[a];
        qp.hi[a] = u_max - u[a];
        a += 1;
    }
}

/// The explicit plan for relative state `e` into `out` (`coasted`:
/// constant sampling's tables; `last`: the previous step's slot, or
/// `usize::MAX`; `warm`: the QP's starting active set, None for the stored
/// sample's); None outside the index and the fine grid when no previous
/// sample's successor is a candidate.
#[allow(clippy::too_many_arguments)]
pub fn explicit_plan<const NX: usize, const N: usize, const K: usize>(
    t: &Tables,
    u_max: f64,
    e: &[f64; NX],
    coasted: bool,
    last: usize,
    warm: Option<&[i8; N]>,
    qp: &mut BoxQp<N>,
    out: &mut [f64; K],
) -> Option<ExplicitOutcome> {
    let slot = explicit_slot(t, e, coasted, last)?;
    let s = ExplicitSample::get(t, slot)?;
    stored_tail(t, &s, out);
    let state = explicit_state_row::<NX>(t, slot);
    let mut d = [0.0; NX];
    let mut j = 0;
    while j < NX {
        d[j] = e[j] - state[j];
        j += 1;
    }
    load_qp(&s, u_max, &d, out, qp);
    let stored_active = s.active::<N>();
    let start = match warm {
        Some(active) => active,
        None => &stored_active,
    };
    let (iterations, converged) = qp.solve_from(start);
    let mut a = 0;
    while a < N {
        out[a] = clamp_u(out[a] + qp.x[a], u_max);
        a += 1;
    }
    Some(ExplicitOutcome {
        slot,
        qp_iterations: iterations,
        converged,
        predicted_cost: predicted_cost(&s, &d, qp),
    })
}

/// The Gauss-Newton model of the plan's cost: the stored tail's cost plus
/// the first and second order terms in the deviation and the step (the
/// model is of half the cost, as the QP, hence the factor 2).
fn predicted_cost<const NX: usize, const N: usize>(
    s: &ExplicitSample,
    d: &[f64; NX],
    qp: &BoxQp<N>,
) -> f64 {
    let mut half = 0.0;
    let mut row = [0.0; NX];
    let mut r = 0;
    while r < NX {
        s.cost_hessian_row(r, &mut row);
        let mut hd = 0.0;
        let mut c = 0;
        while c < NX {
            hd += row[c] * d[c];
            c += 1;
        }
        half += d[r] * (s.cost_gradient(r) + 0.5 * hd);
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
        half += qp.x[a] * (s.gradient(a) + qp.g[a] + 0.5 * hx);
        a += 1;
    }
    let c = s.cost() + 2.0 * half;
    if c > 0.0 {
        c
    } else {
        0.0
    }
}

/// Certified worst case of one explicit step: floating-point operations
/// counted from the loop bounds with the QP at its iteration cap
/// `qp_iterations`, every iteration at its worst (all variables free, the
/// factor rebuilt).
pub const fn explicit_step_ops(n: usize, nx: usize, k: usize, qp_iterations: usize) -> u64 {
    let (n, nx, k) = (n as u64, nx as u64, k as u64);
    // Index look-up: per axis a subtraction, a division, two compares, a
    // rounding, a multiply-add; the fine-grid test likewise per capsule.
    // The kept cells of the sparse index are found by bisection over
    // integer cell numbers (at most 64 integer compares per cell, 2 NX + 1
    // cells): no floating-point operations.
    let lookup = 6 * nx + 6 * (nx / 2) + 2 * nx;
    // The nearest of the candidates (the cell's sample, its 2 NX axis
    // neighbours', the last sample's `EXPLICIT_SUCCESSORS` successors): per
    // candidate and axis a subtraction, a division, a multiply-add, and one
    // compare.
    let candidates = (2 * nx + 1 + EXPLICIT_SUCCESSORS as u64) * (4 * nx + 1);
    // Deviation, gradient g0 + F d, bounds, Hessian copy, warm start.
    let setup = nx + 2 * n * nx + 2 * n + n * n + 2 * n;
    // One active-set iteration, worst case.
    let collect = n;
    // Cholesky rows r = 0..n, columns c = 0..=r: 2c multiply-adds + 1.
    let mut factor = 0;
    let mut r = 0;
    while r < n {
        let mut c = 0;
        while c <= r {
            factor += 2 * c + 2;
            c += 1;
        }
        r += 1;
    }
    let newton_rhs = n * (2 * n + 1);
    let substitutions = 2 * (n * n + n);
    let ratio = 5 * n;
    let update = 3 * n;
    let multipliers = n * (2 * n + 3);
    let per_iteration =
        collect + factor + newton_rhs + substitutions + ratio + update + multipliers + n;
    // Plan assembly (window clamp, tail copy) and the predicted cost.
    let finish = 3 * n + k + (nx * nx * 2 + nx * 2 + 2 * n * nx + n * n * 2 + 2 * n + 4);
    // The law alone's similar model state (`refine::Similarity`, its
    // factors computed when the learned factors change): each capsule's
    // error and speed scaled; each of the plan's K inputs scaled and
    // clamped.
    let similarity = nx + 3 * k;
    lookup + candidates + setup + qp_iterations as u64 * per_iteration + finish + similarity
}
