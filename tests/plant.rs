//! The plant against closed forms and its seeding/disturbance contracts.

use capsule_mpc_generator::config::{
    Config, CostUnits, DisturbanceConfig, DisturbanceKind, DragLaw,
};
use capsule_mpc_generator::model::{Drag, Model};
use capsule_mpc_sim::plant::{DisturbanceLevel, Phase, Plant};

fn quadratic_model() -> Model {
    let config = Config::embedded_default();
    assert_eq!(config.drag.law, DragLaw::Quadratic);
    Model::from_config(&config)
}

fn b_of(model: &Model, i: usize) -> f64 {
    match model.capsules[i].drag {
        Drag::Quadratic { b_per_m } => b_per_m,
        other => panic!("expected the quadratic law, got {other:?}"),
    }
}

/// v' = -b v|v| from v0: v = v0 / (1 + b|v0| t), x = x0 + sign(v0) ln(1 + b|v0| t) / b.
fn check_free_coast(v0: f64) {
    let model = quadratic_model();
    let x0 = [0.01, -0.02];
    let state0 = vec![x0[0], v0, x0[1], v0];
    let mut plant =
        Plant::new(model.clone(), state0, DisturbanceConfig::default(), 0.0, 1).unwrap();
    for _ in 0..50 {
        plant.advance(0.02, 0.0, Phase::Track).unwrap();
    }
    assert!((plant.time_s() - 1.0).abs() < 1e-12);
    let records = plant.records();
    assert_eq!(records.len(), 1001);
    for r in records {
        for (i, &x0_i) in x0.iter().enumerate() {
            let b = b_of(&model, i);
            let s = 1.0 + b * v0.abs() * r.t_s;
            let v = v0 / s;
            let x = x0_i + v0.signum() * s.ln() / b;
            let (xs, vs) = (r.x[2 * i], r.x[2 * i + 1]);
            assert!(
                (vs - v).abs() <= 1e-6 * v.abs(),
                "capsule {i} t {} v {vs} vs {v}",
                r.t_s
            );
            let dx = x - x0_i;
            assert!(
                (xs - x).abs() <= 1e-6 * dx.abs() + 1e-15,
                "capsule {i} t {} x {xs} vs {x}",
                r.t_s
            );
        }
    }
}

#[test]
fn free_coast_matches_closed_form_forward() {
    check_free_coast(0.1);
}

#[test]
fn free_coast_matches_closed_form_backward() {
    check_free_coast(-0.1);
}

fn run(seed: u64, kind: DisturbanceKind) -> (Vec<capsule_mpc_sim::plant::Record>, Vec<Vec<f64>>) {
    let model = quadratic_model();
    let disturbance = DisturbanceConfig {
        bound: 0.3,
        units: CostUnits::Si,
        kind,
        seed: 5,
    };
    let mut plant = Plant::new(model, vec![0.0; 4], disturbance, 2e-4, seed).unwrap();
    let mut measurements = Vec::new();
    for k in 0..20 {
        let u = if k % 2 == 0 { 0.04 } else { -0.02 };
        plant.advance(0.0137, u, Phase::Actuate).unwrap();
        plant.advance(0.017, 0.0, Phase::Track).unwrap();
        measurements.push(plant.measure_positions());
    }
    (plant.records().to_vec(), measurements)
}

#[test]
fn same_seed_same_run_different_seed_different_run() {
    for kind in [DisturbanceKind::Random, DisturbanceKind::Constant] {
        let a = run(11, kind);
        let b = run(11, kind);
        let c = run(12, kind);
        assert_eq!(a, b, "{kind:?}");
        assert_ne!(a.0, c.0, "{kind:?}: records should depend on the seed");
        assert_ne!(a.1, c.1, "{kind:?}: measurements should depend on the seed");
    }
}

#[test]
fn disturbance_norm_never_exceeds_the_bound() {
    let (records, _) = run(3, DisturbanceKind::Random);
    let mut largest = 0.0_f64;
    let mut distinct = std::collections::HashSet::new();
    for r in &records {
        let norm = r.d.iter().map(|e| e * e).sum::<f64>().sqrt();
        assert!(
            norm <= 0.3 * (1.0 + 1e-12),
            "||d|| = {norm} at t = {}",
            r.t_s
        );
        largest = largest.max(norm);
        distinct.insert(r.d.iter().map(|e| e.to_bits()).collect::<Vec<_>>());
    }
    // Uniform in a 4-ball: the largest of ~30 draws is close to the bound.
    assert!(largest > 0.2, "largest ||d|| = {largest}");
    // Redrawn every 20 ms over 0.614 s: about 31 values.
    assert!(
        (25..=40).contains(&distinct.len()),
        "{} distinct values",
        distinct.len()
    );
}

#[test]
fn named_levels_respect_their_bounds() {
    let model = quadratic_model();
    for (level, bound) in [
        (DisturbanceLevel::None, 0.0),
        (DisturbanceLevel::Paper, 5e-4),
        (DisturbanceLevel::Stress, 0.05 * 173.25 * 0.04),
    ] {
        let cfg = level.config(&model, 7);
        assert!(
            (cfg.bound_si() - bound).abs() <= 1e-3 * bound.max(1e-12),
            "{level:?}"
        );
        let mut plant = Plant::new(model.clone(), vec![0.0; 4], cfg, 0.0, 7).unwrap();
        plant.advance(0.5, 0.01, Phase::Actuate).unwrap();
        for r in plant.records() {
            let norm = r.d.iter().map(|e| e * e).sum::<f64>().sqrt();
            assert!(norm <= bound * (1.0 + 1e-9) + 1e-15, "{level:?}: {norm}");
        }
    }
}

#[test]
fn noise_free_measurement_is_the_true_position() {
    let model = quadratic_model();
    let mut plant = Plant::new(
        model,
        vec![0.01, 0.0, -0.02, 0.0],
        DisturbanceConfig::default(),
        0.0,
        1,
    )
    .unwrap();
    plant.advance(0.1, 0.04, Phase::Actuate).unwrap();
    let p = plant.measure_positions();
    assert_eq!(p, vec![plant.state()[0], plant.state()[2]]);
}
