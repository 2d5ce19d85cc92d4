//! Fuzz harnesses for capsule-mpc (issue 8), shared by the cargo-fuzz
//! targets in `fuzz_targets/` and by `tests/fuzz_regressions.rs` in the main
//! workspace, which replays `fuzz/seeds/` and `fuzz/regressions/` through the
//! same functions in a normal `cargo test` (this file is included there as a
//! module, so it has no crate attributes and no dependencies beyond the
//! project's crates and `std`).
//!
//! Each harness panics (a fuzzer crash) when a contract is broken:
//! - [`config`]: TOML text through the config parser and the model: never
//!   a panic; an error is one line; a config that parses also validates.
//! - [`capi`]: bytes -> a sequence of C ABI calls (init, set_sampling,
//!   set_target, reset, feed_tracking, feed_state, next_actuation, estimate,
//!   last_status, dimensions) with arbitrary doubles (NaN, inf, huge),
//!   wrong lengths, null pointers, small buffers: every call returns a
//!   documented code; on error nothing is written; on success the plan is
//!   finite, |u| <= u_max, 1..=N samples, a documented status, and the
//!   estimate stays finite.
//! - [`runtime`]: bytes -> settings + a sequence of `Controller` calls on
//!   the product controller or the paper preset, same contracts.

use capsule_mpc_capi as capi;
use capsule_mpc_generator::config::{Config, ConfigError};
use capsule_mpc_generator::model::Model;
use capsule_mpc_runtime::controller::{Sampling, SwitchingRule, SETTING_NAMES};
use capsule_mpc_runtime::solver::PlanSolver;
use capsule_mpc_runtime::{
    Controller, DefaultController, PaperController, RuntimeError, RuntimeStatus,
};

/// Reads structured values from the fuzzer's bytes; `None` when they run out.
pub struct Input<'a> {
    data: &'a [u8],
}

/// Doubles the decoder returns for its "special" tag.
const SPECIAL: [f64; 16] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.0,
    -0.0,
    f64::MAX,
    f64::MIN,
    f64::MIN_POSITIVE,
    f64::EPSILON,
    1e300,
    -1e-300,
    1.0,
    -1.0,
    0.5,
    1e-3,
    -0.04,
];

impl<'a> Input<'a> {
    pub fn new(data: &'a [u8]) -> Input<'a> {
        Input { data }
    }

    pub fn byte(&mut self) -> Option<u8> {
        let (&b, rest) = self.data.split_first()?;
        self.data = rest;
        Some(b)
    }

    fn bytes<const L: usize>(&mut self) -> Option<[u8; L]> {
        if self.data.len() < L {
            return None;
        }
        let (head, rest) = self.data.split_at(L);
        self.data = rest;
        head.try_into().ok()
    }

    fn i16(&mut self) -> Option<i16> {
        self.bytes::<2>().map(i16::from_le_bytes)
    }

    /// A double: raw bits, a special value (NaN, inf, huge, ...), or a
    /// value on the problem's scale (mm to m, m/s).
    pub fn f64(&mut self) -> Option<f64> {
        Some(match self.byte()? % 8 {
            0 => f64::from_le_bytes(self.bytes::<8>()?),
            1 => SPECIAL[(self.byte()? % 16) as usize],
            2..=5 => f64::from(self.i16()?) * 2e-6,
            _ => f64::from(self.i16()?) * 1e-4,
        })
    }

    pub fn array<const L: usize>(&mut self) -> Option<[f64; L]> {
        let mut a = [0.0; L];
        for v in &mut a {
            *v = self.f64()?;
        }
        Some(a)
    }
}

// ---------------------------------------------------------------------------
// Config parser.

/// TOML text (lossy UTF-8) through `Config::from_toml_str` and the model.
pub fn config(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    match Config::from_toml_str(&text) {
        Ok(c) => {
            assert_eq!(c.validate(), Ok(()), "parsed config does not validate");
            let model = Model::from_config(&c);
            assert_eq!(model.state_count(), c.state_count());
            for i in 0..model.capsule_count() {
                let v = model.terminal_speed_m_per_s(i, model.u_max_t_per_m);
                assert!(!v.is_nan(), "terminal speed of capsule {i} is NaN");
            }
            let _ = model.lipschitz_f(c.controller.speed_bound_m_per_s);
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.is_empty());
            assert!(!msg.contains('\n'), "multi-line config error: {msg:?}");
            if let ConfigError::Invalid { field, .. } = &e {
                assert!(!field.is_empty(), "an invalid value names no field: {msg}");
            }
        }
    }
}

