//! Literals of the emitted code, and the emitter's errors: a float is
//! written so that it round-trips exactly, and a value that is not finite is
//! refused with its name.

use proc_macro2::Literal;

/// A float literal that round-trips exactly; refuses non-finite values.
pub(super) fn float(name: &str, v: f64) -> Result<Literal, EmitError> {
    if !v.is_finite() {
        return Err(EmitError::NonFinite {
            name: name.to_string(),
            value: v,
        });
    }
    Ok(Literal::f64_unsuffixed(v))
}

pub(super) fn floats(name: &str, vs: &[f64]) -> Result<Vec<Literal>, EmitError> {
    vs.iter().map(|&v| float(name, v)).collect()
}

#[derive(Debug, thiserror::Error)]
pub enum EmitError {
    #[error("cannot emit `{name}`: value {value} is not finite")]
    NonFinite { name: String, value: f64 },
    #[error("emitted code does not parse: {0}")]
    Parse(String),
}
