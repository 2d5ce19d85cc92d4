//! The runtime's cycle calls never touch the heap: a counting global
//! allocator counts this thread's allocations while `set_target`,
//! `cycle_full_state`, `cycle` and `cycle_at` run along closed-loop trajectories of
//! scenarios A and C (the trajectories themselves are simulated first, with
//! the counter off). `capsule-mpc bench` reports `allocations_per_step` from
//! this test.

use capsule_mpc_generator::config::Config;
use capsule_mpc_runtime::controller::{Refine, Sampling as RtSampling};
use capsule_mpc_runtime::generated::controller::{spec, Solver};
use capsule_mpc_runtime::solver::Tier;
use capsule_mpc_runtime::DefaultController;
use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling, Scenario};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    /// Whether this thread counts, and its count (const-initialized: no
    /// allocation on first access).
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    // try_with: the thread-local may already be gone while a thread exits.
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note();
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `f` and returns its result and the allocations it made on this thread.
fn counted<R>(f: impl FnOnce() -> R) -> (R, usize) {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|on| on.set(true));
    let r = f();
    COUNTING.with(|on| on.set(false));
    (r, COUNT.with(|c| c.get()))
}

#[test]
fn counter_sees_allocations() {
    let (v, n) = counted(|| vec![1u8; 100]);
    assert_eq!(v.len(), 100);
    assert!(
        n >= 1,
        "the counting allocator counts nothing: the test below would prove nothing"
    );
    drop(v);
}

/// Scenario's target and the states of its ideal closed-loop run (simulated
/// with the counter off).
/// `x - target` (the solver works on the state relative to the target).
fn relative(x: &[f64; spec::NX], target: &[f64; spec::NX]) -> [f64; spec::NX] {
    core::array::from_fn(|j| x[j] - target[j])
}

fn trajectory(config: &Config, scenario: Scenario) -> ([f64; spec::NX], Vec<[f64; spec::NX]>) {
    let target_v = scenario.target_state();
    let target: [f64; spec::NX] = target_v.as_slice().try_into().unwrap();
    let opts = RunOptions::new(config, target_v, Sampling::Ideal);
    let report = run(config, &opts).expect("closed-loop run");
    let rows = report
        .x
        .iter()
        .map(|x| x.as_slice().try_into().unwrap())
        .collect();
    (target, rows)
}

#[test]
fn controller_cycles_do_not_allocate() {
    let config = Config::embedded_default();
    let mut total_calls = 0usize;
    for scenario in [Scenario::A, Scenario::C] {
        let (target, rows) = trajectory(&config, scenario);
        assert!(rows.len() > 50);

        // Ideal sampling: set_target + cycle_full_state along the trajectory.
        let mut settings = DefaultController::default_settings();
        settings.sampling = RtSampling::Ideal;
        let mut ctl = DefaultController::new(settings, &[0.0; spec::M]).unwrap();
        let (r, n) = counted(|| ctl.set_target(&target));
        r.unwrap();
        assert_eq!(n, 0, "set_target allocated");
        let (_, n) = counted(|| {
            for x in &rows {
                ctl.cycle_full_state(x).unwrap();
            }
        });
        assert_eq!(
            n,
            0,
            "cycle_full_state allocated {n} times over {} calls",
            rows.len()
        );
        total_calls += rows.len();

        // Measured positions (constant and variable sampling), incl. a lost frame.
        for sampling in [RtSampling::Constant, RtSampling::Variable] {
            let mut settings = DefaultController::default_settings();
            settings.sampling = sampling;
            let mut ctl = DefaultController::new(settings, &[0.0; spec::M]).unwrap();
            ctl.set_target(&target).unwrap();
            let positions: Vec<[f64; spec::M]> = rows
                .iter()
                .map(|x| core::array::from_fn(|i| x[2 * i]))
                .collect();
            let (_, n) = counted(|| {
                for (k, z) in positions.iter().enumerate() {
                    let z = if k % 17 == 5 { None } else { Some(&z[..]) };
                    ctl.cycle(z).unwrap();
                }
            });
            assert_eq!(n, 0, "cycle ({sampling:?}) allocated {n} times");
            total_calls += positions.len();

            // On the host's clock, tracking phases of 5-30 ms (cycle_at).
            ctl.reset(&[0.0; spec::M]).unwrap();
            let (_, n) = counted(|| {
                let mut t = 0.0;
                for (k, z) in positions.iter().enumerate() {
                    let z = if k % 17 == 5 { None } else { Some(&z[..]) };
                    let t_act = t + 0.005 * (1 + k % 6) as f64;
                    let out = ctl.cycle_at(z, t, t_act).unwrap();
                    t = t_act + out.actuation_samples as f64 * spec::DT_S;
                }
            });
            assert_eq!(n, 0, "cycle_at ({sampling:?}) allocated {n} times");
            total_calls += positions.len();
        }

        // The generated solver alone.
        let mut s = Solver::new();
        let (_, n) = counted(|| {
            for x in &rows {
                let e = relative(x, &target);
                s.shift(1);
                s.solve(&e);
            }
        });
        assert_eq!(n, 0, "Solver::solve allocated");
    }
    assert!(total_calls > 300);
}

/// Both tiers: the explicit tier alone (`refine = none`) and with each
/// refinement mode, through the controller and the solver's own calls.
#[test]
fn both_tiers_do_not_allocate() {
    let config = Config::embedded_default();
    for scenario in [Scenario::A, Scenario::C] {
        let (target, rows) = trajectory(&config, scenario);
        let mut explicit_cycles = 0;
        for refine in [Refine::None, Refine::Once, Refine::PerSample] {
            for sampling in [
                RtSampling::Ideal,
                RtSampling::Constant,
                RtSampling::Variable,
            ] {
                let mut settings = DefaultController::default_settings();
                settings.sampling = sampling;
                settings.refine = refine;
                let mut ctl = DefaultController::new(settings, &[0.0; spec::M]).unwrap();
                ctl.set_target(&target).unwrap();
                let (tiers, n) = counted(|| {
                    let mut explicit = 0;
                    for x in &rows {
                        let out = if sampling == RtSampling::Ideal {
                            ctl.cycle_full_state(x).unwrap()
                        } else {
                            let z: [f64; spec::M] = core::array::from_fn(|i| x[2 * i]);
                            ctl.cycle(Some(&z[..])).unwrap()
                        };
                        if out.solve.is_some_and(|r| r.tier == Tier::Explicit) {
                            explicit += 1;
                        }
                    }
                    explicit
                });
                assert_eq!(n, 0, "{refine:?} {sampling:?} allocated {n} times");
                explicit_cycles += tiers;
            }
        }
        assert!(
            explicit_cycles > 50,
            "the explicit tier produced only {explicit_cycles} plans"
        );
        let mut s = Solver::new();
        let (_, n) = counted(|| {
            for x in &rows {
                let e = relative(x, &target);
                s.solve_explicit(&e);
                s.adopt_explicit();
                s.shift(1);
            }
        });
        assert_eq!(n, 0, "Solver::solve_explicit allocated");
    }
}