// ---------------------------------------------------------------------------
// C ABI.

const M: usize = 2;
const NX: usize = 4;

/// The build's dimensions through the ABI.
fn dims() -> (usize, usize, usize, f64) {
    let (mut m, mut n, mut k, mut dt, mut u_max) = (0u32, 0u32, 0u32, 0.0, 0.0);
    let rc = unsafe { capi::capsule_mpc_dimensions(&mut m, &mut n, &mut k, &mut dt, &mut u_max) };
    assert_eq!(rc, capi::CAPSULE_MPC_OK);
    assert_eq!(m as usize, M, "the harness assumes {M} capsules");
    assert!(dt > 0.0 && u_max > 0.0);
    (n as usize, k as usize, m as usize, u_max)
}

const CODES: [i32; 14] = [
    capi::CAPSULE_MPC_OK,
    capi::CAPSULE_MPC_ERR_NULL_POINTER,
    capi::CAPSULE_MPC_ERR_BAD_SIZE,
    capi::CAPSULE_MPC_ERR_BAD_ALIGN,
    capi::CAPSULE_MPC_ERR_WRONG_LENGTH,
    capi::CAPSULE_MPC_ERR_NON_FINITE,
    capi::CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE,
    capi::CAPSULE_MPC_ERR_BAD_MODE,
    capi::CAPSULE_MPC_ERR_NOT_INITIALIZED,
    capi::CAPSULE_MPC_ERR_BAD_SETTING,
    capi::CAPSULE_MPC_ERR_BAD_TIME,
    capi::CAPSULE_MPC_ERR_WRONG_FEED,
    capi::CAPSULE_MPC_ERR_LOOP_RUNNING,
    capi::CAPSULE_MPC_ERR_TARGET_NOT_AT_REST,
];

/// Largest `CAPSULE_MPC_STATUS_*` value.
const LAST_STATUS: i32 = capi::CAPSULE_MPC_STATUS_RECOVERING;

fn check_code(what: &str, rc: i32) -> i32 {
    assert!(CODES.contains(&rc), "{what}: undocumented return code {rc}");
    rc
}

/// A zeroed workspace buffer of 16-byte words (the workspace's alignment
/// is checked to be at most 16), a little larger than needed.
struct Workspace {
    words: Vec<u128>,
}

impl Workspace {
    fn new() -> Workspace {
        let size = capi::capsule_mpc_workspace_size();
        let align = capi::capsule_mpc_workspace_align();
        assert!(align <= core::mem::align_of::<u128>(), "align {align}");
        Workspace {
            words: vec![0u128; size.div_ceil(16) + 1],
        }
    }

    fn ptr(&mut self) -> *mut capi::CapsuleMpc {
        self.words.as_mut_ptr().cast()
    }

    fn bytes(&self) -> usize {
        self.words.len() * 16
    }
}

/// A length argument: mostly right, sometimes wrong.
fn length(inp: &mut Input, right: usize) -> Option<usize> {
    Some(match inp.byte()? % 8 {
        0 => 0,
        1 => right + 1,
        2 => right.saturating_sub(1),
        3 => usize::MAX,
        _ => right,
    })
}

/// A pointer to `values`, or null (one time in 16).
fn ptr_or_null(inp: &mut Input, values: &[f64]) -> Option<*const f64> {
    Some(if inp.byte()? % 16 == 0 {
        core::ptr::null()
    } else {
        values.as_ptr()
    })
}

