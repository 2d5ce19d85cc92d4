//! Argument checks that name what is wrong: positions inside the
//! workspace, frames of the right length.

use super::status::RuntimeError;
use capsule_mpc_solver::PlanSolver;

/// Positions of `x` (every `stride`-th entry: 1 for positions only, 2 for
/// a full state) must lie in the solver's workspace.
pub fn check_workspace<S: PlanSolver<NX, K>, const NX: usize, const K: usize>(
    argument: &'static str,
    x: &[f64],
    stride: usize,
) -> Result<(), RuntimeError> {
    for (capsule, &p) in x.iter().step_by(stride).enumerate() {
        let excess_m = if p < S::WORKSPACE_MIN_M {
            p - S::WORKSPACE_MIN_M
        } else if p > S::WORKSPACE_MAX_M {
            p - S::WORKSPACE_MAX_M
        } else {
            continue;
        };
        return Err(RuntimeError::OutsideWorkspace {
            argument,
            capsule,
            excess_m,
        });
    }
    Ok(())
}

/// `WrongLength("measured_positions_m")` unless a frame has M positions.
pub(super) fn check_frame_length<const NX: usize>(z: Option<&[f64]>) -> Result<(), RuntimeError> {
    match z {
        Some(z) if z.len() != NX / 2 => Err(RuntimeError::WrongLength("measured_positions_m")),
        _ => Ok(()),
    }
}
