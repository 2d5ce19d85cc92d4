//! The simulated plant: the true nonlinear capsule dynamics, a bounded additive
//! disturbance and noisy position measurements.
//!
//! It is kept separate from every controller model on purpose: controllers see
//! the plant only through [`Plant::measure_positions`] and the gradient they
//! apply, so a modelling shortcut in a controller cannot leak into the "truth".
//! Integration is classical RK4 with a fixed internal step of at most
//! [`DEFAULT_MAX_STEP_S`]; every internal step appends one [`Record`] row.

use anyhow::{bail, Result};
use capsule_mpc_generator::config::{CostUnits, DisturbanceConfig, DisturbanceKind};
use capsule_mpc_generator::model::Model;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Default internal RK4 step, s: 1 ms is far below the fastest drag time
/// constant (1 / (2 b v) ~ 15 ms at 0.25 m/s for the small capsule).
pub const DEFAULT_MAX_STEP_S: f64 = 1e-3;

/// Default period after which a `random` disturbance is redrawn, s (one
/// scanner sample).
pub const DEFAULT_REDRAW_PERIOD_S: f64 = 0.02;

/// Sinusoids per component of a `drift` disturbance.
pub const DRIFT_TERMS: usize = 3;
/// Shortest and longest period of a `drift` sinusoid, s.
pub const DRIFT_PERIOD_RANGE_S: (f64, f64) = (1.0, 5.0);

/// The paper's disturbance bound, read as cm/s and cm/s^2.
pub const PAPER_DISTURBANCE_BOUND_CM: f64 = 0.05;

/// Stress disturbance as a fraction of the first capsule's full magnetic
/// acceleration g_1 u_max.
pub const STRESS_DISTURBANCE_FRACTION: f64 = 0.05;

/// What the scanner is doing during a record row: tracking (measuring, u ~ 0)
/// or actuating (applying the gradient).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Phase {
    Track,
    Actuate,
}

/// Named disturbance levels for the CLI and scripts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DisturbanceLevel {
    /// No disturbance.
    None,
    /// The paper's ||d|| <= 0.05 (cm units), random.
    Paper,
    /// 5 % of the first capsule's full magnetic acceleration, random.
    Stress,
}

impl DisturbanceLevel {
    /// Parses "none" | "paper" | "stress" (case-insensitive).
    pub fn from_name(name: &str) -> Result<DisturbanceLevel> {
        match name.to_ascii_lowercase().as_str() {
            "none" => Ok(DisturbanceLevel::None),
            "paper" => Ok(DisturbanceLevel::Paper),
            "stress" => Ok(DisturbanceLevel::Stress),
            other => bail!("unknown disturbance level `{other}` (expected none, paper or stress)"),
        }
    }

    /// The disturbance config for this level with another model (`kind`)
    /// of the same size: `None` stays no disturbance whatever `kind` is.
    pub fn config_of_kind(
        self,
        model: &Model,
        seed: u64,
        kind: DisturbanceKind,
    ) -> DisturbanceConfig {
        let mut c = self.config(model, seed);
        if self != DisturbanceLevel::None {
            c.kind = kind;
        }
        c
    }

    /// The disturbance config for this level; `seed` is stored in the config.
    pub fn config(self, model: &Model, seed: u64) -> DisturbanceConfig {
        match self {
            DisturbanceLevel::None => DisturbanceConfig {
                bound: 0.0,
                units: CostUnits::Si,
                kind: DisturbanceKind::None,
                seed,
            },
            DisturbanceLevel::Paper => DisturbanceConfig {
                bound: PAPER_DISTURBANCE_BOUND_CM,
                units: CostUnits::Cm,
                kind: DisturbanceKind::Random,
                seed,
            },
            DisturbanceLevel::Stress => {
                let g1 = model.capsules.first().map_or(0.0, |c| c.g);
                DisturbanceConfig {
                    bound: STRESS_DISTURBANCE_FRACTION * g1 * model.u_max_t_per_m,
                    units: CostUnits::Si,
                    kind: DisturbanceKind::Random,
                    seed,
                }
            }
        }
    }
}

/// Parses a disturbance model: "random" | "drift" | "constant" | "none"
/// (case-insensitive).
pub fn disturbance_kind_from_name(name: &str) -> Result<DisturbanceKind> {
    match name.to_ascii_lowercase().as_str() {
        "none" => Ok(DisturbanceKind::None),
        "random" => Ok(DisturbanceKind::Random),
        "drift" => Ok(DisturbanceKind::Drift),
        "constant" => Ok(DisturbanceKind::Constant),
        other => {
            bail!("unknown disturbance model `{other}` (expected random, drift, constant or none)")
        }
    }
}