/// Bytes -> a sequence of C ABI calls on one workspace, with contracts.
pub fn capi(data: &[u8]) {
    let mut inp = Input::new(data);
    let (n_horizon, k_plan, _, u_max) = dims();
    let mut ws = Workspace::new();
    let h = ws.ptr();
    // A zeroed buffer is detected as not initialized.
    let mut st = 0i32;
    let rc = unsafe { capi::capsule_mpc_last_status(h, &mut st) };
    assert_eq!(rc, capi::CAPSULE_MPC_ERR_NOT_INITIALIZED);

    let Some(start) = inp.array::<M>() else {
        return;
    };
    let rc = unsafe { capi::capsule_mpc_init(h.cast(), ws.bytes(), start.as_ptr(), M) };
    if start.iter().all(|v| v.is_finite()) {
        assert_eq!(rc, capi::CAPSULE_MPC_OK, "init at {start:?}");
    } else {
        assert_eq!(rc, capi::CAPSULE_MPC_ERR_NON_FINITE);
        // Initialize at the origin instead, so the sequence goes on.
        let rc = unsafe { capi::capsule_mpc_init(h.cast(), ws.bytes(), [0.0; M].as_ptr(), M) };
        assert_eq!(rc, capi::CAPSULE_MPC_OK);
    }

    // The host's clock: the end of the last actuation phase returned.
    let mut clock = 0.0f64;
    let mut steps = 0usize;
    while let Some(op) = inp.byte() {
        steps += 1;
        if steps > 256 {
            break;
        }
        match op % 12 {
            0 => {
                let Some(z) = inp.array::<M>() else { return };
                let Some(n) = length(&mut inp, M) else { return };
                let Some(p) = ptr_or_null(&mut inp, &z) else {
                    return;
                };
                let Some(t) = inp.f64() else { return };
                let Some(lost) = inp.byte() else { return };
                // A plausible time (the clock) or the fuzzed one.
                let t = if lost & 2 == 0 { clock } else { t };
                let lost = i32::from(lost % 4 == 0);
                let rc = check_code("feed_tracking", unsafe {
                    capi::capsule_mpc_feed_tracking(h, p, n, t, lost)
                });
                if rc == capi::CAPSULE_MPC_ERR_WRONG_FEED {
                    // Ideal sampling: frames do not fit, whatever they are.
                } else if !t.is_finite() {
                    assert_eq!(rc, capi::CAPSULE_MPC_ERR_NON_FINITE);
                } else if lost != 0 {
                    assert!(
                        [capi::CAPSULE_MPC_OK, capi::CAPSULE_MPC_ERR_BAD_TIME].contains(&rc),
                        "lost frame at {t}: {rc}"
                    );
                }
            }
            1 => {
                let Some(x) = inp.array::<NX>() else { return };
                let Some(n) = length(&mut inp, NX) else {
                    return;
                };
                let Some(p) = ptr_or_null(&mut inp, &x) else {
                    return;
                };
                let rc = check_code("feed_state", unsafe {
                    capi::capsule_mpc_feed_state(h, p, n)
                });
                if !p.is_null()
                    && n == NX
                    && x.iter().all(|v| v.is_finite())
                    && rc != capi::CAPSULE_MPC_ERR_WRONG_FEED
                {
                    assert_eq!(rc, capi::CAPSULE_MPC_OK);
                }
            }
            2 => {
                let Some(sel) = inp.byte() else { return };
                let capacity = [n_horizon, k_plan, k_plan + 5, n_horizon - 1, 0][sel as usize % 5];
                let t = if sel & 8 == 0 {
                    clock + 0.02
                } else {
                    let Some(t) = inp.f64() else { return };
                    t
                };
                if let Some(end) = next_actuation(h, t, capacity, n_horizon, k_plan, u_max) {
                    clock = end;
                }
            }
            3 => {
                let Some(t) = inp.array::<NX>() else { return };
                let Some(n) = length(&mut inp, NX) else {
                    return;
                };
                let Some(p) = ptr_or_null(&mut inp, &t) else {
                    return;
                };
                check_code("set_target", unsafe {
                    capi::capsule_mpc_set_target(h, p, n)
                });
            }
            4 => {
                let Some(z) = inp.array::<M>() else { return };
                let Some(n) = length(&mut inp, M) else { return };
                let Some(p) = ptr_or_null(&mut inp, &z) else {
                    return;
                };
                let rc = check_code("reset", unsafe { capi::capsule_mpc_reset(h, p, n) });
                if !p.is_null() && n == M && z.iter().all(|v| v.is_finite()) {
                    assert_eq!(rc, capi::CAPSULE_MPC_OK);
                }
            }
            5 => {
                let Some(b) = inp.byte() else { return };
                let mode = i32::from(b % 6) - 1;
                let rc = check_code("set_sampling", unsafe {
                    capi::capsule_mpc_set_sampling(h, mode)
                });
                if !(0..=2).contains(&mode) {
                    assert_eq!(rc, capi::CAPSULE_MPC_ERR_BAD_MODE);
                } else {
                    assert!(
                        [capi::CAPSULE_MPC_OK, capi::CAPSULE_MPC_ERR_LOOP_RUNNING].contains(&rc),
                        "set_sampling({mode}): {rc}"
                    );
                }
            }
            6 => {
                let mut s = -100i32;
                let rc = unsafe { capi::capsule_mpc_last_status(h, &mut s) };
                assert_eq!(rc, capi::CAPSULE_MPC_OK);
                assert!((0..=LAST_STATUS).contains(&s), "last status {s}");
            }
            7 => {
                let Some(sel) = inp.byte() else { return };
                let capacity = [NX, NX + 3, NX - 1, 0][sel as usize % 4];
                let mut x = [f64::from_bits(0x7ff8_dead_beef_0001); NX + 3];
                let rc = unsafe { capi::capsule_mpc_estimate(h, x.as_mut_ptr(), capacity) };
                if capacity < NX {
                    assert_eq!(rc, capi::CAPSULE_MPC_ERR_WRONG_LENGTH);
                    assert!(x.iter().all(|v| v.to_bits() == 0x7ff8_dead_beef_0001));
                } else {
                    assert_eq!(rc, capi::CAPSULE_MPC_OK);
                    assert!(
                        x[..NX].iter().all(|v| v.is_finite()),
                        "estimate not finite: {:?}",
                        &x[..NX]
                    );
                }
            }
            8 => {
                let _ = dims();
                let rc = unsafe {
                    capi::capsule_mpc_dimensions(
                        core::ptr::null_mut(),
                        core::ptr::null_mut(),
                        core::ptr::null_mut(),
                        core::ptr::null_mut(),
                        core::ptr::null_mut(),
                    )
                };
                assert_eq!(rc, capi::CAPSULE_MPC_ERR_NULL_POINTER);
            }
            9 => {
                // Re-init (or a refused init that must leave the workspace as it was).
                let Some(z) = inp.array::<M>() else { return };
                let Some(sel) = inp.byte() else { return };
                let size = if sel % 4 == 0 {
                    capi::capsule_mpc_workspace_size() - 1
                } else {
                    ws.bytes()
                };
                let rc = check_code("init", unsafe {
                    capi::capsule_mpc_init(h.cast(), size, z.as_ptr(), M)
                });
                if size < capi::capsule_mpc_workspace_size() {
                    assert_eq!(rc, capi::CAPSULE_MPC_ERR_BAD_SIZE);
                }
                let mut s = 0;
                assert_eq!(
                    unsafe { capi::capsule_mpc_last_status(h, &mut s) },
                    capi::CAPSULE_MPC_OK
                );
            }
            10 => {
                // A stretch of a plausible loop: frames consistent with the
                // estimate plus a small offset, so that short inputs reach
                // deep states.
                let Some(count) = inp.byte() else { return };
                let Some(offset) = inp.f64() else { return };
                for _ in 0..(count % 32) {
                    let mut x = [0.0; NX];
                    let rc = unsafe { capi::capsule_mpc_estimate(h, x.as_mut_ptr(), NX) };
                    assert_eq!(rc, capi::CAPSULE_MPC_OK);
                    let z = [x[0] + offset, x[2] - offset];
                    check_code("feed_tracking", unsafe {
                        capi::capsule_mpc_feed_tracking(h, z.as_ptr(), M, clock, 0)
                    });
                    if let Some(end) =
                        next_actuation(h, clock + 0.02, n_horizon, n_horizon, k_plan, u_max)
                    {
                        clock = end;
                    }
                }
            }
            _ => {
                // Calls on a null handle and on a never-initialized buffer.
                let mut other = Workspace::new();
                for handle in [core::ptr::null_mut(), other.ptr()] {
                    let expected = if handle.is_null() {
                        capi::CAPSULE_MPC_ERR_NULL_POINTER
                    } else {
                        capi::CAPSULE_MPC_ERR_NOT_INITIALIZED
                    };
                    let z = [0.0; NX];
                    let mut g = [0.0; 64];
                    let (mut n, mut s) = (0u32, 0i32);
                    unsafe {
                        assert_eq!(capi::capsule_mpc_reset(handle, z.as_ptr(), M), expected);
                        assert_eq!(
                            capi::capsule_mpc_set_target(handle, z.as_ptr(), NX),
                            expected
                        );
                        assert_eq!(capi::capsule_mpc_set_sampling(handle, 0), expected);
                        assert_eq!(
                            capi::capsule_mpc_feed_tracking(handle, z.as_ptr(), M, 0.0, 0),
                            expected
                        );
                        assert_eq!(
                            capi::capsule_mpc_feed_state(handle, z.as_ptr(), NX),
                            expected
                        );
                        assert_eq!(
                            capi::capsule_mpc_next_actuation(
                                handle,
                                0.0,
                                g.as_mut_ptr(),
                                64,
                                &mut n,
                                &mut s
                            ),
                            expected
                        );
                        assert_eq!(capi::capsule_mpc_last_status(handle, &mut s), expected);
                        assert_eq!(
                            capi::capsule_mpc_estimate(handle, g.as_mut_ptr(), 64),
                            expected
                        );
                    }
                }
            }
        }
    }
}

