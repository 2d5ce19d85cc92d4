//! Closed-loop quality metrics computed from the plant's records, so that every
//! controller and sampling scheme is scored by the same rules.

use crate::plant::{Phase, Record};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// Settling band on each position error, m (the one the solver's
/// minimum-time shooting aims inside).
pub const SETTLE_POSITION_TOL_M: f64 = capsule_mpc_runtime::solver::shooting::BAND_POSITION_M;
/// Settling band on each speed, m/s (strict: |v| < this).
pub const SETTLE_SPEED_TOL_M_PER_S: f64 = capsule_mpc_runtime::solver::shooting::BAND_SPEED_M_PER_S;

/// Summary of one closed-loop run (the `metrics` object of `simulate --json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Earliest record time from which every position stays within
    /// [`SETTLE_POSITION_TOL_M`] of its target and every |speed| below
    /// [`SETTLE_SPEED_TOL_M_PER_S`] until the end; `null` if never.
    pub settle_time_s: Option<f64>,
    /// Largest |x_i - target_i| over capsules at the last row, m.
    pub final_position_error_m: f64,
    /// Largest |u| applied, T/m.
    pub max_abs_u: f64,
    /// Fraction of the run time spent actuating (weighted by row durations).
    pub duty_cycle: f64,
    /// The same fraction from the start until `settle_time_s` (the whole run
    /// when it never settles): the part of the run the switching rule
    /// shapes, before the terminal hold.
    pub duty_cycle_until_settled: f64,
    /// Rows with some |x_i - target_i| > position bound or |v_i| > speed bound.
    pub state_bound_violations: usize,
    /// Longest controller computation for one step, ns (measured by the caller).
    pub max_step_compute_ns: u64,
    /// Minimum rest-to-rest time of the move into the settle band, from the
    /// generator's tables (summed over legs for a chained move), s; `null`
    /// when unknown (paper preset, a retarget, no move).
    #[serde(default)]
    pub min_time_bound_s: Option<f64>,
    /// settle_time_s / min_time_bound_s (the strict settle); `null` when
    /// either is.
    #[serde(default)]
    pub settle_over_bound: Option<f64>,
    /// settle_held_s / min_time_bound_s, labelled as the held settle's
    /// ratio wherever it is printed; `null` when either is.
    #[serde(default)]
    pub held_settle_over_bound: Option<f64>,
    /// Minimum time of the schedule actually played, s: under constant
    /// sampling the stored coasted plan's (one sample per actuation phase,
    /// then the tracking coast; `null` off its 5 mm plan grid), otherwise
    /// `min_time_bound_s` (every sample actuates).
    #[serde(default)]
    pub schedule_min_time_s: Option<f64>,
    /// settle_time_s / schedule_min_time_s (the strict settle); `null`
    /// when either is.
    #[serde(default)]
    pub settle_over_schedule_bound: Option<f64>,
    /// Farthest any capsule went beyond the workspace box, m (0: inside).
    #[serde(default)]
    pub workspace_excursion_m: f64,
    /// First record time at which the state is inside the settle band
    /// (every position within [`SETTLE_POSITION_TOL_M`], every speed below
    /// [`SETTLE_SPEED_TOL_M_PER_S`]); `null` if never.
    #[serde(default)]
    pub first_in_band_s: Option<f64>,
    /// Station keeping: the fraction of the time from `first_in_band_s` to
    /// the end of the run spent inside the settle band (1 when it never
    /// leaves it again); `null` when never in the band or entered at the
    /// last row.
    #[serde(default)]
    pub time_in_band_after_entry: Option<f64>,
    /// Earliest record time from which the state stays in the settle band
    /// for at least [`SETTLE_HOLD_S`] (the arrival, robust to the slow
    /// relative drift that can take the capsules out seconds later; see
    /// docs/known-limits.md); `null` if never. Printed only labelled as
    /// the held settle; `held_settle_over_bound` uses it.
    #[serde(default)]
    pub settle_held_s: Option<f64>,
}

/// How long the state must stay in the band for `settle_held_s`, s.
pub const SETTLE_HOLD_S: f64 = 1.0;

/// Earliest record time from which every row for the next `hold_s` lies in
/// the settle band around `target` (the run must last that long).
pub fn settle_held_s(records: &[Record], target: &[f64], hold_s: f64) -> Option<f64> {
    let mut start: Option<f64> = None;
    for r in records {
        if in_settle_band(&r.x, target) {
            let t0 = *start.get_or_insert(r.t_s);
            if r.t_s - t0 >= hold_s - 1e-9 {
                return Some(t0);
            }
        } else {
            start = None;
        }
    }
    None
}

/// True when every capsule of `x` is inside the settling band around `target`.
fn in_settle_band(x: &[f64], target: &[f64]) -> bool {
    x.chunks_exact(2)
        .zip(target.chunks_exact(2))
        .all(|(xv, tv)| {
            (xv[0] - tv[0]).abs() <= SETTLE_POSITION_TOL_M && xv[1].abs() < SETTLE_SPEED_TOL_M_PER_S
        })
}

