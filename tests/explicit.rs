//! The explicit tier against references on the same stored data: its plan
//! equals clarabel's solution of the stored window QP at the deviation;
//! the refinement never raises the true cost of the explicit plan; its
//! operation bound covers what it does.

// Per-component loops over the state mirror the math (e_j, d_j).
#![allow(clippy::needless_range_loop)]

use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::explicit::{
    build_explicit, dense_hessian, reference_box_qp, ExplicitTables, PlanSource,
};
use capsule_mpc_generator::table_file;
use capsule_mpc_runtime::generated::controller::spec::{K, M, NX};
use capsule_mpc_runtime::generated::controller::Spec;
use capsule_mpc_runtime::generated::controller::{spec, Solver, TABLES};
use capsule_mpc_runtime::solver::explicit::{self, explicit_state, ExplicitSample};
use capsule_mpc_runtime::solver::format::SCALAR_COAST_S as COAST;
use capsule_mpc_runtime::solver::format::{Section, NO_SLOT};
use capsule_mpc_runtime::solver::qp::BoxQp;
use capsule_mpc_runtime::solver::rollout::rollout_cost;
use capsule_mpc_runtime::solver::tables::PlanSet;
use capsule_mpc_runtime::solver::{lookup, PlanSolver, SolveStatus, Tier};
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::sync::OnceLock;

/// The generator's explicit data, rebuilt from the committed tables (the
/// emitted module is checked against it below).
fn generator_explicit() -> &'static ExplicitTables {
    static DATA: OnceLock<ExplicitTables> = OnceLock::new();
    DATA.get_or_init(|| {
        let config = Config::embedded_default();
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("generated/controller.tables.bin");
        let tables = table_file::read(&path, &config).expect("committed tables read");
        build_explicit(&config, &tables)
    })
}

fn stored_row(source: PlanSource, plan: usize) -> [f64; spec::K] {
    let set = match source {
        PlanSource::Main => PlanSet::BackToBack,
        PlanSource::Coasted => PlanSet::Coasted,
        PlanSource::Fine => PlanSet::Fine,
        PlanSource::CoastedFine => PlanSet::CoastedFine,
    };
    std::array::from_fn(|k| TABLES.plan_u(set, plan, k))
}

/// The emitted table file's kept index cells, slots and sample states.
fn index_cells() -> Vec<u64> {
    (0..TABLES.cell_count)
        .map(|c| TABLES.u64_at(Section::IndexCells, c))
        .collect()
}

fn slots(section: Section) -> Vec<u16> {
    (0..TABLES.elements(section))
        .map(|c| TABLES.u16_at(section, c))
        .collect()
}

fn sample_state(slot: usize) -> [f64; spec::NX] {
    std::array::from_fn(|j| explicit_state(&TABLES, slot, j))
}

#[test]
fn the_emitted_samples_are_the_generators() {
    let g = generator_explicit();
    assert_eq!(g.samples.len(), TABLES.explicit_count);
    assert_eq!(g.index_slot, slots(Section::ExplicitIndexSlot));
    assert_eq!(
        g.coasted_index_slot,
        slots(Section::CoastedExplicitIndexSlot)
    );
    assert_eq!(g.fine_slot, slots(Section::FineExplicitSlot));
    assert_eq!(g.coasted_fine_slot, slots(Section::CoastedFineExplicitSlot));
    for (slot, s) in g.samples.iter().enumerate() {
        let e = ExplicitSample::get(&TABLES, slot).expect("stored sample");
        assert_eq!(&s.state[..], &sample_state(slot)[..]);
        assert_eq!(s.source as u8, e.source());
        assert_eq!((s.plan, s.offset), (e.plan() as usize, e.offset() as usize));
        let hessian: Vec<f64> = (0..s.hessian.len()).map(|i| e.hessian(i)).collect();
        assert_eq!(s.hessian, hessian);
        let gradient: Vec<f64> = (0..spec::N).map(|a| e.gradient(a)).collect();
        assert_eq!(s.gradient, gradient);
        let sensitivity: Vec<f64> = (0..spec::N * spec::NX)
            .map(|i| e.sensitivity(i / spec::NX, i % spec::NX))
            .collect();
        assert_eq!(s.sensitivity, sensitivity);
        assert_eq!(s.cost, e.cost());
        assert_eq!(&s.active[..], &e.active::<{ spec::N }>()[..]);
    }
}