/// One `capsule_mpc_next_actuation` with output checks.
/// `capsule_mpc_next_actuation` for an actuation starting at `t` with its
/// contracts; the end of the returned actuation phase, s, on success.
fn next_actuation(
    h: *mut capi::CapsuleMpc,
    t: f64,
    capacity: usize,
    n_horizon: usize,
    k_plan: usize,
    u_max: f64,
) -> Option<f64> {
    const SENTINEL: u64 = 0x7ff8_dead_beef_0002;
    let mut g = vec![f64::from_bits(SENTINEL); capacity.max(1) + 4];
    let (mut samples, mut status) = (u32::MAX, i32::MIN);
    let rc = check_code("next_actuation", unsafe {
        capi::capsule_mpc_next_actuation(h, t, g.as_mut_ptr(), capacity, &mut samples, &mut status)
    });
    if rc != capi::CAPSULE_MPC_OK {
        let expected = if capacity < n_horizon {
            capi::CAPSULE_MPC_ERR_WRONG_LENGTH
        } else if !t.is_finite() {
            capi::CAPSULE_MPC_ERR_NON_FINITE
        } else {
            capi::CAPSULE_MPC_ERR_BAD_TIME
        };
        assert_eq!(rc, expected, "next_actuation at {t} s, capacity {capacity}");
        assert!(
            g.iter().all(|v| v.to_bits() == SENTINEL),
            "written on error"
        );
        assert_eq!((samples, status), (u32::MAX, i32::MIN), "written on error");
        return None;
    }
    assert!(
        (1..=n_horizon as u32).contains(&samples),
        "samples {samples}"
    );
    assert!((0..=LAST_STATUS).contains(&status), "status {status}");
    let written = capacity.min(k_plan);
    for (k, u) in g[..written].iter().enumerate() {
        assert!(
            u.is_finite() && u.abs() <= u_max,
            "gradient[{k}] = {u} (status {status})"
        );
    }
    assert!(
        g[written..].iter().all(|v| v.to_bits() == SENTINEL),
        "written past the plan"
    );
    Some(t + f64::from(samples) * 0.02)
}

