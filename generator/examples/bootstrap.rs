//! Generates the solver crate with the generator alone, for when the
//! template's interface changed and the `capsule-mpc` binary (which links
//! the old generated crate) cannot be built:
//!
//!     cargo run --release -p capsule-mpc-generator --example bootstrap [CONFIG] [OUT] [--reuse-tables] [--three-capsules]
//!
//! (`--reuse-tables`: re-emit from the module's tables in OUT when only the
//! templates changed; `--three-capsules`: the `three_capsules` module, from
//! configs/three-capsules.toml unless CONFIG is given)
//! then `cargo build --release` and `capsule-mpc generate --reuse-tables`
//! to measure the QP iteration map.

use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::generate::{
    emit_module_files, generate_module, write_atomically, ControllerModule,
};
use capsule_mpc_generator::tables::{Progress, Tables};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Prints each phase and every tenth of its progress.
struct Log {
    done: AtomicUsize,
    total: AtomicUsize,
    started: Instant,
}

impl Progress for Log {
    fn start(&self, phase: &str, total: usize) {
        self.done.store(0, Ordering::Relaxed);
        self.total.store(total, Ordering::Relaxed);
        eprintln!(
            "{:7.1} s  {phase}: {total}",
            self.started.elapsed().as_secs_f64()
        );
    }
    fn tick(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let total = self.total.load(Ordering::Relaxed).max(1);
        if done * 10 / total != (done - 1) * 10 / total {
            eprintln!(
                "{:7.1} s    {done}/{total}",
                self.started.elapsed().as_secs_f64()
            );
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let all: Vec<String> = std::env::args().skip(1).collect();
    let reuse = all.iter().any(|a| a == "--reuse-tables");
    let module = match all.iter().any(|a| a == "--three-capsules") {
        true => ControllerModule::ThreeCapsules,
        false => ControllerModule::Controller,
    };
    let mut args = all.into_iter().filter(|a| !a.starts_with("--"));
    let config = match args.next() {
        Some(path) => Config::from_file(std::path::Path::new(&path))?,
        None => module.default_config(),
    };
    let out = PathBuf::from(args.next().unwrap_or_else(|| "generated".to_string()));
    let log = Log {
        done: AtomicUsize::new(0),
        total: AtomicUsize::new(0),
        started: Instant::now(),
    };
    let files = if reuse {
        let tables = Tables::read(&out.join(module.tables_path()), &config)?;
        emit_module_files(module, &config, tables)?
    } else {
        generate_module(module, &config, &log)?
    };
    write_atomically(&out, &files)?;
    let t = &files.tables;
    println!(
        "generated {} in {:.1} s: {} plans ({} reached), {} index cells",
        out.display(),
        log.started.elapsed().as_secs_f64(),
        t.plans.len(),
        t.reached_count(),
        t.index.len()
    );
    Ok(())
}