/// The explicit look-up on the sparse index against a plain reference: the
/// cell of `e` and its 2 NX axis neighbours on the dense grid, each looked
/// up among the kept cells (`INDEX_CELLS`, `binary_search`), cells not kept
/// skipped, the nearest named sample in index cells taken (first of equals
/// in the runtime's order). States moving (off the fine grid's rest test),
/// both schedules.
#[test]
fn explicit_lookup_matches_a_reference_over_the_kept_cells() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let axis = |j: usize| lookup::index_axis(&TABLES, j);
    let kept_cells = index_cells();
    let (slots_b2b, slots_coasted) = (
        slots(Section::ExplicitIndexSlot),
        slots(Section::CoastedExplicitIndexSlot),
    );
    let (mut found, mut not_kept, mut neighbours_only) = (0, 0, 0);
    for t in 0..20_000 {
        let coasted = t % 2 == 1;
        let slots: &[u16] = if coasted { &slots_coasted } else { &slots_b2b };
        // Half the states near a stored sample (where the kept cells are),
        // half anywhere on the grid.
        let mut e = [0.0; spec::NX];
        if t % 4 < 2 {
            let state = sample_state(rng.gen_range(0..TABLES.explicit_count));
            for j in 0..spec::NX {
                e[j] = state[j] + rng.gen_range(-1.5..1.5) * axis(j).step;
            }
        } else {
            for j in 0..spec::NX {
                let a = axis(j);
                let end = a.start + (a.count - 1) as f64 * a.step;
                e[j] = rng.gen_range(a.start..end);
            }
        }
        if e[1].abs() <= 0.01 {
            e[1] = 0.02; // off the fine grid's rest test
        }
        let idx: Option<Vec<usize>> = (0..spec::NX)
            .map(|j| lookup::axis_nearest(&axis(j), e[j]))
            .collect();
        let got = explicit::explicit_slot(&TABLES, &e, coasted, usize::MAX);
        let Some(idx) = idx else {
            assert_eq!(got, None, "outside the grid at {e:?}");
            continue;
        };
        let dims: Vec<u64> = (0..spec::NX).map(|j| axis(j).count as u64).collect();
        let flat_of = |idx: &[usize]| {
            idx.iter()
                .zip(&dims)
                .fold(0u64, |f, (&i, &n)| f * n + i as u64)
        };
        let mut cells = vec![idx.clone()];
        for j in (0..spec::NX).rev() {
            if idx[j] > 0 {
                let mut c = idx.clone();
                c[j] -= 1;
                cells.push(c);
            }
            if idx[j] + 1 < axis(j).count {
                let mut c = idx.clone();
                c[j] += 1;
                cells.push(c);
            }
        }
        let (mut best, mut best_d) = (None, f64::INFINITY);
        for (i, c) in cells.iter().enumerate() {
            let Ok(kept) = kept_cells.binary_search(&flat_of(c)) else {
                if i == 0 {
                    not_kept += 1;
                }
                continue;
            };
            let slot = slots[kept];
            if slot == NO_SLOT {
                continue;
            }
            let st = sample_state(slot as usize);
            let d: f64 = (0..spec::NX)
                .map(|j| ((e[j] - st[j]) / axis(j).step).powi(2))
                .sum();
            if d < best_d {
                best_d = d;
                best = Some(slot as usize);
            }
        }
        assert_eq!(got, best, "at {e:?}");
        if got.is_some() {
            found += 1;
            if kept_cells.binary_search(&flat_of(&idx)).is_err() {
                neighbours_only += 1;
            }
        }
    }
    eprintln!(
        "{found} states with a sample ({neighbours_only} from a neighbour only), {not_kept} in a cell not kept"
    );
    assert!(
        found > 5_000 && not_kept > 0,
        "{found} found, {not_kept} not kept"
    );
}

