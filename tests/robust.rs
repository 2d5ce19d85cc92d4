//! Issue 14: the closed loop must hold whatever the tracking frames and
//! their time stamps do. The runtime controller against the plant
//! simulator, cycle by cycle on the scanner's timeline:
//!
//! - glitches: 1-20 frames reported 2 mm to 20 cm off, before and after
//!   settling, under constant and variable sampling; the loop must be
//!   settled again (every position within 1 mm of the target and every
//!   speed below 5 mm/s until the end of the run) within 3 s of the last
//!   bad frame;
//! - tracking phases of 10-60 ms, fixed or jittering from cycle to cycle,
//!   time-stamped by the host: the loop must settle.
//!
//! Run with `--nocapture` to see the worst cases.

use capsule_mpc::plant::{DisturbanceLevel, Phase, Plant};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::Sampling;
use capsule_mpc_runtime::generated::controller::spec::{self, K, M, NX};
use capsule_mpc_runtime::{CycleOutput, DefaultController, RuntimeStatus};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const A: [f64; NX] = [0.02, 0.0, 0.03, 0.0];
const C: [f64; NX] = [0.02, 0.0, -0.01, 0.0];
const SETTLE_POSITION_M: f64 = 1e-3;
const SETTLE_SPEED_M_PER_S: f64 = 5e-3;
/// The loop must be settled again this long after the last bad frame, s.
const RECOVERY_S: f64 = 3.0;

/// How long each tracking phase lasts (u = 0 from the measurement to the
/// actuation start).
#[derive(Debug, Clone, Copy)]
enum Tracking {
    Fixed(f64),
    /// Uniform in whole milliseconds between the bounds, redrawn every cycle.
    Jitter(f64, f64),
}

impl Tracking {
    fn draw(self, rng: &mut ChaCha8Rng) -> f64 {
        match self {
            Tracking::Fixed(s) => s,
            Tracking::Jitter(lo, hi) => {
                let ms = rng.gen_range((lo * 1e3).round() as u32..=(hi * 1e3).round() as u32);
                f64::from(ms) * 1e-3
            }
        }
    }
}

/// Frames reported `offset_m` off the measured positions, starting with the
/// first frame measured at or after `start_s`.
#[derive(Debug, Clone, Copy)]
struct Glitch {
    start_s: f64,
    frames: usize,
    offset_m: [f64; M],
}

#[derive(Debug, Clone, Copy)]
struct Case {
    sampling: Sampling,
    target: [f64; NX],
    seed: u64,
    tracking: Tracking,
    glitch: Option<Glitch>,
    disturbance: DisturbanceLevel,
    /// Run length after the last bad frame (or the whole run without one), s.
    duration_s: f64,
}

#[derive(Debug)]
struct Outcome {
    /// Earliest time after which the run stays settled to its end.
    settle_s: Option<f64>,
    /// Measurement time of the last bad frame.
    last_bad_s: Option<f64>,
    end_s: f64,
    statuses: Vec<RuntimeStatus>,
    /// Statuses of the bad frames' cycles.
    bad_statuses: Vec<RuntimeStatus>,
    final_state: Vec<f64>,
    /// (time, every position and speed within the settle band) per plant row.
    band: Vec<(f64, bool)>,
}

/// One cycle of the runtime: the frame `z` (None: lost), measured at
/// `t_measured_s`, the actuation starting at `t_actuation_start_s`.
fn cycle(
    ctl: &mut DefaultController,
    z: Option<&[f64]>,
    t_measured_s: f64,
    t_actuation_start_s: f64,
) -> CycleOutput<K> {
    ctl.cycle_at(z, t_measured_s, t_actuation_start_s).unwrap()
}

