//! Bad arguments and settings, and the invariant |u| <= u_max over every
//! fault at once.

use super::*;

// ---------------------------------------------------------------------------
// Bad arguments.

/// Every call with a bad argument returns a RuntimeError naming it, and
/// changes nothing.
#[test]
fn bad_arguments_are_errors_naming_the_argument_and_change_nothing() {
    let s = settings(Sampling::Constant);
    assert_eq!(
        DefaultController::new(s, &[0.0]).unwrap_err(),
        RuntimeError::WrongLength("positions_m")
    );
    assert_eq!(
        DefaultController::new(s, &[0.0; M + 1]).unwrap_err(),
        RuntimeError::WrongLength("positions_m")
    );
    assert_eq!(
        DefaultController::new(s, &[f64::NAN, 0.0]).unwrap_err(),
        RuntimeError::NonFinite("positions_m")
    );
    assert_eq!(
        DefaultController::new(s, &[0.0, f64::INFINITY]).unwrap_err(),
        RuntimeError::NonFinite("positions_m")
    );

    let mut c = controller(Sampling::Constant, &A);
    warm_up(&mut c);
    let snapshot = (filters(&c), c.target().copied(), c.holding());
    let unchanged = |c: &DefaultController| {
        assert_eq!(
            (filters(c), c.target().copied(), c.holding()),
            snapshot,
            "state changed on an error"
        );
    };

    assert_eq!(
        c.reset(&[0.0]).unwrap_err(),
        RuntimeError::WrongLength("positions_m")
    );
    assert_eq!(
        c.reset(&[0.0, f64::NEG_INFINITY]).unwrap_err(),
        RuntimeError::NonFinite("positions_m")
    );
    unchanged(&c);

    for t in [
        [f64::NAN, 0.0, 0.03, 0.0],
        [0.02, f64::INFINITY, 0.03, 0.0],
        [0.02, 0.0, 0.03, f64::NEG_INFINITY],
    ] {
        assert_eq!(
            c.set_target(&t).unwrap_err(),
            RuntimeError::NonFinite("target")
        );
    }
    match c.set_target(&[0.2, 0.0, -0.2, 0.0]).unwrap_err() {
        RuntimeError::OutsideWorkspace {
            argument,
            capsule,
            excess_m,
        } => {
            assert_eq!((argument, capsule), ("target", 0));
            assert!((excess_m - 0.14).abs() < 1e-12, "{excess_m}");
        }
        e => panic!("{e:?}"),
    }
    unchanged(&c);

    for z in [&[][..], &[0.0][..], &[0.0, 0.0, 0.0][..]] {
        assert_eq!(
            c.cycle(Some(z)).unwrap_err(),
            RuntimeError::WrongLength("measured_positions_m")
        );
    }
    unchanged(&c);

    for x in [
        [f64::NAN, 0.0, 0.0, 0.0],
        [0.0, f64::INFINITY, 0.0, 0.0],
        [0.0, 0.0, 0.0, f64::NEG_INFINITY],
    ] {
        assert_eq!(
            c.cycle_full_state(&x).unwrap_err(),
            RuntimeError::NonFinite("x")
        );
    }
    unchanged(&c);
    // After all that, the controller works as before.
    let out = c.cycle(Some(&expected_frame(&c))).unwrap();
    assert_eq!(out.status, RuntimeStatus::Ok);
    assert_safe(&out, "after errors");
}

fn bad_setting(edit: impl Fn(&mut ControllerSettings)) -> RuntimeError {
    let mut s = DefaultController::default_settings();
    edit(&mut s);
    DefaultController::new(s, &[0.0; M]).unwrap_err()
}

/// Settings out of range are refused by name.
#[test]
fn bad_settings_are_errors_naming_the_setting() {
    for v in [f64::NAN, f64::INFINITY, -1e-3, 2.0] {
        assert_eq!(
            bad_setting(|s| s.tracking_time_s = v),
            RuntimeError::BadSetting("tracking_time_s"),
            "{v}"
        );
        assert_eq!(
            bad_setting(|s| s.extra_delay_s = v),
            RuntimeError::BadSetting("extra_delay_s"),
            "{v}"
        );
        assert_eq!(
            bad_setting(|s| s.position_noise_m = v),
            RuntimeError::BadSetting("position_noise_m"),
            "{v}"
        );
    }
    for v in [f64::NAN, f64::NEG_INFINITY, -1.0, 1e4] {
        assert_eq!(
            bad_setting(|s| s.disturbance_bound = v),
            RuntimeError::BadSetting("disturbance_bound"),
            "{v}"
        );
    }
    for n in [0, N + 1, usize::MAX] {
        assert_eq!(
            bad_setting(|s| s.max_actuation_samples = n),
            RuntimeError::BadSetting("max_actuation_samples"),
            "{n}"
        );
    }
}