/// Explicit plan vs clarabel on the same stored QP, at random deviations
/// within a cell around random stored samples (both schedules).
#[test]
fn explicit_plan_matches_clarabel_on_the_stored_qp() {
    let g = generator_explicit();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(15);
    let mut qp = BoxQp::<{ spec::N }>::new(spec::QP_MAX_ITERATIONS, spec::QP_MULTIPLIER_TOLERANCE);
    let mut plan = [0.0; spec::K];
    let (mut checked, mut worst) = (0, 0.0_f64);
    for _ in 0..400 {
        let slot = rng.gen_range(0..g.samples.len());
        let s = &g.samples[slot];
        let coasted = s.source.coasted();
        let mut e = [0.0; spec::NX];
        for j in 0..spec::NX {
            let half = if j % 2 == 0 {
                0.5 * TABLES.index_position_axis.step
            } else {
                0.5 * TABLES.index_speed_axis.step
            };
            e[j] = s.state[j] + rng.gen_range(-half..half);
        }
        // The sample the runtime takes for e may be another: compare on the
        // one it takes.
        let Some(used) = explicit::explicit_slot(&TABLES, &e, coasted, usize::MAX) else {
            continue;
        };
        let out = explicit::explicit_plan(
            &TABLES,
            spec::U_MAX_T_PER_M,
            &e,
            coasted,
            usize::MAX,
            None,
            &mut qp,
            &mut plan,
        )
        .expect("in range");
        assert_eq!(out.slot, used);
        assert!(out.converged, "QP did not converge at slot {used}");
        let s = &g.samples[used];
        let n = spec::N;
        let row = stored_row(s.source, s.plan);
        let u: Vec<f64> = (0..spec::K)
            .map(|i| {
                if s.offset + i < spec::K {
                    row[s.offset + i]
                } else {
                    0.0
                }
            })
            .collect();
        let d: Vec<f64> = (0..spec::NX).map(|j| e[j] - s.state[j]).collect();
        let grad: Vec<f64> = (0..n)
            .map(|a| {
                (0..spec::NX)
                    .map(|j| s.sensitivity[a * spec::NX + j] * d[j])
                    .sum::<f64>()
            })
            .collect();
        let lo: Vec<f64> = (0..n).map(|a| -spec::U_MAX_T_PER_M - u[a]).collect();
        let hi: Vec<f64> = (0..n).map(|a| spec::U_MAX_T_PER_M - u[a]).collect();
        let x = reference_box_qp(&dense_hessian(s, n), &grad, &lo, &hi).expect("clarabel solves");
        let h = dense_hessian(s, n);
        let obj = |x: &[f64]| -> f64 {
            (0..n)
                .map(|a| x[a] * (grad[a] + 0.5 * (0..n).map(|b| h[a][b] * x[b]).sum::<f64>()))
                .sum()
        };
        let mut diff = 0.0_f64;
        for a in 0..n {
            let reference = (u[a] + x[a]).clamp(-spec::U_MAX_T_PER_M, spec::U_MAX_T_PER_M);
            diff = diff.max((plan[a] - reference).abs());
        }
        if diff > 1e-6 {
            eprintln!(
                "slot {used}: diff {diff:.2e} obj ours {:.12e} clarabel {:.12e} iters {}",
                obj(&qp.x),
                obj(&x),
                out.qp_iterations
            );
        }
        worst = worst.max(diff);
        for i in n..spec::K {
            assert_eq!(
                plan[i], u[i],
                "the tail beyond the window is the stored one"
            );
        }
        checked += 1;
    }
    eprintln!("{checked} explicit plans, worst difference to clarabel {worst:.2e} T/m");
    assert!(
        checked >= 300,
        "only {checked} states fell in a cell with a sample"
    );
    assert!(
        worst <= 1e-6,
        "explicit plan differs from clarabel by {worst:e} T/m"
    );
}

/// Refinement after the explicit tier: the returned plan's true cost is
/// never above the explicit plan's (rolled out here independently).
#[test]
fn refinement_never_raises_the_true_cost() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
    let schedules = [
        (spec::K, 0.0),
        (1, TABLES.scalar(COAST)),
        (spec::N, TABLES.scalar(COAST)),
    ];
    let mut compared = 0;
    let mut refined_won = 0;
    for t in 0..600 {
        let (samples, coast) = schedules[t % 3];
        let sched = Solver::schedule_for(samples, coast);
        let mut s = Solver::new();
        s.set_schedule(samples, coast);
        let mut e = [0.0; spec::NX];
        for j in 0..spec::NX {
            e[j] = if j % 2 == 0 {
                rng.gen_range(-0.04..0.04)
            } else {
                rng.gen_range(-0.25..0.25)
            };
        }
        // Half the trials with a previous plan (a shifted explicit one).
        if t % 2 == 1 && s.solve_explicit(&e).status != SolveStatus::OutOfRange {
            s.adopt_explicit();
            s.shift(1);
        }
        let x = s.solve_explicit(&e);
        if x.status == SolveStatus::OutOfRange {
            continue;
        }
        let explicit_cost = rollout_cost::<Spec, M, NX, K>(&e, s.explicit_plan(), &sched);
        let r = s.solve(&e);
        let refined_cost = rollout_cost::<Spec, M, NX, K>(&e, s.plan(), &sched);
        assert_eq!(
            r.cost, refined_cost,
            "the report's cost is the plan's true cost"
        );
        assert!(
            refined_cost <= explicit_cost,
            "refinement raised the cost: {refined_cost} > {explicit_cost} at {e:?}"
        );
        if r.tier == Tier::Explicit {
            assert_eq!(
                s.plan(),
                s.explicit_plan(),
                "tier Explicit means the explicit plan"
            );
        } else {
            refined_won += 1;
        }
        compared += 1;
    }
    eprintln!("{compared} states compared, refinement cheaper in {refined_won}");
    assert!(compared >= 200, "only {compared} states in range");
}

