//! Issue 8, property tests: the runtime never panics and its plan always
//! respects |u| <= u_max, whatever the state, target, disturbance, noise,
//! sampling and faults; the config parser never panics and its errors name
//! a field.
//!
//! Case counts are set so that the whole file runs in a few seconds with
//! `cargo test --release` on a 2-core machine; `PROPTEST_CASES=N` raises
//! every count for a longer local run.

use capsule_mpc_generator::config::{Config, ConfigError, DEFAULT_CONFIG_TOML};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::{
    braking_gradient, ControllerSettings, Sampling, SwitchingRule, MAX_ABS_POSITION_M,
    MAX_ABS_SPEED_M_PER_S, PROVEN_EXTRA_GAP_S, SETTING_NAMES, TIME_TOLERANCE_S,
};
use capsule_mpc_runtime::generated::controller::spec::{self, K, M, N, NX};
use capsule_mpc_runtime::generated::controller::Solver;
use capsule_mpc_runtime::solver::PlanSolver;
use capsule_mpc_runtime::{CycleOutput, DefaultController, RuntimeError, RuntimeStatus};
use capsule_mpc_sim::plant::{DisturbanceLevel, Phase, Plant};
use proptest::prelude::*;
use proptest::test_runner::Config as ProptestConfig;

const U_MAX: f64 = spec::U_MAX_T_PER_M;

/// `cases` unless PROPTEST_CASES asks for more.
fn cases(cases: u32) -> ProptestConfig {
    let env = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    ProptestConfig {
        cases: cases.max(env),
        max_global_rejects: 100_000,
        ..ProptestConfig::default()
    }
}

/// The output invariant: every gradient finite and within u_max, a play
/// length in 1..=N that the sampling mode allows.
fn check_output(out: &CycleOutput<K>, s: &ControllerSettings) -> Result<(), TestCaseError> {
    for (k, u) in out.gradients_t_per_m.iter().enumerate() {
        prop_assert!(
            u.is_finite() && u.abs() <= U_MAX,
            "gradient[{}] = {} ({:?})",
            k,
            u,
            out.status
        );
    }
    let n = out.actuation_samples;
    prop_assert!((1..=N).contains(&n), "actuation_samples = {}", n);
    match s.sampling {
        Sampling::Ideal | Sampling::Constant => prop_assert_eq!(n, 1),
        Sampling::Variable => prop_assert!(n <= s.max_actuation_samples),
    }
    Ok(())
}

fn sampling() -> impl Strategy<Value = Sampling> {
    prop_oneof![
        Just(Sampling::Ideal),
        Just(Sampling::Constant),
        Just(Sampling::Variable)
    ]
}

fn switching() -> impl Strategy<Value = SwitchingRule> {
    prop_oneof![Just(SwitchingRule::Tight), Just(SwitchingRule::Paper)]
}

fn disturbance() -> impl Strategy<Value = DisturbanceLevel> {
    prop_oneof![
        Just(DisturbanceLevel::None),
        Just(DisturbanceLevel::Paper),
        Just(DisturbanceLevel::Stress)
    ]
}

/// One closed-loop case.
#[derive(Debug, Clone)]
struct LoopCase {
    sampling: Sampling,
    switching: SwitchingRule,
    compensate_delay: bool,
    /// Target positions (speeds 0), m; within the tables' grid.
    target: [f64; M],
    /// True start state; the controller starts at rest at its positions.
    x0: [f64; NX],
    disturbance: DisturbanceLevel,
    seed: u64,
    noise_m: f64,
    extra_delay_s: f64,
    max_actuation_samples: usize,
    lose_every: Option<usize>,
    cycles: usize,
}

prop_compose! {
    fn loop_case()(
        sampling in sampling(),
        switching in switching(),
        compensate_delay in any::<bool>(),
        target in [-0.04..=0.04f64, -0.04..=0.04f64],
        x0 in [-0.005..=0.005f64, -0.05..=0.05f64, -0.005..=0.005f64, -0.05..=0.05f64],
        disturbance in disturbance(),
        seed in any::<u64>(),
        noise_m in prop_oneof![Just(0.0), 0.0..=1e-3f64],
        extra_delay_s in prop_oneof![Just(0.0), 0.0..=PROVEN_EXTRA_GAP_S],
        max_actuation_samples in 1..=N,
        lose_every in proptest::option::of(2..10usize),
        cycles in 5..60usize,
    ) -> LoopCase {
        LoopCase {
            sampling, switching, compensate_delay, target, x0, disturbance, seed,
            noise_m, extra_delay_s, max_actuation_samples, lose_every, cycles,
        }
    }
}