// ---------------------------------------------------------------------------
// Runtime, directly (both generated solvers, arbitrary settings).

/// Bytes -> settings + a sequence of calls on the product controller or
/// the paper preset.
pub fn runtime(data: &[u8]) {
    let mut inp = Input::new(data);
    let Some(which) = inp.byte() else { return };
    if which % 4 == 0 {
        run_controller::<
            capsule_mpc_runtime::generated::paper_preset::Solver,
            { capsule_mpc_runtime::generated::paper_preset::spec::NX },
            { capsule_mpc_runtime::generated::paper_preset::spec::K },
        >(&mut inp, PaperController::default_settings());
    } else {
        run_controller::<
            capsule_mpc_runtime::generated::controller::Solver,
            { capsule_mpc_runtime::generated::controller::spec::NX },
            { capsule_mpc_runtime::generated::controller::spec::K },
        >(&mut inp, DefaultController::default_settings());
    }
}

fn run_controller<S: PlanSolver<NX2, K>, const NX2: usize, const K: usize>(
    inp: &mut Input,
    defaults: capsule_mpc_runtime::ControllerSettings,
) {
    let m = NX2 / 2;
    let mut s = defaults;
    let Some(flags) = inp.byte() else { return };
    s.sampling = [Sampling::Ideal, Sampling::Constant, Sampling::Variable][(flags % 3) as usize];
    s.switching = if flags & 4 == 0 {
        SwitchingRule::Tight
    } else {
        SwitchingRule::Paper
    };
    s.compensate_delay = flags & 8 == 0;
    // Each remaining flag bit replaces one setting by a fuzzed value.
    if flags & 16 != 0 {
        let Some(v) = inp.f64() else { return };
        s.tracking_time_s = v;
        let Some(v) = inp.f64() else { return };
        s.extra_delay_s = v;
    }
    if flags & 32 != 0 {
        let Some(v) = inp.f64() else { return };
        s.position_noise_m = v;
    }
    if flags & 64 != 0 {
        let Some(v) = inp.f64() else { return };
        s.disturbance_bound = v;
    }
    if flags & 128 != 0 {
        let Some(b) = inp.byte() else { return };
        s.max_actuation_samples = usize::from(b % (S::N as u8 + 2));
    }
    let Some(start) = inp.array::<2>() else {
        return;
    };
    let start = &start[..m.min(2)];
    if std::env::var_os("FUZZ_TRACE").is_some() {
        eprintln!("settings {s:?}, start {start:?}");
    }
    let mut c = match Controller::<S, NX2, K>::new(s, start) {
        Ok(c) => c,
        Err(RuntimeError::BadSetting(name)) => {
            assert!(SETTING_NAMES.contains(&name), "unknown setting {name}");
            return;
        }
        Err(RuntimeError::NonFinite(name)) => {
            assert_eq!(name, "positions_m");
            return;
        }
        // A start outside the workspace is refused like a target there.
        Err(RuntimeError::OutsideWorkspace {
            argument: "positions_m",
            capsule,
            ..
        }) => {
            assert!(!(S::WORKSPACE_MIN_M..=S::WORKSPACE_MAX_M).contains(&start[capsule]));
            return;
        }
        Err(e) => panic!("new: {e:?}"),
    };
    let u_max = S::U_MAX_T_PER_M;
    let check = |out: &capsule_mpc_runtime::CycleOutput<K>, c: &Controller<S, NX2, K>| {
        for (k, u) in out.gradients_t_per_m.iter().enumerate() {
            assert!(
                u.is_finite() && u.abs() <= u_max,
                "gradient[{k}] = {u} ({:?})",
                out.status
            );
        }
        assert!((1..=S::N).contains(&out.actuation_samples));
        if s.sampling == Sampling::Variable {
            assert!(out.actuation_samples <= s.max_actuation_samples);
        } else {
            assert_eq!(out.actuation_samples, 1);
        }
        assert!(
            c.estimate().iter().all(|v| v.is_finite()),
            "estimate not finite: {:?} ({:?})",
            c.estimate(),
            out.status
        );
    };
    let trace = std::env::var_os("FUZZ_TRACE").is_some();
    let mut steps = 0;
    while let Some(op) = inp.byte() {
        steps += 1;
        if steps > 256 {
            break;
        }
        if trace {
            eprintln!("op {} estimate {:?}", op % 8, c.estimate());
        }
        match op % 8 {
            0 | 1 => {
                let Some(z) = inp.array::<2>() else { return };
                let out = c.cycle(Some(&z[..m.min(2)])).unwrap();
                check(&out, &c);
            }
            2 => {
                // On the host's clock: a plausible time stamp (the last
                // actuation end, then a 10-60 ms tracking phase) or fuzzed.
                let Some(z) = inp.array::<2>() else { return };
                let Some(sel) = inp.byte() else { return };
                let Some(fuzzed) = inp.array::<2>() else {
                    return;
                };
                let end = c.actuation_end_s().unwrap_or(0.0);
                let (t_meas, t_act) = if sel % 4 == 0 {
                    (fuzzed[0], fuzzed[1])
                } else {
                    // 5-30 ms: within the proven range (`MAX_GAP_S`).
                    (end, end + 0.005 * f64::from(1 + sel % 6))
                };
                let frame = (sel & 16 == 0).then_some(&z[..m.min(2)]);
                match c.cycle_at(frame, t_meas, t_act) {
                    Ok(out) => {
                        check(&out, &c);
                        assert_eq!(
                            c.actuation_end_s(),
                            Some(t_act + out.actuation_samples as f64 * S::DT_S)
                        );
                    }
                    Err(RuntimeError::NonFinite(name)) | Err(RuntimeError::BadTime(name)) => {
                        assert!(sel % 4 == 0, "plausible times refused: {name}");
                        assert!(
                            ["t_measured_s", "t_actuation_start_s"].contains(&name),
                            "{name}"
                        );
                    }
                    Err(RuntimeError::GapBeyondProven { gap_s, max_s }) => {
                        assert!(sel % 4 == 0, "a gap within the range refused: {gap_s} s");
                        assert!(gap_s > max_s, "{gap_s} <= {max_s}");
                    }
                    Err(e) => panic!("cycle_at: {e:?}"),
                }
            }
            3 => {
                let out = c.cycle(None).unwrap();
                assert!(matches!(
                    out.status,
                    RuntimeStatus::MeasurementLost
                        | RuntimeStatus::Fallback
                        | RuntimeStatus::NoTarget
                ));
                check(&out, &c);
            }
            4 => {
                let Some(x) = inp.array::<4>() else { return };
                let mut full = [0.0; NX2];
                full.copy_from_slice(&x[..NX2.min(4)]);
                match c.cycle_full_state(&full) {
                    Ok(out) => check(&out, &c),
                    Err(e) => {
                        assert_eq!(e, RuntimeError::NonFinite("x"));
                        assert!(full.iter().any(|v| !v.is_finite()));
                    }
                }
            }
            5 => {
                let Some(x) = inp.array::<4>() else { return };
                let mut t = [0.0; NX2];
                t.copy_from_slice(&x[..NX2.min(4)]);
                match c.set_target(&t) {
                    Ok(()) => assert_eq!(c.target(), Some(&t)),
                    Err(RuntimeError::NonFinite("target"))
                    | Err(RuntimeError::TargetOutOfRange)
                    | Err(RuntimeError::OutsideWorkspace { .. })
                    | Err(RuntimeError::TargetNotAtRest) => {}
                    Err(e) => panic!("set_target: {e:?}"),
                }
            }
            6 => {
                let Some(z) = inp.array::<2>() else { return };
                match c.reset(&z[..m.min(2)]) {
                    Ok(()) => {}
                    Err(RuntimeError::NonFinite("positions_m"))
                    | Err(RuntimeError::OutsideWorkspace {
                        argument: "positions_m",
                        ..
                    }) => {}
                    Err(e) => panic!("reset: {e:?}"),
                }
            }
            _ => {
                // A stretch of consistent frames (the estimate's positions
                // plus a small offset).
                let Some(count) = inp.byte() else { return };
                let Some(offset) = inp.f64() else { return };
                for _ in 0..(count % 32) {
                    let x = c.estimate();
                    let z = [x[0] + offset, x[2 % NX2] - offset];
                    let out = c.cycle(Some(&z[..m.min(2)])).unwrap();
                    check(&out, &c);
                }
            }
        }
    }
}
