//! The warm-start index: for relative states (positions and speeds) near a
//! stored plan, the plan sample whose tail is the best warm start.
//!
//! Why sparse: a dense grid over [e1, v1, ..., eM, vM] has
//! (positions x speeds)^M cells, 35 721 for two capsules but 250 047 for
//! three and 1.3e9 for four, while the plans visit a thin tube of that
//! space (plans x samples states). The index keeps only the cells within
//! [`INDEX_NEIGHBOUR_RADIUS`] cells of a stored sample, as a sorted list of
//! row-major cell numbers searched by bisection online (at most 64 probes,
//! fixed bound, no heap); a state in no kept cell is outside the index,
//! exactly as a state beyond the dense grid's edge was. The work to build
//! it scales the same way: candidates for a cell come only from samples in
//! its neighbourhood, not from every sample of every plan.

use crate::grid::{flatten, unflatten, Axis, PlanEntry, Progress};
use crate::ocp::Ocp;
use rayon::prelude::*;

/// Cells kept around every stored plan sample: those within this many
/// cells along every axis of the one the sample falls in.
pub const INDEX_NEIGHBOUR_RADIUS: usize = 1;
/// Candidates (nearest by scaled distance) whose tails are rolled out when
/// choosing a cell's warm start.
const INDEX_CANDIDATES: usize = 8;
/// A cell with no candidate plan (a stored entry).
pub const NO_PLAN: (u16, u16) = (u16::MAX, 0);

/// The index's grid: one axis for relative positions, one for speeds, the
/// same for every capsule (row-major over e1, v1, e2, v2, ...).
#[derive(Debug, Clone, Copy)]
pub struct IndexGrid<'a> {
    pub position: &'a Axis,
    pub speed: &'a Axis,
    pub capsules: usize,
}

impl IndexGrid<'_> {
    fn dims(&self) -> Vec<usize> {
        (0..2 * self.capsules).map(|j| self.axis(j).count).collect()
    }

    fn axis(&self, j: usize) -> &Axis {
        if j.is_multiple_of(2) {
            self.position
        } else {
            self.speed
        }
    }

    /// Centre of cell `flat`.
    pub fn centre(&self, flat: u64) -> Vec<f64> {
        unflatten(flat as usize, &self.dims())
            .iter()
            .enumerate()
            .map(|(j, &i)| self.axis(j).value(i))
            .collect()
    }

    /// Multi-index of the cell `state` falls in, each axis clamped to the
    /// grid (a sample beyond the edge still marks the edge cells).
    fn nearest_clamped(&self, state: &[f64]) -> Vec<usize> {
        (0..2 * self.capsules)
            .map(|j| {
                let a = self.axis(j);
                let f = ((state[j] - a.start) / a.step).round();
                f.clamp(0.0, (a.count - 1) as f64) as usize
            })
            .collect()
    }

    /// Row-major numbers of the cells within `radius` of `centre` along
    /// every axis (inside the grid).
    fn neighbourhood(&self, centre: &[usize], radius: usize) -> Vec<u64> {
        let dims = self.dims();
        let r = radius as i64;
        let side = 2 * radius + 1;
        let total = side.pow(dims.len() as u32);
        (0..total)
            .filter_map(|k| {
                let mut k = k;
                let mut idx = vec![0usize; dims.len()];
                for d in (0..dims.len()).rev() {
                    let off = (k % side) as i64 - r;
                    k /= side;
                    let i = centre[d] as i64 + off;
                    if i < 0 || i >= dims[d] as i64 {
                        return None;
                    }
                    idx[d] = i as usize;
                }
                Some(flatten(&idx, &dims) as u64)
            })
            .collect()
    }
}

/// Stored samples of reached plans: (plan, sample, state).
fn reached_samples(plans: &[PlanEntry], steps: usize) -> Vec<(u16, u16, &[f64])> {
    plans
        .iter()
        .enumerate()
        .filter(|(_, p)| p.reached)
        .flat_map(|(pi, p)| {
            p.plan.states[..steps]
                .iter()
                .enumerate()
                .map(move |(k, s)| (pi as u16, k as u16, s.as_slice()))
        })
        .collect()
}

/// The kept cells: within [`INDEX_NEIGHBOUR_RADIUS`] of a sample of any of
/// `plan_sets`, sorted ascending (the order the runtime bisects).
pub fn occupied_cells(grid: IndexGrid, plan_sets: &[&[PlanEntry]], steps: usize) -> Vec<u64> {
    let samples: Vec<&[f64]> = plan_sets
        .iter()
        .flat_map(|plans| reached_samples(plans, steps))
        .map(|(_, _, s)| s)
        .collect();
    let mut cells: Vec<u64> = samples
        .par_iter()
        .flat_map_iter(|s| grid.neighbourhood(&grid.nearest_clamped(s), INDEX_NEIGHBOUR_RADIUS))
        .collect();
    cells.par_sort_unstable();
    cells.dedup();
    cells
}