/// Runs the case in the plant simulator and checks every cycle. Returns
/// Ok(None) when the target is not covered from the start (rejected case).
fn run_loop(case: &LoopCase) -> Result<Option<()>, TestCaseError> {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let dist = case.disturbance.config(&model, case.seed);
    let noise = if case.sampling == Sampling::Ideal {
        0.0
    } else {
        case.noise_m
    };
    let mut plant = Plant::new(model, case.x0.to_vec(), dist.clone(), noise, case.seed).unwrap();
    let mut s = DefaultController::default_settings();
    s.sampling = case.sampling;
    s.switching = case.switching;
    s.compensate_delay = case.compensate_delay;
    s.position_noise_m = noise;
    s.disturbance_bound = dist.bound_si();
    s.extra_delay_s = case.extra_delay_s;
    s.max_actuation_samples = case.max_actuation_samples;
    let positions: [f64; M] = core::array::from_fn(|i| case.x0[2 * i]);
    let mut ctl = DefaultController::new(s, &positions).unwrap();
    let target: [f64; NX] =
        core::array::from_fn(|j| if j % 2 == 0 { case.target[j / 2] } else { 0.0 });
    match ctl.set_target(&target) {
        Ok(()) => {}
        Err(RuntimeError::TargetOutOfRange)
        | Err(RuntimeError::OutsideWorkspace { .. })
        | Err(RuntimeError::TargetNotAtRest) => return Ok(None),
        Err(e) => return Err(TestCaseError::fail(format!("set_target: {e:?}"))),
    }
    for cycle in 1..=case.cycles {
        let out = if case.sampling == Sampling::Ideal {
            let x: [f64; NX] = plant.state().try_into().unwrap();
            ctl.cycle_full_state(&x)
        } else {
            let z = plant.measure_positions();
            plant
                .advance(s.tracking_time_s + s.extra_delay_s, 0.0, Phase::Track)
                .unwrap();
            let lost = case.lose_every.is_some_and(|n| cycle % n == 0);
            ctl.cycle(if lost { None } else { Some(&z) })
        };
        let out = out.map_err(|e| TestCaseError::fail(format!("cycle {cycle}: {e:?}")))?;
        check_output(&out, &s)?;
        prop_assert!(
            out.estimate[..NX].iter().all(|v| v.is_finite()),
            "estimate {:?}",
            &out.estimate[..NX]
        );
        if case.lose_every.is_none() && case.sampling != Sampling::Ideal {
            prop_assert_ne!(out.status, RuntimeStatus::MeasurementLost);
        }
        for &u in &out.gradients_t_per_m[..out.actuation_samples] {
            plant.advance(spec::DT_S, u, Phase::Actuate).unwrap();
        }
    }
    Ok(Some(()))
}

proptest! {
    #![proptest_config(cases(1024))]

    /// Random start states, covered targets, disturbances, noise seeds and
    /// settings (sampling, switching, delay, actuation cap, lost frames) in
    /// the plant simulator: no error, no panic, every plan within u_max and
    /// finite, actuation_samples in 1..=N, a finite estimate.
    #[test]
    fn closed_loop_plans_are_bounded(case in loop_case()) {
        let ran = run_loop(&case)?;
        prop_assume!(ran.is_some(), "target not covered from the start");
    }
}

/// A relative state component: mostly inside the warm-start index
/// (`inside`), sometimes anywhere up to `outside`.
fn relative(inside: f64, outside: f64) -> impl Strategy<Value = f64> {
    prop_oneof![4 => -inside..=inside, 1 => -outside..=outside]
}