/// Fraction of the time in [`from_s`, `to_s`) (rows weighted by their
/// duration, clipped to the window) the state spends inside the settle band
/// around `target`; `None` for an empty window. Rows are piecewise
/// constant: a row counts as in or out for its whole duration.
pub fn time_in_band_fraction(
    records: &[Record],
    target: &[f64],
    from_s: f64,
    to_s: f64,
) -> Option<f64> {
    let (mut inside_s, mut total_s) = (0.0, 0.0);
    for pair in records.windows(2) {
        let (a, b) = (pair[0].t_s.max(from_s), pair[1].t_s.min(to_s));
        if b <= a {
            continue;
        }
        total_s += b - a;
        if in_settle_band(&pair[0].x, target) {
            inside_s += b - a;
        }
    }
    (total_s > 0.0).then(|| inside_s / total_s)
}

/// First record time inside the settle band around `target`.
pub fn first_in_band_s(records: &[Record], target: &[f64]) -> Option<f64> {
    records
        .iter()
        .find(|r| in_settle_band(&r.x, target))
        .map(|r| r.t_s)
}

/// Actuation time over total time for the rows that start before `end_s`.
fn duty_cycle_until(records: &[Record], end_s: f64) -> f64 {
    let (mut actuate_s, mut total_s) = (0.0, 0.0);
    for pair in records.windows(2).filter(|p| p[0].t_s < end_s) {
        let dt_s = pair[1].t_s - pair[0].t_s;
        total_s += dt_s;
        if pair[0].phase == Phase::Actuate {
            actuate_s += dt_s;
        }
    }
    if total_s > 0.0 {
        actuate_s / total_s
    } else {
        0.0
    }
}