/// For every kept cell, the stored plan sample whose tail, rolled out from
/// the cell centre, has the lowest cost among the nearest candidates of the
/// cell's neighbourhood; [`NO_PLAN`] where the neighbourhood has none.
pub fn build_index(
    ocp: &Ocp,
    plans: &[PlanEntry],
    grid: IndexGrid,
    cells: &[u64],
    progress: &dyn Progress,
) -> Vec<(u16, u16)> {
    let chooser = CellChooser::new(ocp, plans, grid);
    progress.start("warm-start index", cells.len());
    cells
        .par_iter()
        .map(|&flat| {
            let cell = chooser.cell(flat);
            progress.tick();
            cell
        })
        .collect()
}

/// The per-cell choice of [`build_index`]: every cell is independent of the
/// others (which lets `crate::shard` split the cells over processes).
pub struct CellChooser<'p> {
    ocp: &'p Ocp<'p>,
    plans: &'p [PlanEntry],
    grid: IndexGrid<'p>,
    samples: Vec<(u16, u16, &'p [f64])>,
    /// Samples bucketed by the cell they fall in, sorted for bisection.
    buckets: Vec<(u64, u32)>,
    scale: Vec<f64>,
}

impl<'p> CellChooser<'p> {
    pub fn new(ocp: &'p Ocp<'p>, plans: &'p [PlanEntry], grid: IndexGrid<'p>) -> Self {
        let nx = 2 * grid.capsules;
        let samples = reached_samples(plans, ocp.steps);
        let mut buckets: Vec<(u64, u32)> = samples
            .iter()
            .enumerate()
            .map(|(si, (_, _, s))| {
                let dims = grid.dims();
                (flatten(&grid.nearest_clamped(s), &dims) as u64, si as u32)
            })
            .collect();
        buckets.sort_unstable();
        let scale: Vec<f64> = (0..nx).map(|j| grid.axis(j).step).collect();
        CellChooser {
            ocp,
            plans,
            grid,
            samples,
            buckets,
            scale,
        }
    }

    /// The warm start of cell `flat` (row-major cell number).
    pub fn cell(&self, flat: u64) -> (u16, u16) {
        let (grid, buckets, samples) = (self.grid, &self.buckets, &self.samples);
        let nx = 2 * grid.capsules;
        let steps = self.ocp.steps;
        let centre = grid.centre(flat);
        let around = grid.neighbourhood(&grid.nearest_clamped(&centre), INDEX_NEIGHBOUR_RADIUS);
        let mut near: Vec<(f64, u32)> = around
            .iter()
            .flat_map(|&c| {
                let from = buckets.partition_point(|&(b, _)| b < c);
                buckets[from..]
                    .iter()
                    .take_while(move |&&(b, _)| b == c)
                    .map(|&(_, si)| si)
            })
            .map(|si| {
                let s = samples[si as usize].2;
                let d: f64 = (0..nx)
                    .map(|j| ((s[j] - centre[j]) / self.scale[j]).powi(2))
                    .sum();
                (d, si)
            })
            .collect();
        if near.is_empty() {
            return NO_PLAN;
        }
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        near.truncate(INDEX_CANDIDATES);
        let best = near
            .iter()
            .map(|&(_, si)| {
                let (pi, k, _) = samples[si as usize];
                let plan = &self.plans[pi as usize].plan;
                let mut tail = vec![0.0; steps];
                tail[..steps - k as usize].copy_from_slice(&plan.u[k as usize..]);
                (self.ocp.rollout(&centre, &tail).1, pi, k)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("non-empty");
        (best.1, best.2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbourhood_stays_inside_the_grid() {
        let pos = Axis::symmetric(0.01, 0.01);
        let spd = Axis::symmetric(0.1, 0.1);
        let grid = IndexGrid {
            position: &pos,
            speed: &spd,
            capsules: 1,
        };
        // A corner cell has 2 x 2 neighbours (itself included), the centre 3 x 3.
        assert_eq!(grid.neighbourhood(&[0, 0], 1).len(), 4);
        assert_eq!(
            grid.neighbourhood(&[1, 1], 1),
            vec![0, 1, 2, 3, 4, 5, 6, 7, 8]
        );
        assert_eq!(grid.centre(5), vec![0.0, 0.1]);
    }
}
