//! `capsule-mpc bench`: the timings of the online step and the peers on the
//! same states (see [`crate::bench`]).

use crate::bench::harness::{measure, prototype_controller_with};
use crate::bench::reference::RefProblem;
use crate::bench::states::sample_states;
use crate::cli::BenchArgs;
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
