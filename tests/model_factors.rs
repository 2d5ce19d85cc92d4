//! `Controller::set_model_factors`: what a calibration says of a capsule's
//! gain and drag, checked (each error names the argument), used by the
//! estimator at once and kept across `reset`.

use capsule_mpc_runtime::{DefaultController, RuntimeError};

fn controller() -> DefaultController {
    DefaultController::new(DefaultController::default_settings(), &[0.0, 0.0]).unwrap()
}

#[test]
fn told_factors_replace_the_estimate_and_survive_reset() {
    let mut c = controller();
    c.set_model_factors(1, [0.9, 1.2], [0.01, 0.02]).unwrap();
    let f = c.model_factors(1).unwrap();
    assert_eq!(f.mean, [0.9, 1.2]);
    assert!((f.cov[0] - 1e-4).abs() < 1e-12 && (f.cov[3] - 4e-4).abs() < 1e-12);
    assert_eq!(c.model_factors(0).unwrap().mean, [1.0, 1.0]);
    c.reset(&[0.01, -0.01]).unwrap();
    assert_eq!(c.model_factors(1).unwrap().mean, [0.9, 1.2]);
}

#[test]
fn bad_factors_are_refused_by_name_and_change_nothing() {
    let mut c = controller();
    let cases: [(usize, [f64; 2], [f64; 2], RuntimeError); 6] = [
        (
            2,
            [1.0, 1.0],
            [0.01, 0.01],
            RuntimeError::BadSetting("capsule"),
        ),
        (
            0,
            [f64::NAN, 1.0],
            [0.01, 0.01],
            RuntimeError::NonFinite("factors"),
        ),
        (
            0,
            [1.0, 1.0],
            [0.01, f64::INFINITY],
            RuntimeError::NonFinite("std_devs"),
        ),
        (
            0,
            [1.0, 0.2],
            [0.01, 0.01],
            RuntimeError::BadSetting("factors"),
        ),
        (
            0,
            [4.5, 1.0],
            [0.01, 0.01],
            RuntimeError::BadSetting("factors"),
        ),
        (
            0,
            [1.0, 1.0],
            [0.0, 0.01],
            RuntimeError::BadSetting("std_devs"),
        ),
    ];
    for (capsule, factors, std_devs, err) in cases {
        assert_eq!(
            c.set_model_factors(capsule, factors, std_devs),
            Err(err),
            "capsule {capsule}, factors {factors:?}, deviations {std_devs:?}"
        );
        assert_eq!(c.model_factors(0).unwrap().mean, [1.0, 1.0]);
    }
}

/// Told before the first cycle, the gain's deviation also sets how sure the
/// estimator is that the capsules start at rest (`INITIAL_SPEED_STD_M_PER_S`
/// under the model's 10 % prior, scaled by the told deviation); once the
/// capsules have moved, told factors leave the speeds' uncertainty alone.
#[test]
fn told_gain_deviation_sets_the_starting_speed_uncertainty() {
    use capsule_mpc_runtime::estimator::INITIAL_SPEED_STD_M_PER_S;
    let speed_std = |c: &DefaultController, i: usize| c.filter(i).unwrap().speed_std_m_per_s();
    let mut c = controller();
    assert_eq!(speed_std(&c, 0), INITIAL_SPEED_STD_M_PER_S);
    c.set_model_factors(0, [1.0, 1.0], [0.01, 0.05]).unwrap();
    assert!((speed_std(&c, 0) - 0.1 * INITIAL_SPEED_STD_M_PER_S).abs() < 1e-12);
    assert_eq!(speed_std(&c, 1), INITIAL_SPEED_STD_M_PER_S);
    // Less sure than the model's prior: no wider than the model's start.
    c.set_model_factors(1, [1.0, 1.0], [0.5, 0.5]).unwrap();
    assert_eq!(speed_std(&c, 1), INITIAL_SPEED_STD_M_PER_S);
    c.set_target(&[0.02, 0.0, 0.01, 0.0]).unwrap();
    c.cycle(Some(&[0.0, 0.0])).unwrap();
    let moving = speed_std(&c, 1);
    c.set_model_factors(1, [1.0, 1.0], [0.01, 0.01]).unwrap();
    assert_eq!(speed_std(&c, 1), moving);
    // A new start at rest takes the known deviation again.
    c.reset(&[0.0, 0.0]).unwrap();
    assert!((speed_std(&c, 1) - 0.1 * INITIAL_SPEED_STD_M_PER_S).abs() < 1e-12);
}