/// The emitted bound is the operation count at the QP's iteration cap, and
/// every explicit step over the bench's states (seed 1, as `capsule-mpc
/// bench`, plus the closed-loop states) stays within it: its iteration
/// count never passes the cap, and the count it reports is the one its
/// operations are bounded by.
#[test]
fn certified_operation_bound_covers_the_bench_states() {
    use capsule_mpc_generator::explicit::explicit_step_ops;
    let certified = <Solver as PlanSolver<{ spec::NX }, { spec::K }>>::EXPLICIT_CERTIFIED_OPS;
    assert_eq!(
        certified,
        explicit_step_ops(spec::N, spec::NX, spec::K, spec::QP_MAX_ITERATIONS)
    );
    let config = Config::embedded_default();
    let states = capsule_mpc::bench::states::sample_states(&config, 20_000, 1).expect("states");
    let (mut solved, mut most) = (0, 0u32);
    for st in &states {
        let mut s = Solver::new();
        if s.solve_explicit(&st.e).status == SolveStatus::OutOfRange {
            continue;
        }
        s.adopt_explicit();
        let e1 = Solver::predict_plan(&st.e, s.plan(), 1);
        s.shift(1);
        for r in [s.solve_explicit(&st.e), s.solve_explicit(&e1)] {
            if r.status == SolveStatus::OutOfRange {
                continue;
            }
            let ops = explicit_step_ops(spec::N, spec::NX, spec::K, r.max_qp_iterations as usize);
            assert!(
                ops <= certified,
                "{} QP iterations: {ops} operations above the certified {certified}",
                r.max_qp_iterations
            );
            most = most.max(r.max_qp_iterations);
            solved += 1;
        }
    }
    eprintln!("{solved} explicit steps, most QP iterations {most}");
    assert!(solved > 20_000, "only {solved} explicit steps in range");
    assert!(
        most > 1,
        "every QP took one iteration: the bound was not exercised"
    );
}

/// The explicit tier alone in the closed loop, as measured (docs/results.md,
/// "The explicit tier alone"): ideal sampling, no disturbance. The tier
/// follows the stored plan it started on (each named sample's successors
/// are stored up to the plan's last input): A settles in 0.519 s, within
/// issue 15's 10 % of the refined 0.499 s, and C in 0.750 s (refined
/// 0.679 s). Asserted: those with a small margin, no refinement ran, and
/// the refinement still settles A.
#[test]
fn explicit_tier_alone_closed_loop_as_measured() {
    use capsule_mpc_generator::config::RefineMode;
    use capsule_mpc_sim::closed_loop::{run, RunOptions, Sampling, Scenario};
    let config = Config::embedded_default();
    let run_with = |scenario: Scenario, refine: RefineMode| {
        let mut opts = RunOptions::new(&config, scenario.target_state(), Sampling::Ideal);
        opts.refine = refine;
        run(&config, &opts).expect("closed-loop run")
    };
    let a = run_with(Scenario::A, RefineMode::None);
    let first = a
        .metrics
        .first_in_band_s
        .expect("A reaches the band with the explicit tier alone");
    assert!(first <= 0.75, "A reached the band at {first} s");
    let settle = a
        .metrics
        .settle_time_s
        .expect("A settles with the explicit tier alone");
    assert!(settle <= 0.55, "A settled at {settle} s");
    assert!(
        a.metrics.final_position_error_m < 1e-3,
        "A ends {} m off",
        a.metrics.final_position_error_m
    );
    let tiers = a.tier_cycles.expect("tier counts");
    assert_eq!(tiers.refined, 0, "refine none ran the refinement");
    let c = run_with(Scenario::C, RefineMode::None);
    let settle_c = c
        .metrics
        .settle_time_s
        .expect("C settles with the explicit tier alone");
    assert!(settle_c <= 0.8, "C settled at {settle_c} s");
    let refined = run_with(Scenario::A, RefineMode::PerSample);
    let settle_refined = refined.metrics.settle_time_s.expect("A settles refined");
    assert!(
        settle_refined < 0.55,
        "refined A settled at {settle_refined} s"
    );
}