proptest! {
    #![proptest_config(cases(2048))]

    /// Random full states in and far outside the tables (relative
    /// positions up to 30 cm, speeds up to 3 m/s) from a fresh plan: Ok,
    /// IterationLimit, Fallback or (after a Fallback at rest) Recovering,
    /// and a Fallback output is the braking law alone (never a table value); a state beyond the physical range is
    /// rejected with the estimate kept. Then a few more cycles from the
    /// plan's predicted states.
    #[test]
    fn full_states_anywhere_give_bounded_plans(
        target in [-0.04..=0.04f64, -0.04..=0.04f64],
        e in [relative(0.05, 0.3), relative(0.45, 3.0), relative(0.05, 0.3), relative(0.45, 3.0)],
        steps in 1..8usize,
    ) {
        let mut s = DefaultController::default_settings();
        s.sampling = Sampling::Ideal;
        let mut ctl = DefaultController::new(s, &[0.0; M]).unwrap();
        let t = [target[0], 0.0, target[1], 0.0];
        prop_assume!(ctl.set_target(&t).is_ok());
        let mut x: [f64; NX] = core::array::from_fn(|j| t[j] + e[j]);
        for _ in 0..steps {
            let before = ctl.estimate();
            let out = ctl.cycle_full_state(&x).unwrap();
            check_output(&out, &s)?;
            let physical = (0..M).all(|i| {
                x[2 * i].abs() <= MAX_ABS_POSITION_M && x[2 * i + 1].abs() <= MAX_ABS_SPEED_M_PER_S
            });
            if !physical {
                prop_assert_eq!(out.status, RuntimeStatus::MeasurementRejected);
                prop_assert_eq!(ctl.estimate(), before);
                return Ok(());
            }
            match out.status {
                RuntimeStatus::Ok
                | RuntimeStatus::IterationLimit
                | RuntimeStatus::AboveIterationMap
                | RuntimeStatus::Recovering => {}
                RuntimeStatus::Fallback => {
                    prop_assert_eq!(
                        out.gradients_t_per_m[0],
                        braking_gradient::<Solver, NX, K>(&x)
                    );
                    prop_assert!(out.gradients_t_per_m[1..].iter().all(|&u| u == 0.0));
                }
                other => prop_assert!(false, "status {:?}", other),
            }
            x = <Solver as PlanSolver<NX, K>>::predict_plan(&x, &out.gradients_t_per_m, 1);
            prop_assume!(x.iter().all(|v| v.is_finite()));
        }
    }
}

/// A value that is sometimes plausible, sometimes wild: any f64 (NaN and
/// infinities included) or a magnitude near the scale of the problem.
fn wild_f64(scale: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -scale..=scale,
        1 => any::<f64>(),
        1 => prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(0.0),
            Just(-0.0),
            Just(f64::MAX),
            Just(f64::MIN_POSITIVE),
        ],
    ]
}

/// One call on the controller.
#[derive(Debug, Clone)]
enum Op {
    Frame([f64; M]),
    Lost,
    FullState([f64; NX]),
    SetTarget([f64; NX]),
    Reset([f64; M]),
    /// `cycle_at`: a frame (or lost), and the measurement time and the
    /// actuation start relative to the last actuation end (wild).
    Timed(Option<[f64; M]>, f64, f64),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => [wild_f64(0.06), wild_f64(0.06)].prop_map(Op::Frame),
        2 => Just(Op::Lost),
        2 => [wild_f64(0.06), wild_f64(0.5), wild_f64(0.06), wild_f64(0.5)].prop_map(Op::FullState),
        1 => [wild_f64(0.05), wild_f64(0.01), wild_f64(0.05), wild_f64(0.01)].prop_map(Op::SetTarget),
        1 => [wild_f64(0.06), wild_f64(0.06)].prop_map(Op::Reset),
        3 => (
            proptest::option::of([wild_f64(0.06), wild_f64(0.06)]),
            wild_f64(0.05),
            wild_f64(0.1),
        )
            .prop_map(|(z, dm, da)| Op::Timed(z, dm, da)),
    ]
}

/// Random settings: mostly in range, sometimes not.
#[derive(Debug, Clone)]
struct SettingsCase {
    sampling: Sampling,
    switching: SwitchingRule,
    compensate_delay: bool,
    tracking_time_s: f64,
    extra_delay_s: f64,
    position_noise_m: f64,
    disturbance_bound: f64,
    max_actuation_samples: usize,
    reacquire_after_rejections: usize,
}

prop_compose! {
    fn settings_case()(
        sampling in sampling(),
        switching in switching(),
        compensate_delay in any::<bool>(),
        tracking_time_s in wild_f64(0.05),
        extra_delay_s in wild_f64(0.03),
        position_noise_m in wild_f64(2e-3),
        disturbance_bound in wild_f64(1.0),
        max_actuation_samples in prop_oneof![4 => 1..=N, 1 => any::<usize>()],
        reacquire_after_rejections in prop_oneof![4 => 0..=8usize, 1 => any::<usize>()],
    ) -> SettingsCase {
        SettingsCase {
            sampling, switching, compensate_delay, tracking_time_s, extra_delay_s,
            position_noise_m, disturbance_bound, max_actuation_samples,
            reacquire_after_rejections,
        }
    }
}

