//! Emission of the explicit tier's data (`explicit_tables` in a controller
//! module; see `crate::explicit`).

use super::literal::{float, floats, EmitError};
use crate::explicit::{explicit_step_ops, ExplicitTables, NO_SLOT};
use proc_macro2::{Literal, TokenStream};
use quote::quote;

/// The `explicit_tables` module. `explicit` is None for a controller
/// without an explicit tier (the paper preset, which has no tables, and
/// `three_capsules`): no samples and empty slot arrays (the template reads
/// them with `get`, so a missing slot is no sample), so
/// `HAS_EXPLICIT_TIER` is false. Otherwise the slot arrays parallel the
/// kept cells of the sparse index (`INDEX_CELLS`) and the fine grid.
pub fn emit_explicit_tables(
    explicit: Option<&ExplicitTables>,
    n: usize,
    nx: usize,
    k: usize,
    qp_max_iterations: usize,
) -> Result<TokenStream, EmitError> {
    let empty = ExplicitTables::default();
    let t = explicit.unwrap_or(&empty);
    let samples = t
        .samples
        .iter()
        .map(|s| {
            let source = s.source as u8;
            let plan = u16::try_from(s.plan).expect("plan index fits u16");
            let offset = u16::try_from(s.offset).expect("offset fits u16");
            let hessian = floats("explicit hessian", &s.hessian)?;
            let gradient = floats("explicit gradient", &s.gradient)?;
            let sensitivity = matrix_rows("explicit sensitivity", &s.sensitivity, nx)?;
            let active = s.active.iter().map(|&a| Literal::i8_unsuffixed(a));
            let next = s.next;
            let cost = float("explicit cost", s.cost)?;
            let cost_gradient = floats("explicit cost gradient", &s.cost_gradient)?;
            let cost_hessian = matrix_rows("explicit cost hessian", &s.cost_hessian, nx)?;
            Ok(quote! {
                ExplicitSample {
                    source: #source, plan: #plan, offset: #offset,
                    hessian: [#(#hessian),*],
                    gradient: [#(#gradient),*],
                    sensitivity: [#(#sensitivity),*],
                    active: [#(#active),*],
                    cost: #cost,
                    cost_gradient: [#(#cost_gradient),*],
                    cost_hessian: [#(#cost_hessian),*],
                    next: #next,
                }
            })
        })
        .collect::<Result<Vec<_>, EmitError>>()?;
    let states = t
        .samples
        .iter()
        .map(|s| {
            let state = floats("explicit state", &s.state)?;
            Ok(quote! { [#(#state),*] })
        })
        .collect::<Result<Vec<_>, EmitError>>()?;
    let count = samples.len();
    let index_slot = &t.index_slot;
    let coasted_index_slot = &t.coasted_index_slot;
    let fine_slot = &t.fine_slot;
    let coasted_fine_slot = &t.coasted_fine_slot;
    let (cells, fine) = (index_slot.len(), fine_slot.len());
    let bytes = t.bytes(n, nx);
    let ops = explicit_step_ops(n, nx, k, qp_max_iterations);
    Ok(quote! {
        /// The explicit tier's data: the window QP of every stored plan
        /// sample the index (or the fine grid) names, linearized offline
        /// around that sample (see `capsule-mpc-generator`'s `explicit`).
        pub mod explicit_tables {
            use super::spec::{N, NX};
            /// Entries of an N x N symmetric matrix's upper triangle.
            pub const HESSIAN_LEN: usize = N * (N + 1) / 2;
            /// One stored sample's window QP as a function of the deviation
            /// d = e - state: min 1/2 x'Hx + (sensitivity d)'x over the
            /// window's input changes x (tracking the stored trajectory; SI,
            /// the cost halved as in the refinement's QP).
            #[derive(Debug, Clone, Copy)]
            pub struct ExplicitSample {
                /// Plan table: 0 back to back, 1 constant sampling, 2 fine,
                /// 3 fine with the coast.
                pub source: u8,
                pub plan: u16,
                /// Plan sample the window starts at (its relative state,
                /// the linearization point, is `EXPLICIT_STATE[slot]`).
                pub offset: u16,
                /// Condensed Hessian, upper triangle row by row.
                pub hessian: [f64; HESSIAN_LEN],
                /// Gradient of the online cost in the window inputs at zero
                /// deviation (for the cost prediction).
                pub gradient: [f64; N],
                /// d gradient / d deviation.
                pub sensitivity: [[f64; NX]; N],
                /// Active set of the solution at zero deviation (-1, 0, +1).
                pub active: [i8; N],
                /// Nonlinear cost of the stored tail from `state`.
                pub cost: f64,
                /// Gauss-Newton model of that cost in d (halved, as the QP).
                pub cost_gradient: [f64; NX],
                pub cost_hessian: [[f64; NX]; NX],
                /// Slot of the same plan's next sample (NO_SLOT: not stored).
                pub next: u16,
            }
            /// Number of stored samples.
            pub const EXPLICIT_COUNT: usize = #count;
            /// Slot value of a cell without a sample.
            pub const NO_SLOT: u16 = #NO_SLOT;
            pub static EXPLICIT: [ExplicitSample; EXPLICIT_COUNT] = [#(#samples),*];
            /// Every sample's relative state (its linearization point),
            /// apart from the sample: the candidate search compares up to
            /// 2 NX + 2 of them per step, and 32-byte rows stay in cache
            /// where 1 kB samples do not.
            pub static EXPLICIT_STATE: [[f64; NX]; EXPLICIT_COUNT] = [#(#states),*];
            /// Per kept cell of the sparse warm-start index (parallel to
            /// `tables::INDEX_CELLS`; empty without an explicit tier): the
            /// slot of its sample (back to back, and constant sampling's).
            pub static EXPLICIT_INDEX_SLOT: [u16; #cells] = [#(#index_slot),*];
            pub static COASTED_EXPLICIT_INDEX_SLOT: [u16; #cells] = [#(#coasted_index_slot),*];
            /// Per fine grid point: the slot of its plan's first sample.
            pub static FINE_EXPLICIT_SLOT: [u16; #fine] = [#(#fine_slot),*];
            pub static COASTED_FINE_EXPLICIT_SLOT: [u16; #fine] = [#(#coasted_fine_slot),*];
            /// Bytes of the arrays above.
            pub const EXPLICIT_TABLE_BYTES: usize = #bytes;
            /// Certified worst case of one explicit step: floating-point
            /// operations counted from the loop bounds with the QP at its
            /// iteration cap (`QP_MAX_ITERATIONS`), every iteration at its
            /// worst (all variables free, the factor rebuilt).
            pub const EXPLICIT_CERTIFIED_OPS: u64 = #ops;
        }
    })
}

/// A row-major matrix with `cols` columns as nested array literals.
fn matrix_rows(name: &str, flat: &[f64], cols: usize) -> Result<Vec<TokenStream>, EmitError> {
    flat.chunks(cols)
        .map(|row| {
            let r = floats(name, row)?;
            Ok(quote! { [#(#r),*] })
        })
        .collect()
}
