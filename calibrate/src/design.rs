//! The excitation: a gradient sequence from rest, played on the configured
//! scanner cycle (one sample per actuation phase, then a tracking phase),
//! that identifies both constants of every capsule: fast push-pull blocks
//! at full gradient (speeds where drag dominates: the drag) and slow blocks
//! at a quarter of it (speeds where drag is small: the gain), both signs,
//! each block returning near where it started. The block length is the
//! longest that keeps every capsule, on the model, within the allowed
//! excursion and speed.

use crate::fit::simulate_capsule;
use crate::log::TrackingLog;
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::Model;

/// Gradient of the slow blocks as a fraction of the largest.
pub const SLOW_FRACTION: f64 = 0.25;
/// Samples of rest after each block (the capsules coast to near rest).
pub const REST_SAMPLES: usize = 6;
/// Longest push of a block, samples.
pub const MAX_PUSH_SAMPLES: usize = 8;
/// Largest excursion from the start, as a fraction of half the workspace.
pub const MAX_EXCURSION_FRACTION: f64 = 0.5;

/// A designed excitation: the log to play (positions empty: the scanner
/// measures them at every tracking row) and what the model predicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Excitation {
    pub log: TrackingLog,
    /// Rows that start an actuation sample (the others start a tracking phase).
    pub actuation_rows: Vec<usize>,
    /// Per capsule, the model's positions at every row (from rest at 0), m.
    pub predicted_m: Vec<Vec<f64>>,
    /// Samples per push of the fast blocks.
    pub push_samples: usize,
    pub sample_time_s: f64,
    pub tracking_s: f64,
}

impl Excitation {
    /// Largest |position| over capsules and rows, m.
    pub fn max_excursion_m(&self) -> f64 {
        self.predicted_m
            .iter()
            .flatten()
            .fold(0.0, |a, &x| a.max(x.abs()))
    }

    /// Largest distance of a capsule from its start at the end, m.
    pub fn end_offset_m(&self) -> f64 {
        self.predicted_m
            .iter()
            .filter_map(|x| x.last())
            .fold(0.0, |a, &x| a.max(x.abs()))
    }
}

/// One sample's gradient per cycle: blocks of (+A n, -A 2n, +A n) at full
/// gradient and at `SLOW_FRACTION` of it (twice as long), alternating the
/// starting sign, with rests between.
fn pattern(cycles: usize, n: usize, u_max: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(cycles);
    let mut block = 0usize;
    while out.len() < cycles {
        let (amp, len) = if block.is_multiple_of(2) {
            (u_max, n)
        } else {
            (SLOW_FRACTION * u_max, 2 * n)
        };
        let sign = if (block / 2).is_multiple_of(2) {
            1.0
        } else {
            -1.0
        };
        for (k, s) in [(len, 1.0), (2 * len, -1.0), (len, 1.0)] {
            out.extend(std::iter::repeat_n(sign * s * amp, k));
        }
        out.extend(std::iter::repeat_n(0.0, REST_SAMPLES));
        block += 1;
    }
    out.truncate(cycles);
    out
}

fn build(config: &Config, model: &Model, duration_s: f64, n: usize) -> Excitation {
    let dt = config.controller.sample_time_s;
    let gap = config.scanner.tracking_time_s + config.scanner.extra_delay_s;
    let period = dt + gap;
    let cycles = (duration_s / period).floor().max(1.0) as usize;
    let u = pattern(cycles, n, model.u_max_t_per_m);
    let m = model.capsule_count();
    let mut log = TrackingLog {
        t_s: Vec::new(),
        gradient_t_per_m: Vec::new(),
        positions_m: Vec::new(),
    };
    let mut actuation_rows = Vec::new();
    for (k, &uk) in u.iter().enumerate() {
        let t = k as f64 * period;
        // Tracking phase (u = 0) measured at its start, then one sample.
        log.t_s.push(t);
        log.gradient_t_per_m.push(0.0);
        log.positions_m.push(vec![None; m]);
        actuation_rows.push(log.t_s.len());
        log.t_s.push(t + gap);
        log.gradient_t_per_m.push(uk);
        log.positions_m.push(vec![None; m]);
    }
    // A last tracking row measures where the sequence ends.
    log.t_s.push(cycles as f64 * period);
    log.gradient_t_per_m.push(0.0);
    log.positions_m.push(vec![None; m]);
    let predicted_m = model
        .capsules
        .iter()
        .map(|c| simulate_capsule(&log, c.g, &c.drag, 0.0, 0.0, 1.0e-3))
        .collect();
    Excitation {
        log,
        actuation_rows,
        predicted_m,
        push_samples: n,
        sample_time_s: dt,
        tracking_s: gap,
    }
}

/// The excitation of `duration_s` for `config` (see the module docs);
/// refused when even one-sample pushes leave the allowed excursion.
pub fn design_excitation(config: &Config, duration_s: f64) -> Result<Excitation, String> {
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 600.0) {
        return Err(format!("duration {duration_s} s must be in (0, 600] s"));
    }
    let model = Model::from_config(config);
    let half_span = 0.5 * config.workspace.span_m();
    let max_excursion = MAX_EXCURSION_FRACTION * half_span;
    let speed_bound = config.controller.speed_bound_m_per_s;
    for n in (1..=MAX_PUSH_SAMPLES).rev() {
        let e = build(config, &model, duration_s, n);
        if e.max_excursion_m() <= max_excursion && max_speed(&e) <= speed_bound {
            return Ok(e);
        }
    }
    Err(format!(
        "no excitation keeps the capsules within {max_excursion} m of their start (half of the workspace's half-span)"
    ))
}

/// Largest speed of any capsule on the model along the excitation (by
/// differences of the predicted positions over each sample), m/s.
fn max_speed(e: &Excitation) -> f64 {
    e.predicted_m
        .iter()
        .flat_map(|x| {
            x.windows(2)
                .zip(e.log.t_s.windows(2))
                .map(|(p, t)| ((p[1] - p[0]) / (t[1] - t[0])).abs())
                .collect::<Vec<_>>()
        })
        .fold(0.0, f64::max)
}
