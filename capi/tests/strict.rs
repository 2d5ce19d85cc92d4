//! Issue 14 through the C ABI, as an independent host drives it: a feed
//! that does not fit the sampling mode, `set_sampling` mid-run, target
//! speeds, time stamps that go backwards or jump, tracking phases longer
//! than the configured 20 ms, and a glitch after the loop has settled.

use capsule_mpc_capi::*;
use core::ptr::null;

#[repr(C, align(64))]
struct Buf([u8; 1 << 16]);

const ORIGIN: [f64; 2] = [0.0, 0.0];
const TARGET_C: [f64; 4] = [0.02, 0.0, -0.01, 0.0];
const SAMPLE_S: f64 = 0.02;

fn initialized(b: &mut Buf) -> *mut CapsuleMpc {
    let size = b.0.len();
    let rc = unsafe { capsule_mpc_init(b.0.as_mut_ptr().cast(), size, ORIGIN.as_ptr(), 2) };
    assert_eq!(rc, CAPSULE_MPC_OK);
    b.0.as_mut_ptr().cast()
}

fn new_buf() -> Box<Buf> {
    Box::new(Buf([0; 1 << 16]))
}

/// `capsule_mpc_next_actuation` for an actuation starting at `t_s`.
fn next(h: *mut CapsuleMpc, _t_s: f64, grads: &mut [f64]) -> Result<(u32, i32), i32> {
    let (mut samples, mut status) = (0u32, -1i32);
    let rc = unsafe {
        capsule_mpc_next_actuation(
            h,
            grads.as_mut_ptr(),
            grads.len(),
            &mut samples,
            &mut status,
        )
    };
    if rc == CAPSULE_MPC_OK {
        Ok((samples, status))
    } else {
        Err(rc)
    }
}

fn feed(h: *mut CapsuleMpc, z: &[f64; 2], t_s: f64) -> i32 {
    unsafe { capsule_mpc_feed_tracking(h, z.as_ptr(), 2, t_s, 0) }
}

#[test]
fn a_feed_that_does_not_fit_the_sampling_mode_is_an_error() {
    let mut b = new_buf();
    let h = initialized(&mut b);
    let x = [0.0; 4];
    // Constant sampling (the default): full states are not fed.
    let rc = unsafe { capsule_mpc_feed_state(h, x.as_ptr(), 4) };
    assert_ne!(rc, CAPSULE_MPC_OK, "feed_state under constant sampling");
    assert_eq!(
        unsafe { capsule_mpc_set_sampling(h, CAPSULE_MPC_SAMPLING_VARIABLE) },
        CAPSULE_MPC_OK
    );
    let rc = unsafe { capsule_mpc_feed_state(h, x.as_ptr(), 4) };
    assert_ne!(rc, CAPSULE_MPC_OK, "feed_state under variable sampling");
    // Ideal sampling: tracking frames are not fed.
    assert_eq!(
        unsafe { capsule_mpc_set_sampling(h, CAPSULE_MPC_SAMPLING_IDEAL) },
        CAPSULE_MPC_OK
    );
    assert_ne!(
        feed(h, &ORIGIN, 0.0),
        CAPSULE_MPC_OK,
        "feed_tracking under ideal sampling"
    );
    assert_ne!(
        unsafe { capsule_mpc_feed_tracking(h, null(), 0, 0.0, 1) },
        CAPSULE_MPC_OK,
        "a lost frame under ideal sampling"
    );
}

#[test]
fn set_sampling_mid_run_is_refused() {
    let mut b = new_buf();
    let h = initialized(&mut b);
    let mut grads = [0.0; 64];
    unsafe {
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
    }
    assert_eq!(feed(h, &ORIGIN, 0.0), CAPSULE_MPC_OK);
    next(h, 0.02, &mut grads).unwrap();
    let rc = unsafe { capsule_mpc_set_sampling(h, CAPSULE_MPC_SAMPLING_VARIABLE) };
    assert_ne!(rc, CAPSULE_MPC_OK, "set_sampling after the loop started");
}