impl SettingsCase {
    fn settings(&self) -> ControllerSettings {
        let mut s = DefaultController::default_settings();
        s.sampling = self.sampling;
        s.switching = self.switching;
        s.compensate_delay = self.compensate_delay;
        s.tracking_time_s = self.tracking_time_s;
        s.extra_delay_s = self.extra_delay_s;
        s.position_noise_m = self.position_noise_m;
        s.disturbance_bound = self.disturbance_bound;
        s.max_actuation_samples = self.max_actuation_samples;
        s.reacquire_after_rejections = self.reacquire_after_rejections;
        s
    }
}

proptest! {
    #![proptest_config(cases(2048))]

    /// Arbitrary settings and an arbitrary sequence of calls with wild
    /// values (NaN, infinities, huge, out of range): construction either
    /// succeeds or names the bad setting; every call returns Ok or one of
    /// the documented errors naming its argument; every output is finite,
    /// within u_max and plays 1..=N samples; the estimate stays finite.
    /// Never a panic.
    #[test]
    fn arbitrary_calls_never_panic_and_stay_bounded(
        settings in settings_case(),
        start in [wild_f64(0.05), wild_f64(0.05)],
        ops in proptest::collection::vec(op(), 1..40),
    ) {
        let s = settings.settings();
        let mut ctl = match DefaultController::new(s, &start) {
            Ok(c) => c,
            Err(RuntimeError::BadSetting(name)) => {
                prop_assert!(SETTING_NAMES.contains(&name), "unknown setting {}", name);
                return Ok(());
            }
            Err(RuntimeError::NonFinite("positions_m")) => {
                prop_assert!(start.iter().any(|p| !p.is_finite()));
                return Ok(());
            }
            Err(RuntimeError::GapBeyondProven { gap_s, max_s }) => {
                prop_assert_eq!(gap_s, s.tracking_time_s + s.extra_delay_s);
                prop_assert!(gap_s > max_s, "{} <= {}", gap_s, max_s);
                return Ok(());
            }
            Err(RuntimeError::OutsideWorkspace { argument: "positions_m", capsule, .. }) => {
                prop_assert!(!(spec::WORKSPACE_MIN_M..=spec::WORKSPACE_MAX_M).contains(&start[capsule]));
                return Ok(());
            }
            Err(e) => return Err(TestCaseError::fail(format!("new: {e:?}"))),
        };
        // A target that is always covered from the start, so that some
        // cases plan from the tables from the beginning.
        let _ = ctl.set_target(&[start[0], 0.0, start[1], 0.0]);
        for op in &ops {
            match op {
                Op::Frame(z) => check_output(&ctl.cycle(Some(z)).unwrap(), &s)?,
                Op::Lost => {
                    let out = ctl.cycle(None).unwrap();
                    prop_assert!(matches!(
                        out.status,
                        RuntimeStatus::MeasurementLost
                            | RuntimeStatus::Fallback
                            | RuntimeStatus::NoTarget
                    ), "{:?}", out.status);
                    check_output(&out, &s)?;
                }
                Op::FullState(x) => match ctl.cycle_full_state(x) {
                    Ok(out) => check_output(&out, &s)?,
                    Err(e) => {
                        prop_assert_eq!(e, RuntimeError::NonFinite("x"));
                        prop_assert!(x.iter().any(|v| !v.is_finite()));
                    }
                },
                Op::SetTarget(t) => match ctl.set_target(t) {
                    Ok(()) => prop_assert_eq!(ctl.target(), Some(t)),
                    Err(RuntimeError::NonFinite(name)) => prop_assert_eq!(name, "target"),
                    Err(RuntimeError::TargetOutOfRange)
                    | Err(RuntimeError::OutsideWorkspace { .. }) => {}
                    Err(RuntimeError::TargetNotAtRest) => {
                        prop_assert!((0..M).any(|i| t[2 * i + 1] != 0.0));
                    }
                    Err(e) => return Err(TestCaseError::fail(format!("set_target: {e:?}"))),
                },
                Op::Timed(z, dm, da) => {
                    let (dm, da) = (*dm, *da);
                    let end = ctl.actuation_end_s().unwrap_or(0.0);
                    let (t_meas, t_act) = (end + dm, end + dm + da);
                    match ctl.cycle_at(z.as_ref().map(|z| &z[..]), t_meas, t_act) {
                        Ok(out) => {
                            check_output(&out, &s)?;
                            prop_assert!(t_meas.is_finite() && t_act >= t_meas);
                        }
                        Err(RuntimeError::NonFinite(name)) | Err(RuntimeError::BadTime(name)) => {
                            prop_assert!(
                                ["t_measured_s", "t_actuation_start_s"].contains(&name),
                                "{}",
                                name
                            );
                            prop_assert!(
                                !t_meas.is_finite()
                                    || !t_act.is_finite()
                                    || t_act < t_meas
                                    || dm < -TIME_TOLERANCE_S,
                                "{} refused at {} / {}",
                                name,
                                dm,
                                da
                            );
                        }
                        Err(RuntimeError::GapBeyondProven { gap_s, max_s }) => {
                            prop_assert_eq!(max_s, DefaultController::MAX_GAP_S);
                            prop_assert!(
                                gap_s > max_s + TIME_TOLERANCE_S
                                    && (dm > max_s || da > max_s || dm + da > max_s),
                                "gap {} refused at {} / {}",
                                gap_s,
                                dm,
                                da
                            );
                        }
                        Err(e) => return Err(TestCaseError::fail(format!("cycle_at: {e:?}"))),
                    }
                }
                Op::Reset(p) => match ctl.reset(p) {
                    Ok(()) => prop_assert_eq!(ctl.estimate()[0], p[0]),
                    // Outside the workspace a restart is refused, naming
                    // the capsule (nothing changes).
                    Err(RuntimeError::OutsideWorkspace { argument, capsule, .. }) => {
                        prop_assert_eq!(argument, "positions_m");
                        prop_assert!(!(spec::WORKSPACE_MIN_M..=spec::WORKSPACE_MAX_M).contains(&p[capsule]));
                    }
                    Err(e) => prop_assert_eq!(e, RuntimeError::NonFinite("positions_m")),
                },
            }
            prop_assert!(
                ctl.estimate().iter().all(|v| v.is_finite()),
                "estimate {:?} after {:?}",
                ctl.estimate(),
                op
            );
        }
    }
}