/// Lower-case name of a disturbance model (as [`disturbance_kind_from_name`] reads it).
pub fn disturbance_kind_name(kind: DisturbanceKind) -> &'static str {
    match kind {
        DisturbanceKind::None => "none",
        DisturbanceKind::Random => "random",
        DisturbanceKind::Drift => "drift",
        DisturbanceKind::Constant => "constant",
    }
}

/// Shorthand for [`DisturbanceLevel::from_name`] + [`DisturbanceLevel::config`].
pub fn disturbance_for_level(name: &str, model: &Model, seed: u64) -> Result<DisturbanceConfig> {
    Ok(DisturbanceLevel::from_name(name)?.config(model, seed))
}

/// One row of the simulation log. The row at time `t_s` holds the input and
/// disturbance applied from `t_s` until the next row; the last row is the
/// current state (zero duration).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub t_s: f64,
    /// True state [x1, v1, x2, v2, ...], m and m/s.
    pub x: Vec<f64>,
    pub u_t_per_m: f64,
    pub phase: Phase,
    /// Disturbance added to the state derivative (SI).
    pub d: Vec<f64>,
}

/// Seeded disturbance generator d(t).
#[derive(Debug, Clone)]
struct Disturbance {
    kind: DisturbanceKind,
    bound_si: f64,
    redraw_period_s: f64,
    rng: ChaCha8Rng,
    /// Index of the redraw interval `current` belongs to (random kind).
    interval: Option<u64>,
    current: Vec<f64>,
    /// Drift kind: per component, [`DRIFT_TERMS`] (weight, angular
    /// frequency rad/s, phase rad); the weights of a component sum to 1.
    drift: Vec<[(f64, f64, f64); DRIFT_TERMS]>,
}

impl Disturbance {
    fn new(config: &DisturbanceConfig, n: usize, seed: u64) -> Disturbance {
        // Both the run seed and the config's seed matter; a separate stream
        // keeps the disturbance independent of how often positions are measured.
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ config.seed.rotate_left(32));
        rng.set_stream(1);
        let bound_si = config.bound_si();
        let mut current = vec![0.0; n];
        if config.kind == DisturbanceKind::Constant && bound_si > 0.0 {
            let dir = unit_vector(&mut rng, n);
            for (c, e) in current.iter_mut().zip(dir) {
                *c = bound_si * e;
            }
        }
        let drift = if config.kind == DisturbanceKind::Drift && bound_si > 0.0 {
            (0..n).map(|_| drift_terms(&mut rng)).collect()
        } else {
            Vec::new()
        };
        Disturbance {
            kind: config.kind,
            bound_si,
            redraw_period_s: DEFAULT_REDRAW_PERIOD_S,
            rng,
            interval: None,
            current,
            drift,
        }
    }

    /// d at time `t_s` (piecewise constant; time only moves forward).
    fn at(&mut self, t_s: f64) -> &[f64] {
        if self.kind == DisturbanceKind::Random && self.bound_si > 0.0 {
            // The small slack puts a row that lands on a redraw instant (up to
            // rounding) into the new interval.
            let k = (t_s / self.redraw_period_s + 1e-9).floor().max(0.0) as u64;
            while !matches!(self.interval, Some(i) if i >= k) {
                self.interval = Some(self.interval.map_or(0, |i| i + 1));
                self.current = uniform_in_ball(&mut self.rng, self.current.len(), self.bound_si);
            }
        }
        if !self.drift.is_empty() {
            // Each component lies in [-1, 1]; the vector is pulled back onto
            // the unit ball when it leaves it, then scaled by the bound.
            for (c, terms) in self.current.iter_mut().zip(&self.drift) {
                *c = terms
                    .iter()
                    .map(|(w, om, ph)| w * (om * t_s + ph).sin())
                    .sum();
            }
            let norm = self.current.iter().map(|e| e * e).sum::<f64>().sqrt();
            let scale = self.bound_si / norm.max(1.0);
            for c in &mut self.current {
                *c *= scale;
            }
        }
        &self.current
    }
}

/// One component of a drift disturbance: [`DRIFT_TERMS`] sinusoids with
/// periods uniform in [`DRIFT_PERIOD_RANGE_S`], random phases and random
/// weights summing to 1.
fn drift_terms(rng: &mut ChaCha8Rng) -> [(f64, f64, f64); DRIFT_TERMS] {
    let (lo, hi) = DRIFT_PERIOD_RANGE_S;
    let mut terms = [(0.0, 0.0, 0.0); DRIFT_TERMS];
    for t in &mut terms {
        let period = lo + (hi - lo) * rng.gen::<f64>();
        *t = (
            0.5 + rng.gen::<f64>(),
            std::f64::consts::TAU / period,
            std::f64::consts::TAU * rng.gen::<f64>(),
        );
    }
    let total: f64 = terms.iter().map(|t| t.0).sum();
    for t in &mut terms {
        t.0 /= total;
    }
    terms
}