#[test]
fn target_speeds_must_be_zero() {
    let mut b = new_buf();
    let h = initialized(&mut b);
    for t in [[0.02, 0.01, -0.01, 0.0], [0.02, 0.0, -0.01, -1e-3]] {
        let rc = unsafe { capsule_mpc_set_target(h, t.as_ptr(), 4) };
        assert_ne!(rc, CAPSULE_MPC_OK, "target {t:?}");
    }
}

/// Time stamps that go backwards or jump by 1000 s are refused.
#[test]
fn implausible_time_stamps_are_refused() {
    let mut grads = [0.0; 64];
    for (what, bad_t) in [("backwards", 0.01), ("+1000 s", 1000.0)] {
        let mut b = new_buf();
        let h = initialized(&mut b);
        unsafe {
            assert_eq!(
                capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
                CAPSULE_MPC_OK
            );
        }
        assert_eq!(feed(h, &ORIGIN, 0.0), CAPSULE_MPC_OK);
        next(h, 0.02, &mut grads).unwrap();
        assert_eq!(feed(h, &ORIGIN, 0.04), CAPSULE_MPC_OK);
        next(h, 0.06, &mut grads).unwrap();
        let rc = feed(h, &ORIGIN, bad_t);
        let refused = rc != CAPSULE_MPC_OK || next(h, bad_t + 0.02, &mut grads).is_err();
        assert!(refused, "{what}: measurement time {bad_t} s accepted");
    }
}

// ---- a host with its own plant ----

const G: [f64; 2] = [173.25, 173.25];
const B: [f64; 2] = [134.7, 16.84];

fn deriv(s: &[f64; 4], u: f64) -> [f64; 4] {
    let mut d = [0.0; 4];
    for i in 0..2 {
        let v = s[2 * i + 1];
        d[2 * i] = v;
        d[2 * i + 1] = -B[i] * v * v.abs() + G[i] * u;
    }
    d
}

