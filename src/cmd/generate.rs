//! `capsule-mpc generate`: solve the tables, emit the solver crate, or check
//! that the committed crate is what the generator produces.

use crate::cli::{load_config, GenerateArgs};
use anyhow::{bail, Context, Result};
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::emit::qp_max_iterations;
use capsule_mpc_generator::explicit::explicit_step_ops;
use capsule_mpc_generator::generate::{
    differences, emit_module_files, generate_module, write_atomically, ControllerModule,
    GeneratedFiles,
};
use capsule_mpc_generator::model::Model;
use capsule_mpc_generator::shard::{compute_shard, merge_parts, ShardSpec, Sharding};
use capsule_mpc_generator::table_file;
use capsule_mpc_generator::tables::Progress;
use capsule_mpc_sim::qp_map;
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Mutex;
use std::time::Instant;

/// An indicatif bar per generator phase (hidden when stderr is not a terminal).
struct Bar(Mutex<Option<ProgressBar>>);

impl Progress for Bar {
    fn start(&self, phase: &str, total: usize) {
        let bar = ProgressBar::new(total as u64);
        bar.set_style(
            ProgressStyle::with_template("{msg:32} [{bar:40}] {pos}/{len} ({elapsed})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_message(phase.to_string());
        if let Some(old) = self.0.lock().expect("progress lock").replace(bar) {
            old.finish();
        }
    }
    fn tick(&self) {
        if let Some(bar) = self.0.lock().expect("progress lock").as_ref() {
            bar.inc(1);
        }
    }
}

impl Bar {
    fn finish(&self) {
        if let Some(bar) = self.0.lock().expect("progress lock").take() {
            bar.finish();
        }
    }
}

pub fn run(args: &GenerateArgs) -> Result<()> {
    let module = ControllerModule::from(args.module);
    let config = match &args.config {
        Some(_) => load_config(args.config.as_deref())?,
        None => module.default_config(),
    };
    check_module_fits(module, &config)?;
    let started = Instant::now();
    let bar = Bar(Mutex::new(None));
    if args.rounds {
        let model = Model::from_config(&config);
        let sharding = Sharding::new(&config, &model);
        for r in 0..sharding.rounds().len() {
            eprintln!("{}", sharding.describe(r)?);
        }
        crate::out!("{}", sharding.rounds().len())?;
        return Ok(());
    }
    if !args.parts.is_empty() && args.shard.is_none() && !args.merge {
        bail!(
            "part files were given ({}, ...) without --shard or --merge",
            args.parts[0].display()
        );
    }
    if let Some(spec) = &args.shard {
        let shard: ShardSpec = spec.parse()?;
        let round = args.round.context("--shard needs --round R")?;
        let Some(out) = &args.out else {
            bail!("--shard {spec} needs --out PART, the part file to write");
        };
        let run = compute_shard(&config, round, shard, &args.parts, &bar)?;
        bar.finish();
        run.part.write(out)?;
        let slowest = run.unit_seconds.iter().copied().fold(0.0, f64::max);
        let busy: f64 = run.unit_seconds.iter().sum();
        crate::out!(
            "round {round}, shard {shard}: {} units in {:.1} s (unit times: sum {busy:.1} s, \
             slowest {slowest:.2} s), wrote {}",
            run.unit_seconds.len(),
            started.elapsed().as_secs_f64(),
            out.display()
        )?;
        return Ok(());
    }
    let out_dir = args.out.clone().unwrap_or_else(|| "generated".into());
    let mut files = if args.merge {
        if args.parts.is_empty() {
            bail!("--merge needs the part files of every round");
        }
        emit_module_files(module, &config, merge_parts(&config, &args.parts)?)?
    } else if args.reuse_tables && !args.check {
        let path = out_dir.join(module.tables_path());
        let tables = table_file::read(&path, &config).context("--reuse-tables")?;
        emit_module_files(module, &config, tables)?
    } else {
        generate_module(module, &config, &bar)?
    };
    bar.finish();
    if module == ControllerModule::Controller && !qp_map::fill_if_compiled(&mut files)? {
        eprintln!(
            "note: the emitted solver differs from the one compiled into this binary, so its \
             QP iteration map was left unmeasured; rebuild (`cargo build --release`) and run \
             `capsule-mpc generate --reuse-tables` to measure it"
        );
    }
    let elapsed = started.elapsed().as_secs_f64();
    let t = &files.tables;
    let table_bytes = files
        .files
        .iter()
        .find(|(p, _)| p.ends_with(module.tables_path()))
        .map_or(0, |(_, b)| b.len());
    if args.check {
        let diff = differences(&out_dir, &files);
        if !diff.is_empty() {
            let names: Vec<String> = diff.iter().map(|p| p.display().to_string()).collect();
            bail!(
                "{} differs from a fresh generation: {} (run `capsule-mpc generate`)",
                out_dir.display(),
                names.join(", ")
            );
        }
        crate::out!(
            "{} matches a fresh generation ({elapsed:.1} s)",
            out_dir.display()
        )?;
        return Ok(());
    }
    write_atomically(&out_dir, &files)?;
    crate::out!(
        "generated {} (module {}) in {elapsed:.1} s: {} plans ({} reach their target), {} index cells, {} {} bytes",
        out_dir.display(),
        module.module_name(),
        t.plans.len(),
        t.reached_count(),
        t.index.len(),
        module.tables_path(),
        table_bytes
    )?;
    print_explicit_tier(&config, &files)?;
    Ok(())
}

/// The explicit tier's data and its certified worst case (emitted as
/// `EXPLICIT_CERTIFIED_OPS`): operations of one step from the loop bounds
/// with the QP at its iteration cap.
fn print_explicit_tier(config: &Config, files: &GeneratedFiles) -> std::io::Result<()> {
    if files.explicit.samples.is_empty() {
        crate::out!("explicit tier: none in this module (refine = none is refused for it)")?;
        return Ok(());
    }
    let c = &config.controller;
    let nx = 2 * config.capsule_count();
    let cap = qp_max_iterations(c.horizon_steps);
    crate::out!(
        "explicit tier: {} samples, {} bytes; certified worst case {} floating-point operations per step ({} QP iterations at most)",
        files.explicit.samples.len(),
        files.explicit.bytes(c.horizon_steps, nx),
        explicit_step_ops(c.horizon_steps, nx, c.plan_steps, cap),
        cap
    )
}

/// The `three-capsules` module is named for its capsule count (the
/// `controller` module takes any count: users regenerate it for theirs).
fn check_module_fits(module: ControllerModule, config: &Config) -> Result<()> {
    let m = config.capsule_count();
    if module == ControllerModule::ThreeCapsules && m != 3 {
        bail!(
            "--config has {m} capsules; the `three-capsules` module is built for 3 \
             (regenerate the `controller` module for other counts)"
        );
    }
    Ok(())
}
