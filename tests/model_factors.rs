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