fn simulate(case: &Case) -> Outcome {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let noise = config.measurement.position_noise_m;
    let dist = case.disturbance.config(&model, case.seed);
    let mut plant = Plant::new(model, vec![0.0; NX], dist.clone(), noise, case.seed).unwrap();
    let mut s = DefaultController::default_settings();
    s.sampling = case.sampling;
    s.disturbance_bound = dist.bound_si();
    s.position_noise_m = noise;
    let mut ctl = DefaultController::new(s, &[0.0; M]).unwrap();
    ctl.set_target(&case.target).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(case.seed.wrapping_mul(7919));
    let (mut bad_done, mut last_bad_s) = (0usize, None);
    let mut statuses = Vec::new();
    let mut bad_statuses = Vec::new();
    let mut end_s = case.duration_s;
    while plant.time_s() < end_s - 1e-9 {
        let t_meas = plant.time_s();
        let mut z = plant.measure_positions();
        let mut bad = false;
        if let Some(g) = case.glitch {
            if t_meas >= g.start_s - 1e-9 && bad_done < g.frames {
                for (zi, o) in z.iter_mut().zip(g.offset_m) {
                    *zi += o;
                }
                bad_done += 1;
                bad = true;
                last_bad_s = Some(t_meas);
                end_s = t_meas + case.duration_s;
            }
        }
        plant
            .advance(case.tracking.draw(&mut rng), 0.0, Phase::Track)
            .unwrap();
        let t_act = plant.time_s();
        let out = cycle(&mut ctl, Some(&z), t_meas, t_act);
        for (k, u) in out.gradients_t_per_m.iter().enumerate() {
            assert!(
                u.is_finite() && u.abs() <= spec::U_MAX_T_PER_M,
                "gradient[{k}] = {u}"
            );
        }
        statuses.push(out.status);
        if bad {
            bad_statuses.push(out.status);
        }
        for &u in &out.gradients_t_per_m[..out.actuation_samples] {
            plant.advance(spec::DT_S, u, Phase::Actuate).unwrap();
        }
    }
    let records = plant.records();
    let out_of_band = |x: &[f64]| {
        (0..M).any(|i| {
            (x[2 * i] - case.target[2 * i]).abs() > SETTLE_POSITION_M
                || x[2 * i + 1].abs() >= SETTLE_SPEED_M_PER_S
        })
    };
    let settle_s = match records.iter().rposition(|r| out_of_band(&r.x)) {
        None => Some(0.0),
        Some(i) if i + 1 < records.len() => Some(records[i + 1].t_s),
        Some(_) => None,
    };
    Outcome {
        settle_s,
        last_bad_s,
        end_s: plant.time_s(),
        statuses,
        bad_statuses,
        final_state: plant.state().to_vec(),
        band: records
            .iter()
            .map(|r| (r.t_s, !out_of_band(&r.x)))
            .collect(),
    }
}

/// Time from the last bad frame until the loop is settled for good (0 when
/// it never left the band after it); None when it does not settle.
fn recovery_s(o: &Outcome) -> Option<f64> {
    let settle = o.settle_s?;
    Some((settle - o.last_bad_s.unwrap_or(0.0)).max(0.0))
}

/// Earliest time T >= `after_s` such that the run stays in the settle band
/// over [T, T + `window_s`] (None: no such T before the run ends).
fn held_from(o: &Outcome, after_s: f64, window_s: f64) -> Option<f64> {
    let mut start: Option<f64> = None;
    for &(t, inside) in &o.band {
        if !inside {
            start = None;
            continue;
        }
        let st = *start.get_or_insert(t);
        let from = st.max(after_s);
        if t >= from + window_s {
            return Some(from);
        }
    }
    None
}

fn glitch_offsets(size_m: f64) -> [[f64; M]; 3] {
    [[size_m, size_m], [size_m, 0.0], [-size_m, size_m]]
}

