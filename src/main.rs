//! `capsule-mpc` command-line entry point.
//!
//! Errors end the program with exactly one line `error: <message>` on stderr
//! and exit code 1: scripts and users get the offending config field, never a
//! panic or a backtrace.

use capsule_mpc::cli::{Cli, Command};
use capsule_mpc::cmd;
use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        // A closed pipe (`inspect | head`) is the reader's choice, not an error.
        Err(e)
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            let message = e
                .chain()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(": ")
                .replace(['\r', '\n'], " ");
            eprintln!("error: {message}");
            ExitCode::from(1)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Inspect(args) => {
            let stdout = std::io::stdout();
            cmd::inspect::run(&args, &mut stdout.lock())?;
        }
        Command::Simulate(args) => cmd::simulate::run(&args)?,
        Command::Generate(args) => cmd::generate::run(&args)?,
        Command::Bench(args) => cmd::bench::run(&args)?,
        Command::Figures(args) => cmd::figures::run(&args)?,
        Command::Reach(args) => cmd::reach::run(&args)?,
        Command::Calibrate(args) => cmd::calibrate::run(&args)?,
    }
    Ok(ExitCode::SUCCESS)
}