/// RK4 stage point: `out = x + scale * k`.
fn stage(out: &mut [f64], x: &[f64], k: &[f64], scale: f64) {
    for ((o, xi), ki) in out.iter_mut().zip(x).zip(k) {
        *o = xi + scale * ki;
    }
}

/// A uniformly distributed direction in R^n (normalized Gaussian vector).
fn unit_vector(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    loop {
        let v: Vec<f64> = (0..n)
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect();
        let norm = v.iter().map(|e| e * e).sum::<f64>().sqrt();
        if norm > 1e-12 {
            return v.into_iter().map(|e| e / norm).collect();
        }
    }
}

/// A point uniformly distributed in the n-ball of radius `radius`.
fn uniform_in_ball(rng: &mut ChaCha8Rng, n: usize, radius: f64) -> Vec<f64> {
    let dir = unit_vector(rng, n);
    let r = radius * rng.gen::<f64>().powf(1.0 / n as f64);
    dir.into_iter()
        .map(|e| (r * e).min(radius).max(-radius))
        .collect()
}

/// The simulated plant.
#[derive(Debug, Clone)]
pub struct Plant {
    model: Model,
    x: Vec<f64>,
    t_s: f64,
    max_step_s: f64,
    position_noise_m: f64,
    noise_rng: ChaCha8Rng,
    disturbance: Disturbance,
    records: Vec<Record>,
    // RK4 scratch, so that a step does not allocate.
    k: [Vec<f64>; 4],
    tmp: Vec<f64>,
}

