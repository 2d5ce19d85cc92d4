//! `capsule-mpc figures`: every figure of the report, one line per figure.

use crate::cli::FiguresArgs;
use crate::figures::all_figures;
use anyhow::Result;

/// Writes the figures into `--out` and prints one line per figure.
pub fn run(args: &FiguresArgs) -> Result<()> {
    for f in all_figures(&args.out, args.duration)? {
        crate::out!("{}", f.describe())?;
    }
    Ok(())
}