/// Holds `u` for `duration_s` in 1 ms RK4 steps.
fn hold(s: &mut [f64; 4], u: f64, duration_s: f64) {
    let steps = (duration_s / 1e-3).round() as usize;
    let h = 1e-3;
    let add =
        |a: &[f64; 4], k: &[f64; 4], c: f64| std::array::from_fn::<f64, 4, _>(|j| a[j] + c * k[j]);
    for _ in 0..steps {
        let k1 = deriv(s, u);
        let k2 = deriv(&add(s, &k1, h / 2.0), u);
        let k3 = deriv(&add(s, &k2, h / 2.0), u);
        let k4 = deriv(&add(s, &k3, h), u);
        for j in 0..4 {
            s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
    }
}

/// Runs scenario C through the C ABI for `end_s` with tracking phases of
/// `tracking_s(cycle)`, frames `glitch(t_measured)` m off the truth.
/// Returns the plant state over time (t, state) at every actuation start
/// and end, and the statuses.
fn host_loop(
    mode: i32,
    end_s: f64,
    tracking_s: impl Fn(usize) -> f64,
    glitch: impl Fn(f64) -> f64,
) -> (Vec<(f64, [f64; 4])>, Vec<i32>) {
    let mut b = new_buf();
    let h = initialized(&mut b);
    unsafe {
        assert_eq!(capsule_mpc_set_sampling(h, mode), CAPSULE_MPC_OK);
        assert_eq!(
            capsule_mpc_set_target(h, TARGET_C.as_ptr(), 4),
            CAPSULE_MPC_OK
        );
    }
    let mut grads = [0.0; 64];
    let (mut s, mut t) = ([0.0; 4], 0.0);
    let mut trace = vec![(t, s)];
    let mut statuses = Vec::new();
    let mut cycle = 0;
    while t < end_s - 1e-9 {
        let off = glitch(t);
        let z = [s[0] + off, s[2] + off];
        let t_meas = t;
        let tr = tracking_s(cycle);
        hold(&mut s, 0.0, tr);
        t += tr;
        assert_eq!(feed(h, &z, t_meas), CAPSULE_MPC_OK);
        let (samples, status) = next(h, t, &mut grads).unwrap();
        statuses.push(status);
        for &u in &grads[..samples as usize] {
            assert!(u.abs() <= 0.04);
            hold(&mut s, u, SAMPLE_S);
            t += SAMPLE_S;
            trace.push((t, s));
        }
        cycle += 1;
    }
    (trace, statuses)
}

/// Earliest trace time after which every position stays within 1 mm of C
/// and every speed below 5 mm/s.
fn settle_time(trace: &[(f64, [f64; 4])]) -> Option<f64> {
    let out = |s: &[f64; 4]| {
        (s[0] - TARGET_C[0]).abs() > 1e-3
            || (s[2] - TARGET_C[2]).abs() > 1e-3
            || s[1].abs() >= 5e-3
            || s[3].abs() >= 5e-3
    };
    match trace.iter().rposition(|(_, s)| out(s)) {
        None => Some(0.0),
        Some(i) if i + 1 < trace.len() => Some(trace[i + 1].0),
        Some(_) => None,
    }
}

/// The report: settled, then 10 frames 5 cm off (constant
/// sampling): the loop must be settled again within 3 s of the last bad
/// frame, not braking for good.
#[test]
fn a_glitch_after_settling_is_recovered_through_the_c_abi() {
    for mode in [CAPSULE_MPC_SAMPLING_CONSTANT, CAPSULE_MPC_SAMPLING_VARIABLE] {
        // The first 10 frames measured from 3 s on are 5 cm off.
        let count = std::cell::Cell::new(0usize);
        let last_bad_s = std::cell::Cell::new(f64::NAN);
        let glitch = |t: f64| {
            if t >= 3.0 - 1e-9 && count.get() < 10 {
                count.set(count.get() + 1);
                last_bad_s.set(t);
                0.05
            } else {
                0.0
            }
        };
        let (trace, statuses) = host_loop(mode, 8.0, |_| 0.02, glitch);
        let settle = settle_time(&trace);
        let fallbacks = statuses
            .iter()
            .rev()
            .take(25)
            .filter(|&&s| s == CAPSULE_MPC_STATUS_FALLBACK)
            .count();
        let last_bad_s = last_bad_s.get();
        assert!(
            settle.is_some_and(|s| s <= last_bad_s + 3.0),
            "mode {mode}: last bad frame {last_bad_s} s, settled {settle:?}, final {:?}, fallback in {fallbacks} of the last 25 cycles",
            trace.last().unwrap().1
        );
    }
}

/// Correctly time-stamped 40 and 60 ms tracking phases, and phases that
/// jitter between 10 and 60 ms: the loop settles.
#[test]
fn longer_and_jittering_tracking_phases_settle_through_the_c_abi() {
    for mode in [CAPSULE_MPC_SAMPLING_CONSTANT, CAPSULE_MPC_SAMPLING_VARIABLE] {
        for (what, tracking) in [
            ("40 ms", &(|_| 0.04) as &dyn Fn(usize) -> f64),
            ("60 ms", &|_| 0.06),
            ("10-60 ms", &|k: usize| {
                0.01 + 0.01 * ((k * 7 + 3) % 6) as f64
            }),
        ] {
            let (trace, _) = host_loop(mode, 6.0, tracking, |_| 0.0);
            let settle = settle_time(&trace);
            assert!(
                settle.is_some_and(|s| s <= 5.0),
                "mode {mode}, tracking {what}: settled {settle:?}, final {:?}",
                trace.last().unwrap().1
            );
        }
    }
}