/// The terminal-hold tolerances are refused by name (kept apart: these
/// settings are the newest).
#[test]
fn bad_hold_settings_are_errors_naming_the_setting() {
    for v in [f64::NAN, -1e-3, 2.0] {
        assert_eq!(
            bad_setting(|s| s.hold_enter_position_m = v),
            RuntimeError::BadSetting("hold_enter_position_m")
        );
        assert_eq!(
            bad_setting(|s| s.hold_enter_speed_m_per_s = v),
            RuntimeError::BadSetting("hold_enter_speed_m_per_s")
        );
    }
    // Release inside entry: no hysteresis.
    assert_eq!(
        bad_setting(|s| s.hold_release_position_m = s.hold_enter_position_m / 2.0),
        RuntimeError::BadSetting("hold_release_position_m")
    );
    assert_eq!(
        bad_setting(|s| s.hold_release_speed_m_per_s = s.hold_enter_speed_m_per_s / 2.0),
        RuntimeError::BadSetting("hold_release_speed_m_per_s")
    );
}

/// One gated-out frame would restart the estimate: refused by name.
#[test]
fn reacquire_after_one_rejection_is_refused() {
    assert_eq!(
        bad_setting(|s| s.reacquire_after_rejections = 1),
        RuntimeError::BadSetting("reacquire_after_rejections")
    );
}

// ---------------------------------------------------------------------------
// The invariant |u| <= u_max over everything at once.

/// Every output of every cycle, in every sampling mode and switching rule,
/// with disturbances, noise, lost frames, NaN frames, out-of-range frames,
/// a target change and a restart outside the tables (re-acquired from the
/// gated-out frames after it, in the measured modes), respects |u| <= u_max
/// (all K samples, played or not), is finite and plays 1..=N samples; the
/// plant never receives more than u_max.
#[test]
fn every_output_respects_u_max() {
    let mut outputs = 0usize;
    let mut statuses = std::collections::BTreeSet::new();
    for sampling in [Sampling::Ideal, Sampling::Constant, Sampling::Variable] {
        for switching in [SwitchingRule::Tight, SwitchingRule::Paper] {
            for (seed, level) in [
                (1, DisturbanceLevel::None),
                (2, DisturbanceLevel::Paper),
                (3, DisturbanceLevel::Stress),
            ] {
                let mut l = Loop::new(sampling, &A, level, seed);
                let mut s = *l.ctl.settings();
                s.switching = switching;
                l.ctl = DefaultController::new(s, &[0.0; M]).unwrap();
                l.ctl.set_target(&A).unwrap();
                for k in 0..90usize {
                    if k == 30 {
                        // Target change while moving (if covered from here).
                        let _ = l.ctl.set_target(&C);
                    }
                    if k == 80 {
                        // A restart outside the workspace is refused; at
                        // its edge, the estimate is outside the tables.
                        assert!(l.ctl.reset(&[0.5, -0.5]).is_err());
                        l.ctl.reset(&[0.06, -0.06]).unwrap();
                    }
                    let out = if k == 70 && sampling == Sampling::Ideal {
                        // A state jump outside the tables (the plant's next
                        // state is fed again afterwards), then an
                        // implausible one.
                        let out = l.ctl.cycle_full_state(&[0.1, 0.9, -0.1, 0.8]).unwrap();
                        assert_safe(&out, "state jump");
                        statuses.insert(format!("{:?}", out.status));
                        l.ctl.cycle_full_state(&[0.1, 9.0, -0.1, 0.8]).unwrap()
                    } else if k % 7 == 3 {
                        l.cycle_with(Frame::Replaced([f64::NAN, 0.01]))
                    } else if k % 11 == 5 {
                        l.cycle_with(Frame::Replaced([5.0, -5.0]))
                    } else if k % 5 == 4 {
                        l.cycle_with(Frame::Lost)
                    } else {
                        l.cycle()
                    };
                    assert_safe(&out, &format!("{sampling:?} {switching:?} {level:?} k={k}"));
                    statuses.insert(format!("{:?}", out.status));
                    outputs += 1;
                }
                assert!(l.max_abs_u <= U_MAX);
            }
        }
    }
    assert!(outputs >= 1000);
    for s in [
        "Ok",
        "Fallback",
        "MeasurementRejected",
        "MeasurementLost",
        "Reacquired",
    ] {
        assert!(statuses.contains(s), "{s} never exercised: {statuses:?}");
    }
}
