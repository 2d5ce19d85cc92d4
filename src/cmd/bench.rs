//! `capsule-mpc bench`: the timings of the online step and the peers on the
//! same states (see [`crate::bench`]).

use crate::bench::harness::{measure, prototype_controller_with};
use crate::bench::module_steps;
use crate::bench::reference::RefProblem;
use crate::bench::states::sample_states;
use crate::cli::{load_config, BenchArgs};
use anyhow::{bail, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_sim::closed_loop::Sampling;
use capsule_mpc_sim::report::write_json_atomic;
use serde_json::json;

/// `capsule-mpc bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    if args.states == 0 {
        bail!("--states must be at least 1");
    }
    if let Some(path) = &args.config {
        return run_module(args, path);
    }
    let config = Config::embedded_default();
    let problem = RefProblem::from_config(&config)?;
    let mismatch = problem.spec_mismatch();
    if mismatch > 1e-9 {
        eprintln!(
            "warning: the embedded config differs from the generated spec (relative {mismatch:.1e}); peers use the config"
        );
    }
    eprintln!(
        "bench: sampling {} states (seed {})",
        args.states, args.seed
    );
    let states = sample_states(&config, args.states, args.seed)?;
    let sampling = Sampling::from(args.sampling);
    let proto = prototype_controller_with(sampling.runtime())?;
    let peer_count = args.peer_states.min(states.len());
    let result = std::thread::scope(|scope| {
        scope
            .spawn(|| measure(&states, &proto, &problem, peer_count))
            .join()
            .map_err(|_| anyhow::anyhow!("the benchmark thread panicked"))
    })??;
    let mut report = result;
    report["states"] = json!(states.len());
    report["seed"] = json!(args.seed);
    report["sampling"] = json!(sampling.name());
    report["spec_mismatch"] = json!(mismatch);
    if let Some(path) = &args.json {
        write_json_atomic(path, &report)?;
    }
    Ok(())
}

/// `capsule-mpc bench --config FILE`: the controller step of the compiled
/// module generated for that config (see [`crate::bench::module_steps`]).
fn run_module(args: &BenchArgs, path: &std::path::Path) -> Result<()> {
    use capsule_mpc_generator::generate::ControllerModule;
    use capsule_mpc_runtime::generated::{controller, three_capsules};
    use capsule_mpc_sim::closed_loop::compiled_controller_for;
    let config = load_config(Some(path))?;
    let module = compiled_controller_for(&config)?;
    let sampling = Sampling::from(args.sampling);
    eprintln!(
        "bench: {} states of module `{}` (seed {})",
        args.states,
        module.module_name(),
        args.seed
    );
    // One arm per compiled module: the module's solver, sizes and tables.
    macro_rules! measure {
        ($m:ident) => {
            module_steps::measure::<$m::Solver, { $m::spec::NX }, { $m::spec::K }>(
                &config,
                &$m::TABLES,
                sampling.runtime(),
                args.states,
                args.seed,
            )
        };
    }
    let mut report = std::thread::scope(|scope| {
        scope
            .spawn(|| match module {
                ControllerModule::Controller => measure!(controller),
                ControllerModule::ThreeCapsules => measure!(three_capsules),
            })
            .join()
            .map_err(|_| anyhow::anyhow!("the benchmark thread panicked"))
    })??;
    report["states"] = json!(args.states);
    report["seed"] = json!(args.seed);
    report["sampling"] = json!(sampling.name());
    report["module"] = json!(module.module_name());
    if let Some(path) = &args.json {
        write_json_atomic(path, &report)?;
    }
    Ok(())
}
