//! Chained legs: displacements beyond the reach of one stored plan, as a
//! sequence of stored rest-to-rest plans.
//!
//! The dynamics do not depend on position, so a plan from rest at e0 moves
//! the capsules by -e0 from anywhere, ending at rest: legs compose exactly.
//! For every displacement `d = x_start - x_target` on a lattice (the plan
//! grid's spacing, spanning the workspace in both directions) a dynamic
//! programme finds the sequence of stored plans with the least summed
//! minimum time, and stores its first leg and the total. Legs are
//! *monotone*: each leg moves every capsule toward its target and never
//! past it, so every waypoint lies in the box spanned by start and target,
//! which is inside the (convex) workspace whenever both ends are.

use crate::grid::{flatten, unflatten, Axis, PlanEntry};
use serde::{Deserialize, Serialize};

/// No chain reaches this displacement (a stored first-leg value).
pub const NO_LEG: u16 = u16::MAX;

/// Per lattice displacement: the first leg's plan and the chain's time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LegTable {
    /// Lattice of each capsule's displacement `x_start - x_target`, m.
    pub axis: Axis,
    /// Row-major over the M displacement axes: index of the first leg's
    /// plan, or [`NO_LEG`] (zero displacement has no leg either).
    pub first_leg: Vec<u16>,
    /// Summed minimum times of the chain's legs (s); infinite without a
    /// chain, 0 at zero displacement.
    pub chain_time_s: Vec<f64>,
}

/// The chain table for displacements up to `span_m` per capsule.
pub fn build_leg_table(plan_axis: &Axis, plans: &[PlanEntry], m: usize, span_m: f64) -> LegTable {
    let axis = Axis::symmetric(span_m, plan_axis.step);
    let dims = vec![axis.count; m];
    let total: usize = dims.iter().product();
    let centre = (axis.count / 2) as i64;
    let plan_centre = (plan_axis.count / 2) as i64;
    let plan_dims = vec![plan_axis.count; m];
    let offsets = |flat: usize, dims: &[usize], c: i64| -> Vec<i64> {
        unflatten(flat, dims)
            .iter()
            .map(|&i| i as i64 - c)
            .collect()
    };
    // Reached plans by their lattice offsets, with their time.
    let legs: Vec<(usize, Vec<i64>, f64)> = plans
        .iter()
        .enumerate()
        .filter(|(_, p)| p.reached && p.min_time_s.is_finite())
        .map(|(pi, p)| (pi, offsets(pi, &plan_dims, plan_centre), p.min_time_s))
        .filter(|(_, o, _)| o.iter().any(|&v| v != 0))
        .collect();
    // Process displacements by growing L1 norm: each leg strictly reduces it.
    let mut order: Vec<usize> = (0..total).collect();
    order.sort_by_key(|&f| {
        (
            offsets(f, &dims, centre)
                .iter()
                .map(|v| v.unsigned_abs())
                .sum::<u64>(),
            f,
        )
    });
    let mut first_leg = vec![NO_LEG; total];
    let mut chain_time_s = vec![f64::INFINITY; total];
    for &flat in &order {
        let d = offsets(flat, &dims, centre);
        if d.iter().all(|&v| v == 0) {
            chain_time_s[flat] = 0.0;
            continue;
        }
        for (pi, l, t) in &legs {
            // Monotone: 0 <= l_i / d_i <= 1 componentwise.
            let inside = d
                .iter()
                .zip(l)
                .all(|(&di, &li)| li == 0 || (li.signum() == di.signum() && li.abs() <= di.abs()));
            if !inside {
                continue;
            }
            let rest: Vec<usize> = d
                .iter()
                .zip(l)
                .map(|(di, li)| (di - li + centre) as usize)
                .collect();
            let total_s = t + chain_time_s[flatten(&rest, &dims)];
            if total_s < chain_time_s[flat] {
                chain_time_s[flat] = total_s;
                first_leg[flat] = *pi as u16;
            }
        }
    }
    LegTable {
        axis,
        first_leg,
        chain_time_s,
    }
}
