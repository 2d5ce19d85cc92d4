//! The calibration end to end in the plant simulator: capsules off the
//! model by up to 20 % in gain and drag, the designed 10 s excitation
//! played on the scanner cycle with 0.2 mm tracking noise, the fit; every
//! fitted constant within 2 % of the plant's and its 95 % interval
//! covering it (over several seeds; the worst printed).

use capsule_mpc_calibrate::{
    design_excitation, fit, fitted_config, FitSettings, TrackingLog, TOLD_STD_MIN,
};
use capsule_mpc_generator::config::{Config, DisturbanceConfig};
use capsule_mpc_generator::model::Model;
use capsule_mpc_sim::mismatch::PlantMismatch;
use capsule_mpc_sim::plant::{Phase, Plant};

const NOISE_M: f64 = 2.0e-4;

/// Plays `excitation` on `plant_model` and fills in the measured positions.
fn play(
    excitation: &TrackingLog,
    actuation_rows: &[usize],
    plant_model: Model,
    seed: u64,
) -> TrackingLog {
    let m = plant_model.capsule_count();
    let mut plant = Plant::new(
        plant_model,
        vec![0.0; 2 * m],
        DisturbanceConfig::default(),
        NOISE_M,
        seed,
    )
    .unwrap();
    let mut log = excitation.clone();
    for r in 0..log.t_s.len() {
        let actuating = actuation_rows.contains(&r);
        if !actuating {
            log.positions_m[r] = plant.measure_positions().into_iter().map(Some).collect();
        }
        if r + 1 < log.t_s.len() {
            let dt = log.t_s[r + 1] - log.t_s[r];
            let phase = if actuating {
                Phase::Actuate
            } else {
                Phase::Track
            };
            plant.advance(dt, log.gradient_t_per_m[r], phase).unwrap();
        }
    }
    log
}

#[test]
fn fitted_constants_are_within_2_percent_and_covered() {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let e = design_excitation(&config, 10.0).unwrap();
    eprintln!(
        "excitation: {} rows, pushes of {} samples, largest excursion {:.1} mm, ends {:.1} mm from the start",
        e.log.t_s.len(),
        e.push_samples,
        1e3 * e.max_excursion_m(),
        1e3 * e.end_offset_m()
    );
    let plants = [
        (vec![1.2, 0.8], vec![0.9, 1.1]),
        (vec![0.8], vec![1.2]),
        (vec![1.15, 1.05], vec![0.85, 0.95]),
    ];
    let mut worst: f64 = 0.0;
    let (mut covered, mut intervals) = (0, 0);
    for (drag, gain) in &plants {
        let mismatch = PlantMismatch {
            drag_scale: drag.clone(),
            gain_scale: gain.clone(),
        };
        let plant_model = mismatch.apply(&model).unwrap();
        for seed in 1..=4 {
            let log = play(&e.log, &e.actuation_rows, plant_model.clone(), seed);
            // Through the CSV, as another program would write it.
            let log = TrackingLog::from_csv(&log.to_csv(), 2, 20).unwrap();
            let cal = fit(&log, &config, &FitSettings::default()).unwrap();
            assert!(cal.warnings.is_empty(), "{:?}", cal.warnings);
            assert!(
                cal.residual_rms_m < 1.5 * NOISE_M,
                "residual {}",
                cal.residual_rms_m
            );
            for (i, f) in cal.capsules.iter().enumerate() {
                let truth_g = plant_model.capsules[i].g;
                let truth_b = plant_model.capsules[i].drag.effective_b_per_m(0.1);
                let (eg, eb) = (
                    (f.gain / truth_g - 1.0).abs(),
                    (f.drag / truth_b - 1.0).abs(),
                );
                worst = worst.max(eg).max(eb);
                assert!(
                    eg <= 0.02 && eb <= 0.02,
                    "capsule {i} seed {seed}: gain {eg:.4}, drag {eb:.4} off"
                );
                // The standard errors cover the truth: within 3 of them
                // (the 95 % intervals miss about one in twenty, as they should).
                assert!(
                    (f.gain - truth_g).abs() <= 3.0 * f.gain_stderr,
                    "capsule {i} seed {seed}: gain {} +- {} misses {truth_g}",
                    f.gain,
                    f.gain_stderr
                );
                assert!(
                    (f.drag - truth_b).abs() <= 3.0 * f.drag_stderr,
                    "capsule {i} seed {seed}: drag {} +- {} misses {truth_b}",
                    f.drag,
                    f.drag_stderr
                );
                // What to tell a controller built for the config: the
                // factors over the config's values, their deviations at
                // least 1 % and covering the plant's true factor.
                let model_i = &model.capsules[i];
                let true_factors = [
                    truth_g / model_i.g,
                    truth_b / model_i.drag.effective_b_per_m(0.1),
                ];
                let told = f.told_factors.iter().zip(&f.told_std);
                for (k, ((&told, &std), truth)) in told.zip(true_factors).enumerate() {
                    assert!(
                        (TOLD_STD_MIN..=1.0).contains(&std) && (told - truth).abs() <= std,
                        "capsule {i} seed {seed}, factor {k}: told {told} +- {std}, truth {truth}"
                    );
                }
                covered += (f.gain_ci95[0] <= truth_g && truth_g <= f.gain_ci95[1]) as usize
                    + (f.drag_ci95[0] <= truth_b && truth_b <= f.drag_ci95[1]) as usize;
                intervals += 2;
            }
            // The fitted config derives exactly the fitted constants.
            let fitted = Model::from_config(&fitted_config(&config, &cal));
            for (c, f) in fitted.capsules.iter().zip(&cal.capsules) {
                assert_eq!(c.g, f.gain);
                assert_eq!(c.drag.effective_b_per_m(0.1), f.drag);
            }
        }
    }
    eprintln!(
        "worst relative error of a fitted constant: {:.3} %; 95 % intervals covering the truth: {covered} of {intervals}",
        100.0 * worst
    );
    assert!(
        covered * 10 >= intervals * 8,
        "{covered} of {intervals} intervals cover the truth"
    );
}

/// A log that plays nothing fast identifies no drag: the fit says so.
#[test]
fn a_weak_log_is_flagged() {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let mut e = design_excitation(&config, 3.0).unwrap();
    for u in e.log.gradient_t_per_m.iter_mut() {
        *u *= 0.02;
    }
    let log = play(&e.log, &e.actuation_rows, model, 1);
    let cal = fit(&log, &config, &FitSettings::default()).unwrap();
    assert!(
        cal.warnings.iter().any(|w| w.contains("drag enough")),
        "{:?}",
        cal.warnings
    );
}
