//! The timer and the statistics of the timings: one call timed alone with
//! `Instant`, nearest-rank percentiles, the thread pinned to one core.

use serde_json::{json, Value};
use std::hint::black_box;
use std::time::Instant;

#[inline(always)]
pub(crate) fn timed<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let t0 = Instant::now();
    let r = black_box(f());
    let ns = t0.elapsed().as_nanos() as u64;
    (r, ns)
}

/// Median, p99, p99.9 and max of `v` (nearest rank), ns.
#[derive(Debug, Clone, Copy, Default)]
pub struct Percentiles {
    pub median: u64,
    pub p99: u64,
    pub p999: u64,
    pub max: u64,
}

impl Percentiles {
    pub fn of(values: &[u64]) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        let mut v = values.to_vec();
        v.sort_unstable();
        let rank = |q: f64| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
        Percentiles {
            median: rank(0.5),
            p99: rank(0.99),
            p999: rank(0.999),
            max: v[v.len() - 1],
        }
    }

    pub fn json(&self) -> Value {
        json!({"median": self.median, "p99": self.p99, "p999": self.p999, "max": self.max})
    }
}

pub(crate) fn fmt_us(ns: u64) -> String {
    format!("{:.2} us", ns as f64 / 1e3)
}

/// The timing table: a header, then one row per (name, percentiles).
pub(crate) fn print_rows(
    rows: impl IntoIterator<Item = (String, Percentiles)>,
) -> std::io::Result<()> {
    crate::out!(
        "{:<34} {:>11} {:>11} {:>11} {:>11}",
        "single shot",
        "median",
        "p99",
        "p99.9",
        "max"
    )?;
    for (name, p) in rows {
        crate::out!(
            "{name:<34} {:>11} {:>11} {:>11} {:>11}",
            fmt_us(p.median),
            fmt_us(p.p99),
            fmt_us(p.p999),
            fmt_us(p.max)
        )?;
    }
    Ok(())
}

/// Pins the calling thread to the last core (best effort); returns its id.
pub(crate) fn pin_to_one_core() -> Option<usize> {
    let ids = core_affinity::get_core_ids()?;
    let id = *ids.last()?;
    core_affinity::set_for_current(id).then_some(id.id)
}

/// Median cost of an empty `Instant` measurement, ns.
pub(crate) fn timer_overhead_ns() -> u64 {
    let v: Vec<u64> = (0..10_000).map(|_| timed(|| ()).1).collect();
    Percentiles::of(&v).median
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_nearest_rank() {
        let v: Vec<u64> = (1..=1000).collect();
        let p = Percentiles::of(&v);
        assert_eq!((p.median, p.p99, p.p999, p.max), (500, 990, 999, 1000));
    }
}