impl Plant {
    /// A plant at time 0 in state `x0` (length 2M). Errors on a wrong state
    /// length, a non-finite state or a negative/non-finite noise level.
    pub fn new(
        model: Model,
        x0: Vec<f64>,
        disturbance: DisturbanceConfig,
        position_noise_m: f64,
        seed: u64,
    ) -> Result<Plant> {
        let n = model.state_count();
        if x0.len() != n {
            bail!(
                "initial state has {} entries; the model has {n} states",
                x0.len()
            );
        }
        if x0.iter().any(|e| !e.is_finite()) {
            bail!("initial state {x0:?} is not finite");
        }
        if !(position_noise_m.is_finite() && position_noise_m >= 0.0) {
            bail!("position noise {position_noise_m} m must be finite and >= 0");
        }
        if !(disturbance.bound_si().is_finite() && disturbance.bound_si() >= 0.0) {
            bail!(
                "disturbance bound {} must be finite and >= 0",
                disturbance.bound
            );
        }
        let mut noise_rng = ChaCha8Rng::seed_from_u64(seed);
        noise_rng.set_stream(2);
        let mut disturbance = Disturbance::new(&disturbance, n, seed);
        let d0 = disturbance.at(0.0).to_vec();
        let records = vec![Record {
            t_s: 0.0,
            x: x0.clone(),
            u_t_per_m: 0.0,
            phase: Phase::Track,
            d: d0,
        }];
        Ok(Plant {
            model,
            x: x0,
            t_s: 0.0,
            max_step_s: DEFAULT_MAX_STEP_S,
            position_noise_m,
            noise_rng,
            disturbance,
            records,
            k: [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            tmp: vec![0.0; n],
        })
    }

    /// Sets the largest internal RK4 step (must be positive and finite).
    pub fn with_max_step_s(mut self, max_step_s: f64) -> Result<Plant> {
        if !(max_step_s.is_finite() && max_step_s > 0.0) {
            bail!("max_step_s = {max_step_s} must be positive and finite");
        }
        self.max_step_s = max_step_s;
        Ok(self)
    }

    /// Sets how often a `random` disturbance is redrawn (before the first
    /// `advance`; must be positive and finite).
    pub fn with_redraw_period_s(mut self, redraw_period_s: f64) -> Result<Plant> {
        if !(redraw_period_s.is_finite() && redraw_period_s > 0.0) {
            bail!("redraw_period_s = {redraw_period_s} must be positive and finite");
        }
        self.disturbance.redraw_period_s = redraw_period_s;
        self.disturbance.interval = None;
        let d0 = self.disturbance.at(self.t_s).to_vec();
        if let Some(last) = self.records.last_mut() {
            last.d = d0;
        }
        Ok(self)
    }

    /// Advances by `duration_s` with the gradient `u_t_per_m` held constant,
    /// in ceil(duration / max_step) equal RK4 sub-steps so that the end time
    /// lands exactly on a record row. The input is applied as given (no
    /// saturation) so that metrics reveal a controller exceeding u_max.
    /// A zero duration only relabels the current row's input and phase.
    pub fn advance(&mut self, duration_s: f64, u_t_per_m: f64, phase: Phase) -> Result<()> {
        if !(duration_s.is_finite() && duration_s >= 0.0) {
            bail!("advance: duration {duration_s} s must be finite and >= 0");
        }
        if !u_t_per_m.is_finite() {
            bail!("advance: gradient {u_t_per_m} T/m is not finite");
        }
        // The last row is the current state; it now starts this segment.
        if let Some(last) = self.records.last_mut() {
            last.u_t_per_m = u_t_per_m;
            last.phase = phase;
        }
        if duration_s == 0.0 {
            return Ok(());
        }
        let steps = (duration_s / self.max_step_s).ceil().max(1.0) as usize;
        let h = duration_s / steps as f64;
        let t0 = self.t_s;
        for s in 0..steps {
            let t = t0 + s as f64 * h;
            let d = self.disturbance.at(t).to_vec();
            if s > 0 {
                // Start-of-substep row (the first one is the current last row).
                self.records.push(Record {
                    t_s: t,
                    x: self.x.clone(),
                    u_t_per_m,
                    phase,
                    d: d.clone(),
                });
            } else if let Some(last) = self.records.last_mut() {
                last.d.clone_from(&d);
            }
            self.rk4_step(h, u_t_per_m, &d);
        }
        self.t_s = t0 + duration_s;
        let d_end = self.disturbance.at(self.t_s).to_vec();
        self.records.push(Record {
            t_s: self.t_s,
            x: self.x.clone(),
            u_t_per_m,
            phase,
            d: d_end,
        });
        Ok(())
    }

    /// One classical RK4 step with u and d held constant.
    fn rk4_step(&mut self, h: f64, u: f64, d: &[f64]) {
        let [k1, k2, k3, k4] = &mut self.k;
        let tmp = &mut self.tmp;
        let x = &mut self.x;
        let model = &self.model;
        model.derivative(x, u, d, k1);
        stage(tmp, x, k1, 0.5 * h);
        model.derivative(tmp, u, d, k2);
        stage(tmp, x, k2, 0.5 * h);
        model.derivative(tmp, u, d, k3);
        stage(tmp, x, k3, h);
        model.derivative(tmp, u, d, k4);
        for ((((xi, a), b), c), e) in x
            .iter_mut()
            .zip(k1.iter())
            .zip(k2.iter())
            .zip(k3.iter())
            .zip(k4.iter())
        {
            *xi += h / 6.0 * (a + 2.0 * b + 2.0 * c + e);
        }
    }

    /// Current true positions plus seeded Gaussian noise (sigma =
    /// `position_noise_m`); what the scanner's tracking returns.
    pub fn measure_positions(&mut self) -> Vec<f64> {
        let sigma = self.position_noise_m;
        let positions: Vec<f64> = self.x.iter().step_by(2).copied().collect();
        positions
            .into_iter()
            .map(|p| {
                if sigma > 0.0 {
                    p + sigma * self.noise_rng.sample::<f64, _>(StandardNormal)
                } else {
                    p
                }
            })
            .collect()
    }

    /// Current true state [x1, v1, x2, v2, ...].
    pub fn state(&self) -> &[f64] {
        &self.x
    }

    /// Current simulation time, s.
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// All rows so far; the last one is the current state.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// Consumes the plant and returns its rows.
    pub fn into_records(self) -> Vec<Record> {
        self.records
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn max_step_s(&self) -> f64 {
        self.max_step_s
    }

    pub fn position_noise_m(&self) -> f64 {
        self.position_noise_m
    }

    /// The disturbance bound in SI units (0 for none).
    pub fn disturbance_bound_si(&self) -> f64 {
        match self.disturbance.kind {
            DisturbanceKind::None => 0.0,
            _ => self.disturbance.bound_si,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use capsule_mpc_generator::config::Config;

    fn model() -> Model {
        Model::from_config(&Config::embedded_default())
    }

    #[test]
    fn switching_instants_land_on_rows() {
        let mut p =
            Plant::new(model(), vec![0.0; 4], DisturbanceConfig::default(), 0.0, 1).unwrap();
        p.advance(0.0175, 0.04, Phase::Actuate).unwrap();
        p.advance(0.02, 0.0, Phase::Track).unwrap();
        let r = p.records();
        assert_eq!(r.len(), 18 + 20 + 1);
        assert_eq!(r[18].t_s, 0.0175);
        assert_eq!(r[18].phase, Phase::Track);
        assert_eq!(r[17].phase, Phase::Actuate);
        assert!((p.time_s() - 0.0375).abs() < 1e-15);
        assert_eq!(r.last().unwrap().x, p.state());
    }

    #[test]
    fn constant_disturbance_has_the_bound_as_norm() {
        let m = model();
        let cfg = DisturbanceConfig {
            bound: 0.3,
            units: CostUnits::Si,
            kind: DisturbanceKind::Constant,
            seed: 3,
        };
        let mut p = Plant::new(m, vec![0.0; 4], cfg, 0.0, 9).unwrap();
        p.advance(0.1, 0.0, Phase::Track).unwrap();
        let d0 = p.records()[0].d.clone();
        for r in p.records() {
            assert_eq!(r.d, d0);
        }
        let norm = d0.iter().map(|e| e * e).sum::<f64>().sqrt();
        assert!((norm - 0.3).abs() < 1e-12, "{norm}");
    }

    #[test]
    fn drift_is_smooth_bounded_and_seeded() {
        let m = model();
        let cfg = DisturbanceLevel::Paper.config_of_kind(&m, 4, DisturbanceKind::Drift);
        let bound = cfg.bound_si();
        let run = |seed: u64| {
            let mut p = Plant::new(m.clone(), vec![0.0; 4], cfg.clone(), 0.0, seed).unwrap();
            p.advance(6.0, 0.0, Phase::Track).unwrap();
            p.into_records()
        };
        let r = run(7);
        assert_eq!(r, run(7));
        assert_ne!(
            r.iter().map(|x| x.d.clone()).collect::<Vec<_>>(),
            run(8).iter().map(|x| x.d.clone()).collect::<Vec<_>>()
        );
        let norms: Vec<f64> = r
            .iter()
            .map(|x| x.d.iter().map(|e| e * e).sum::<f64>().sqrt())
            .collect();
        assert!(norms.iter().all(|&n| n <= bound * (1.0 + 1e-12)));
        // Of the paper's size, not a vanishing drift.
        let mean = norms.iter().sum::<f64>() / norms.len() as f64;
        assert!(mean > 0.4 * bound, "mean ||d|| {mean} of {bound}");
        // Slow: over one 1 ms row no component moves more than
        // bound * 2 pi / 1 s * 1 ms (plus the norm clipping).
        for w in r.windows(2) {
            for (a, b) in w[0].d.iter().zip(&w[1].d) {
                assert!((a - b).abs() <= bound * 0.02, "{a} -> {b}");
            }
        }
    }

    #[test]
    fn kinds_parse_and_the_level_keeps_its_size() {
        let m = model();
        for name in ["random", "drift", "constant", "none"] {
            let k = disturbance_kind_from_name(name).unwrap();
            assert_eq!(disturbance_kind_name(k), name);
        }
        assert!(disturbance_kind_from_name("sine").is_err());
        let c = DisturbanceLevel::Paper.config_of_kind(&m, 1, DisturbanceKind::Constant);
        assert_eq!(c.kind, DisturbanceKind::Constant);
        assert!((c.bound_si() - 5e-4).abs() < 1e-15);
        let n = DisturbanceLevel::None.config_of_kind(&m, 1, DisturbanceKind::Drift);
        assert_eq!(n.kind, DisturbanceKind::None);
    }

    #[test]
    fn levels() {
        let m = model();
        let s = DisturbanceLevel::Stress.config(&m, 1);
        assert!((s.bound_si() - 0.05 * 173.25 * 0.04).abs() < 1e-3);
        let p = disturbance_for_level("paper", &m, 1).unwrap();
        assert!((p.bound_si() - 5e-4).abs() < 1e-15);
        assert!(disturbance_for_level("huge", &m, 1).is_err());
    }

    #[test]
    fn bad_input_is_an_error() {
        let m = model();
        assert!(Plant::new(
            m.clone(),
            vec![0.0; 3],
            DisturbanceConfig::default(),
            0.0,
            1
        )
        .is_err());
        let mut p = Plant::new(m, vec![0.0; 4], DisturbanceConfig::default(), 0.0, 1).unwrap();
        assert!(p.advance(f64::NAN, 0.0, Phase::Track).is_err());
        assert!(p.advance(0.01, f64::INFINITY, Phase::Track).is_err());
    }
}
