//! Standard output of the commands. `println!` panics when the reader has
//! closed the pipe (`capsule-mpc simulate ... | head -1`); `out!` drops the
//! line instead and carries on, so that the command still writes its files
//! (`--json`, `--plot`) and exits 0. Other write errors are returned.

use std::fmt;
use std::io::{self, Write};

/// Writes one line to stdout like `println!`; `io::Result<()>`, a closed
/// pipe counting as success.
#[macro_export]
macro_rules! out {
    () => {
        $crate::out::line(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::out::line(format_args!($($arg)*))
    };
}

/// The line `args` on stdout (see [`out!`]).
pub fn line(args: fmt::Arguments) -> io::Result<()> {
    match writeln!(io::stdout().lock(), "{args}") {
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        r => r,
    }
}