// ---------------------------------------------------------------------------
// The config parser.

/// Every `key = value` line of the default config: (line index, key).
fn config_keys() -> Vec<(usize, String)> {
    DEFAULT_CONFIG_TOML
        .lines()
        .enumerate()
        .filter_map(|(i, line)| {
            let (key, _) = line.split_once(" = ")?;
            let key = key.trim();
            (!key.starts_with('#') && !key.is_empty()).then(|| (i, key.to_string()))
        })
        .collect()
}

/// Every field name a config error may name (leaf keys and tables).
fn field_names() -> Vec<String> {
    let mut names: Vec<String> = config_keys().into_iter().map(|(_, k)| k).collect();
    names.extend(
        [
            "capsule",
            "fluid",
            "drag",
            "scanner",
            "controller",
            "grid",
            "disturbance",
            "measurement",
            "shell_mass_kg",
            "slew_rate_t_per_m_per_s",
            "gradient_raster_s",
            "tracking_rf_duration_s",
            "tracking_adc_duration_s",
            "sqp_iterations",
            "switching_sigma",
            "position_range_m",
            "position_step_m",
            "starts",
        ]
        .map(String::from),
    );
    names
}

/// A TOML value literal: numbers of every kind (incl. nan, inf, huge,
/// negative), strings, booleans, arrays, inline tables.
fn toml_value() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| {
            if v.is_nan() {
                "nan".to_string()
            } else if v.is_infinite() {
                if v > 0.0 { "inf" } else { "-inf" }.to_string()
            } else {
                format!("{v:e}")
            }
        }),
        (-1e3..1e3f64).prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        (-3i64..500).prop_map(|v| v.to_string()),
        Just("nan".to_string()),
        Just("-inf".to_string()),
        Just("1e400".to_string()),
        Just("99999999999999999999999".to_string()),
        "[a-z]{0,8}".prop_map(|s| format!("\"{s}\"")),
        any::<bool>().prop_map(|b| b.to_string()),
        proptest::collection::vec(-1.0..1.0f64, 0..6).prop_map(|v| format!("{v:?}")),
        Just("{ a = 1 }".to_string()),
        Just("1979-05-27".to_string()),
    ]
}

