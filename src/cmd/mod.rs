//! One module per subcommand: each maps its parsed arguments
//! ([`crate::cli`]) to calls into the libraries and prints the result.

pub mod bench;
pub mod calibrate;
pub mod figures;
pub mod generate;
pub mod inspect;
pub mod reach;
pub mod simulate;