impl Metrics {
    /// Scores `records` against the target state `target` ([x1, v1, x2, v2, ...];
    /// only its positions are used). Errors when a row's state length differs
    /// from the target's or is odd.
    pub fn compute(
        records: &[Record],
        target: &[f64],
        position_bound_m: f64,
        speed_bound_m_per_s: f64,
        max_step_compute_ns: u64,
    ) -> Result<Metrics> {
        if target.len() % 2 == 1 {
            bail!(
                "target has {} entries; an even number (x, v per capsule) is needed",
                target.len()
            );
        }
        if let Some(r) = records.iter().find(|r| r.x.len() != target.len()) {
            bail!(
                "record at t = {} s has {} states but the target has {}",
                r.t_s,
                r.x.len(),
                target.len()
            );
        }

        // Settling: the row after the last one outside the band.
        let settle_time_s = match records.iter().rposition(|r| !in_settle_band(&r.x, target)) {
            None => records.first().map(|r| r.t_s),
            Some(last_out) => records.get(last_out + 1).map(|r| r.t_s),
        };

        let final_position_error_m = records.last().map_or(0.0, |r| {
            r.x.iter()
                .step_by(2)
                .zip(target.iter().step_by(2))
                .map(|(x, t)| (x - t).abs())
                .fold(0.0, f64::max)
        });

        let max_abs_u = records
            .iter()
            .map(|r| r.u_t_per_m.abs())
            .fold(0.0, f64::max);

        let duty_cycle = duty_cycle_until(records, f64::INFINITY);
        let duty_cycle_until_settled =
            duty_cycle_until(records, settle_time_s.unwrap_or(f64::INFINITY));

        let state_bound_violations = records
            .iter()
            .filter(|r| {
                r.x.chunks_exact(2)
                    .zip(target.chunks_exact(2))
                    .any(|(xv, tv)| {
                        (xv[0] - tv[0]).abs() > position_bound_m
                            || xv[1].abs() > speed_bound_m_per_s
                    })
            })
            .count();

        let first_in_band = first_in_band_s(records, target);
        let time_in_band_after_entry =
            first_in_band.and_then(|t| time_in_band_fraction(records, target, t, f64::INFINITY));

        Ok(Metrics {
            settle_time_s,
            final_position_error_m,
            max_abs_u,
            duty_cycle,
            duty_cycle_until_settled,
            state_bound_violations,
            max_step_compute_ns,
            min_time_bound_s: None,
            settle_over_bound: None,
            held_settle_over_bound: None,
            schedule_min_time_s: None,
            settle_over_schedule_bound: None,
            workspace_excursion_m: 0.0,
            first_in_band_s: first_in_band,
            time_in_band_after_entry,
            settle_held_s: settle_held_s(records, target, SETTLE_HOLD_S),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t_s: f64, x1: f64, v1: f64, u: f64, phase: Phase) -> Record {
        Record {
            t_s,
            x: vec![x1, v1, 0.0, 0.0],
            u_t_per_m: u,
            phase,
            d: vec![0.0; 4],
        }
    }

    const TARGET: [f64; 4] = [0.02, 0.0, 0.0, 0.0];

    #[test]
    fn settle_time_is_after_the_last_excursion() {
        // Enters the band at 0.2, leaves it at 0.3 (1.5 mm off), back at 0.4.
        let xs = [0.0, 0.01, 0.0195, 0.0205, 0.0215, 0.0201, 0.02];
        let records: Vec<Record> = xs
            .iter()
            .enumerate()
            .map(|(k, &x)| row(0.1 * k as f64, x, 0.0, 0.0, Phase::Track))
            .collect();
        let m = Metrics::compute(&records, &TARGET, 0.1, 0.5, 0).unwrap();
        assert_eq!(m.settle_time_s, Some(0.5));
        assert!((m.final_position_error_m - 0.0).abs() < 1e-15);
    }

    #[test]
    fn time_in_band_counts_from_the_first_entry() {
        // Out until 0.2, in 0.2-0.3, out 0.3-0.4 (1.5 mm off), in from 0.4.
        let xs = [0.0, 0.01, 0.0195, 0.0215, 0.0201, 0.02, 0.02];
        let records: Vec<Record> = xs
            .iter()
            .enumerate()
            .map(|(k, &x)| row(0.1 * k as f64, x, 0.0, 0.0, Phase::Track))
            .collect();
        let m = Metrics::compute(&records, &TARGET, 0.1, 0.5, 0).unwrap();
        assert_eq!(m.first_in_band_s, Some(0.2));
        // 0.2 .. 0.6: 0.4 s, of which 0.1 s out.
        let f = m.time_in_band_after_entry.unwrap();
        assert!((f - 0.75).abs() < 1e-12, "{f}");
        // A window clips rows: 0.25 .. 0.45 is half out.
        let w = time_in_band_fraction(&records, &TARGET, 0.25, 0.45).unwrap();
        assert!((w - 0.5).abs() < 1e-12, "{w}");
        assert_eq!(time_in_band_fraction(&records, &TARGET, 0.7, 0.8), None);
        // Never in the band: no entry, no fraction.
        let far = vec![
            row(0.0, 0.0, 0.0, 0.0, Phase::Track),
            row(0.1, 0.0, 0.0, 0.0, Phase::Track),
        ];
        let m = Metrics::compute(&far, &TARGET, 0.1, 0.5, 0).unwrap();
        assert_eq!(
            (m.first_in_band_s, m.time_in_band_after_entry),
            (None, None)
        );
    }

    #[test]
    fn speed_keeps_a_run_unsettled() {
        // In position all along but moving at 6 mm/s at the end: never settled.
        let records = vec![
            row(0.0, 0.02, 0.0, 0.0, Phase::Track),
            row(0.1, 0.02, 0.006, 0.0, Phase::Track),
        ];
        let m = Metrics::compute(&records, &TARGET, 0.1, 0.5, 0).unwrap();
        assert_eq!(m.settle_time_s, None);
        let json = serde_json::to_value(&m).unwrap();
        assert!(json["settle_time_s"].is_null());
    }

    #[test]
    fn settled_from_the_start() {
        let records = vec![
            row(0.0, 0.0205, 0.001, 0.0, Phase::Track),
            row(0.1, 0.02, 0.0, 0.0, Phase::Track),
        ];
        let m = Metrics::compute(&records, &TARGET, 0.1, 0.5, 0).unwrap();
        assert_eq!(m.settle_time_s, Some(0.0));
    }

    #[test]
    fn duty_cycle_is_time_weighted_and_bounds_are_counted() {
        let records = vec![
            row(0.0, 0.0, 0.0, 0.04, Phase::Actuate),
            row(0.03, 0.0, 0.6, 0.0, Phase::Track), // speed above the 0.5 bound
            row(0.05, -0.09, 0.0, -0.03, Phase::Actuate), // 0.11 m from target
            row(0.06, 0.02, 0.0, 0.0, Phase::Track),
        ];
        let m = Metrics::compute(&records, &TARGET, 0.1, 0.5, 1234).unwrap();
        assert!(
            (m.duty_cycle - 0.04 / 0.06).abs() < 1e-12,
            "{}",
            m.duty_cycle
        );
        assert_eq!(m.state_bound_violations, 2);
        assert!((m.max_abs_u - 0.04).abs() < 1e-15);
        assert_eq!(m.max_step_compute_ns, 1234);
        let json = serde_json::to_value(&m).unwrap();
        let keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        for k in [
            "settle_time_s",
            "final_position_error_m",
            "max_abs_u",
            "duty_cycle",
            "duty_cycle_until_settled",
            "state_bound_violations",
            "max_step_compute_ns",
            "min_time_bound_s",
            "settle_over_bound",
            "workspace_excursion_m",
            "first_in_band_s",
            "time_in_band_after_entry",
            "settle_held_s",
            "held_settle_over_bound",
            "schedule_min_time_s",
            "settle_over_schedule_bound",
        ] {
            assert!(keys.contains(&k), "{k}");
        }
        assert_eq!(keys.len(), 16);
    }

    #[test]
    fn mismatched_target_is_an_error() {
        let records = vec![row(0.0, 0.0, 0.0, 0.0, Phase::Track)];
        assert!(Metrics::compute(&records, &[0.0, 0.0], 0.1, 0.5, 0).is_err());
        assert!(Metrics::compute(&records, &[0.0; 3], 0.1, 0.5, 0).is_err());
    }
}