/// A config edit.
#[derive(Debug, Clone)]
enum Edit {
    /// Replace the value of the n-th key (modulo the key count).
    Value(usize, String),
    /// Delete the n-th line (modulo the line count).
    DeleteLine(usize),
    /// Insert a line of text before the n-th line.
    Insert(usize, String),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        6 => (any::<usize>(), toml_value()).prop_map(|(n, v)| Edit::Value(n, v)),
        2 => any::<usize>().prop_map(Edit::DeleteLine),
        1 => (any::<usize>(), ("[a-z_]{1,12}", toml_value()))
            .prop_map(|(n, (k, v))| Edit::Insert(n, format!("{k} = {v}"))),
        1 => (any::<usize>(), "[\\[\\]a-z_ =\"0-9.#]{0,20}")
            .prop_map(|(n, line)| Edit::Insert(n, line)),
    ]
}

fn apply(edits: &[Edit]) -> String {
    let keys = config_keys();
    let mut lines: Vec<String> = DEFAULT_CONFIG_TOML.lines().map(String::from).collect();
    for e in edits {
        match e {
            Edit::Value(n, v) => {
                let (i, key) = &keys[n % keys.len()];
                if *i < lines.len() && lines[*i].starts_with(key.as_str()) {
                    lines[*i] = format!("{key} = {v}");
                }
            }
            Edit::DeleteLine(n) => {
                let n = n % lines.len();
                lines.remove(n);
            }
            Edit::Insert(n, text) => {
                let n = n % (lines.len() + 1);
                lines.insert(n, text.clone());
            }
        }
    }
    lines.join("\n")
}

/// The error contract: one line, and a field of the config (or, for a TOML
/// syntax error, the line it is on).
fn check_config_error(e: &ConfigError, names: &[String]) -> Result<(), TestCaseError> {
    let msg = e.to_string();
    prop_assert!(!msg.is_empty());
    prop_assert!(!msg.contains('\n'), "multi-line error: {:?}", msg);
    match e {
        ConfigError::Invalid { field, reason } => {
            prop_assert!(!field.is_empty() && !reason.is_empty(), "{}", msg);
        }
        ConfigError::Parse(_) => {
            let names_field = names.iter().any(|n| msg.contains(n.as_str()));
            // A TOML syntax error may have no field; it quotes its line.
            let quotes_line = msg.contains("(line ");
            prop_assert!(names_field || quotes_line, "names no field: {}", msg);
        }
        ConfigError::Io { .. } => prop_assert!(false, "Io from a string: {}", msg),
    }
    Ok(())
}

proptest! {
    #![proptest_config(cases(2048))]

    /// A single value replaced by anything: parse + validate never panics;
    /// the config is accepted, or the error names the field (the replaced
    /// key itself when the value has the wrong type or range).
    #[test]
    fn config_value_edits_never_panic_and_name_the_field(
        n in any::<usize>(),
        value in toml_value(),
    ) {
        let keys = config_keys();
        let (_, key) = &keys[n % keys.len()];
        let text = apply(&[Edit::Value(n, value.clone())]);
        if let Err(e) = Config::from_toml_str(&text) {
            check_config_error(&e, &field_names())?;
            let msg = e.to_string();
            // The changed key, or a field whose range depends on it.
            let named = msg.contains(key.as_str())
                || matches!(&e, ConfigError::Invalid { .. });
            prop_assert!(named, "`{} = {}`: {}", key, value, msg);
        }
    }

    /// Several random edits (values, deleted lines, inserted lines):
    /// never a panic, errors are one line and name a field or a position.
    #[test]
    fn config_edits_never_panic(edits in proptest::collection::vec(edit(), 1..5)) {
        let text = apply(&edits);
        if let Err(e) = Config::from_toml_str(&text) {
            check_config_error(&e, &field_names())?;
        }
    }

    /// Arbitrary text: never a panic.
    #[test]
    fn config_arbitrary_text_never_panics(text in any::<String>()) {
        if let Err(e) = Config::from_toml_str(&text) {
            prop_assert!(!e.to_string().contains('\n'), "{}", e);
        }
    }
}