/// Runs the glitch grid for one sampling mode and asserts recovery within
/// RECOVERY_S of the last bad frame. `starts_s`: glitch start times (before
/// and after settling).
fn glitch_grid(sampling: Sampling, starts_s: &[f64], sizes_m: &[f64], seeds: &[u64]) {
    let mut worst: Option<(f64, String)> = None;
    let mut failures = Vec::new();
    let mut held_failures = Vec::new();
    let mut worst_held: f64 = 0.0;
    let mut runs = 0;
    for &frames in &[1usize, 2, 4, 5, 10, 20] {
        for &size in sizes_m {
            for offset_m in glitch_offsets(size) {
                for &start_s in starts_s {
                    for &seed in seeds {
                        for target in [A, C] {
                            let case = Case {
                                sampling,
                                target,
                                seed,
                                tracking: Tracking::Fixed(0.02),
                                disturbance: DisturbanceLevel::Paper,
                                glitch: Some(Glitch {
                                    start_s,
                                    frames,
                                    offset_m,
                                }),
                                duration_s: RECOVERY_S + 1.0,
                            };
                            let o = simulate(&case);
                            runs += 1;
                            let what = format!(
                                "{sampling:?} target {:?} seed {seed}: {frames} frames {offset_m:?} m from {start_s} s (last bad frame {:?} s, settled {:?} s, run end {:.2} s, final state {:?}, fallback cycles {} of the last 25)",
                                [target[0], target[2]],
                                o.last_bad_s,
                                o.settle_s,
                                o.end_s,
                                o.final_state,
                                o.statuses.iter().rev().take(25).filter(|s| **s == RuntimeStatus::Fallback).count()
                            );
                            assert_eq!(o.bad_statuses.len(), frames, "{what}");
                            let r = recovery_s(&o).unwrap_or(f64::INFINITY);
                            let lb = o.last_bad_s.unwrap();
                            let rh = held_from(&o, lb, 1.0).map_or(f64::INFINITY, |t| t - lb);
                            if rh > RECOVERY_S {
                                held_failures.push(what.clone());
                            }
                            worst_held = worst_held.max(rh);
                            if worst.as_ref().map_or(true, |(w, _)| r > *w) {
                                worst = Some((r, what.clone()));
                            }
                            if r > RECOVERY_S {
                                failures.push(what);
                            }
                        }
                    }
                }
            }
        }
    }
    let (w, what) = worst.unwrap();
    println!("{sampling:?}: {runs} glitch runs, worst recovery {w:.3} s: {what}");
    println!(
        "{sampling:?}: strict failures {}, held-1s failures {}, worst held {worst_held:.3}",
        failures.len(),
        held_failures.len()
    );
    for f in &held_failures {
        println!("HELD FAIL {f}");
    }
    assert!(
        failures.is_empty(),
        "{} of {runs} runs not settled within {RECOVERY_S} s of the last bad frame:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Glitches during the approach (0.3 s, 1.0 s) and after settling (2.5 s),
/// constant sampling.
#[test]
fn glitches_settle_again_constant_sampling() {
    glitch_grid(
        Sampling::Constant,
        &[0.3, 1.0, 2.5],
        &[0.002, 0.01, 0.05, 0.2],
        &[1, 2],
    );
}

/// The same under variable sampling (settles at about 1.1-1.5 s).
#[test]
fn glitches_settle_again_variable_sampling() {
    glitch_grid(
        Sampling::Variable,
        &[0.3, 1.0, 2.5],
        &[0.002, 0.01, 0.05, 0.2],
        &[1, 2],
    );
}

/// The report: after settling (constant sampling), positions
/// reported 5 cm off for 10 frames; the loop must not end up braking for
/// good.
#[test]
fn five_cm_glitch_for_ten_frames_after_settling_recovers() {
    for sampling in [Sampling::Constant, Sampling::Variable] {
        for seed in 1..=3 {
            let case = Case {
                sampling,
                target: A,
                seed,
                tracking: Tracking::Fixed(0.02),
                disturbance: DisturbanceLevel::Paper,
                glitch: Some(Glitch {
                    start_s: 3.0,
                    frames: 10,
                    offset_m: [0.05, 0.05],
                }),
                duration_s: RECOVERY_S + 1.0,
            };
            let o = simulate(&case);
            let tail_fallbacks = o
                .statuses
                .iter()
                .rev()
                .take(25)
                .filter(|s| **s == RuntimeStatus::Fallback)
                .count();
            let r = recovery_s(&o);
            println!(
                "{sampling:?} seed {seed}: recovery {r:?} s, final state {:?}",
                o.final_state
            );
            assert!(
                r.is_some_and(|r| r <= RECOVERY_S),
                "{sampling:?} seed {seed}: recovery {r:?} s, settled {:?}, final state {:?}, fallback in {tail_fallbacks} of the last 25 cycles",
                o.settle_s,
                o.final_state
            );
        }
    }
}

/// Glitches of 1-4 frames are rejected (the default re-acquisition count is
/// 5) and never move the estimate: every bad frame's status says so.
#[test]
fn short_glitches_are_rejected() {
    for sampling in [Sampling::Constant, Sampling::Variable] {
        for frames in 1..=4 {
            let case = Case {
                sampling,
                target: C,
                seed: 3,
                tracking: Tracking::Fixed(0.02),
                disturbance: DisturbanceLevel::Paper,
                glitch: Some(Glitch {
                    start_s: 2.5,
                    frames,
                    offset_m: [0.05, -0.05],
                }),
                duration_s: 2.0,
            };
            let o = simulate(&case);
            assert!(
                o.bad_statuses
                    .iter()
                    .all(|s| *s == RuntimeStatus::MeasurementRejected),
                "{sampling:?} {frames}: {:?}",
                o.bad_statuses
            );
            assert!(!o.statuses.contains(&RuntimeStatus::Reacquired));
            assert!(recovery_s(&o).is_some_and(|r| r <= RECOVERY_S), "{o:?}");
        }
    }
}

/// Settle-time bound for time-stamped tracking phases, s: scenario A/C from
/// rest, 8 s runs. Longer tracking phases lower the duty cycle (constant
/// sampling at 60 ms: 25 %), so the bound is generous; what the issue
/// reported was "never settles".
const TIMED_SETTLE_BOUND_S: f64 = 5.0;

fn timed_grid(sampling: Sampling) {
    let mut failures = Vec::new();
    let mut lines = Vec::new();
    for (name, tracking) in [
        ("10 ms", Tracking::Fixed(0.01)),
        ("20 ms", Tracking::Fixed(0.02)),
        ("40 ms", Tracking::Fixed(0.04)),
        ("60 ms", Tracking::Fixed(0.06)),
        ("10-60 ms", Tracking::Jitter(0.01, 0.06)),
    ] {
        let mut settles = Vec::new();
        let mut helds = Vec::new();
        for target in [A, C] {
            for seed in 1..=3 {
                let o = simulate(&Case {
                    sampling,
                    target,
                    seed,
                    tracking,
                    disturbance: DisturbanceLevel::Paper,
                    glitch: None,
                    duration_s: 8.0,
                });
                let s = o.settle_s.unwrap_or(f64::INFINITY);
                let h = held_from(&o, 0.0, 1.0).unwrap_or(f64::INFINITY);
                helds.push(h);
                settles.push(s);
                if s > TIMED_SETTLE_BOUND_S {
                    failures.push(format!(
                        "{sampling:?} tracking {name} target {:?} seed {seed}: settled {:?}, final state {:?}",
                        [target[0], target[2]],
                        o.settle_s,
                        o.final_state
                    ));
                }
            }
        }
        let worst = settles.iter().copied().fold(0.0, f64::max);
        let mean = settles.iter().sum::<f64>() / settles.len() as f64;
        lines.push(format!(
            "{sampling:?} tracking {name}: settle mean {mean:.2} s, worst {worst:.2} s; held 1 s from {helds:.2?}"
        ));
    }
    println!("{}", lines.join("\n"));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Time-stamped tracking phases of 10, 20, 40 and 60 ms and a jittering
/// 10-60 ms, constant sampling: the loop settles.
#[test]
fn timed_tracking_phases_settle_constant_sampling() {
    timed_grid(Sampling::Constant);
}

/// The same under variable sampling.
#[test]
fn timed_tracking_phases_settle_variable_sampling() {
    timed_grid(Sampling::Variable);
}

#[test]
#[ignore]
fn explore_trace() {
    let env = |k: &str, d: f64| std::env::var(k).map_or(d, |s| s.parse().unwrap());
    let seed = env("SEED", 1.0) as u64;
    let sampling = if env("VAR", 0.0) > 0.0 {
        Sampling::Variable
    } else {
        Sampling::Constant
    };
    let target = if env("TGT", 0.0) > 0.0 { C } else { A };
    let (g_start, g_frames, g0, g1) = (
        env("GS", 1.0),
        env("GF", 20.0) as usize,
        env("G0", 0.05),
        env("G1", 0.05),
    );
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let noise = config.measurement.position_noise_m;
    let dist = DisturbanceLevel::Paper.config(&model, seed);
    let mut plant = Plant::new(model, vec![0.0; NX], dist.clone(), noise, seed).unwrap();
    let mut s = DefaultController::default_settings();
    s.sampling = sampling;
    s.position_noise_m = noise;
    s.disturbance_bound = dist.bound_si();
    let mut ctl = DefaultController::new(s, &[0.0; M]).unwrap();
    ctl.set_target(&target).unwrap();
    let mut done = 0;
    while plant.time_s() < env("END", 6.0) {
        let t_meas = plant.time_s();
        let mut z = plant.measure_positions();
        let mut bad = false;
        if t_meas >= g_start - 1e-9 && done < g_frames {
            z[0] += g0;
            z[1] += g1;
            done += 1;
            bad = true;
        }
        plant.advance(0.02, 0.0, Phase::Track).unwrap();
        let t_act = plant.time_s();
        let out = ctl.cycle_at(Some(&z), t_meas, t_act).unwrap();
        let x = plant.state();
        let e = out.estimate;
        if t_meas > g_start - 0.1 {
            println!("{t_meas:.2}{} true e {:+.2} {:+.2} mm v {:+.1} {:+.1} mm/s | est e {:+.2} {:+.2} v {:+.1} {:+.1} | n {} u {:+.2} mT/m {:?}",
                if bad {"*"} else {" "},
                (x[0]-target[0])*1e3, (x[2]-target[2])*1e3, x[1]*1e3, x[3]*1e3,
                (e[0]-target[0])*1e3, (e[2]-target[2])*1e3, e[1]*1e3, e[3]*1e3, out.actuation_samples, out.gradients_t_per_m[0]*1e3, out.status);
        }
        for &u in &out.gradients_t_per_m[..out.actuation_samples] {
            plant.advance(spec::DT_S, u, Phase::Actuate).unwrap();
        }
    }
}
