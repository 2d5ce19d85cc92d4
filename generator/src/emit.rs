//! Emission of the specialized solver crate (`generated/`).
//!
//! Constants, the drag law and the tables are written with `quote`; the code
//! comes from `templates/` (`qp.rs` the window QP, `lookup.rs` the table
//! lookups, `solver.rs` the refinement, `explicit.rs` the explicit tier, each
//! emitted as a module of that name, none importing from one that imports
//! from it), parsed with `syn` (so a broken
//! template fails here, not in the user's build); the whole file is formatted
//! with `prettyplease`. Output is deterministic (no timestamps) so that
//! `generate --check` can compare bytes.

use crate::config::{Config, Preset};
use crate::model::{Drag, Model};
use crate::ocp::OcpWeights;
use crate::tables::{hex, Axis, Tables};
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

mod explicit;
mod literal;

pub use literal::EmitError;
use literal::{float, floats};

const SOLVER_TEMPLATE: &str = include_str!("../templates/solver.rs");
/// The explicit tier (emitted as module `explicit` beside `solver`).
const EXPLICIT_TEMPLATE: &str = include_str!("../templates/explicit.rs");
/// The window QP's engine (module `qp`), shared by both tiers.
const QP_TEMPLATE: &str = include_str!("../templates/qp.rs");
/// Table lookups (module `lookup`), shared by both tiers.
const LOOKUP_TEMPLATE: &str = include_str!("../templates/lookup.rs");
const LIB_TEMPLATE: &str = include_str!("../templates/lib.rs");

/// Active-set iterations allowed per window QP (each iteration adds or drops
/// one bound, so 3N covers every practical sequence; the generator checks the
/// measured maximum over the grid against it).
pub fn qp_max_iterations(horizon: usize) -> usize {
    3 * horizon
}

/// Everything a generated module needs: config, model, tables (None for
/// the paper preset, which has no tables).
pub struct EmitInput<'a> {
    pub config: &'a Config,
    pub tables: Option<&'a Tables>,
    pub config_hash: [u8; 32],
    /// Path of this module's per-cell QP iteration map in
    /// `qp_iteration_map.rs` (see [`emit_qp_iteration_map`]).
    pub qp_map_ident: &'a str,
    /// The explicit tier's data (None: no explicit tier, as for the paper
    /// preset, which has no tables, and `three_capsules`).
    pub explicit: Option<&'a crate::explicit::ExplicitTables>,
}

fn axis_tokens(name: &str, a: &Axis) -> Result<TokenStream, EmitError> {
    let start = float(name, a.start)?;
    let step = float(name, a.step)?;
    let count = a.count;
    Ok(quote! { Axis { start: #start, step: #step, count: #count } })
}

/// The one-cell leg lattice of a controller without tables.
fn empty_axis_for_legs() -> Axis {
    Axis {
        start: 0.0,
        step: 1.0,
        count: 1,
    }
}

/// Infinity as a token (`f64::INFINITY`): a float literal cannot spell it.
fn float_inf() -> TokenStream {
    quote! { f64::INFINITY }
}

/// Times in s, where +infinity means "never" (NaN is refused).
fn times(name: &str, vs: &[f64]) -> Result<Vec<TokenStream>, EmitError> {
    vs.iter()
        .map(|&v| {
            if v == f64::INFINITY {
                Ok(float_inf())
            } else {
                float(name, v).map(|l| quote! { #l })
            }
        })
        .collect()
}

fn drag_arm(i: usize, drag: &Drag) -> Result<TokenStream, EmitError> {
    Ok(match *drag {
        Drag::Quadratic { b_per_m } => {
            let b = float("b_per_m", b_per_m)?;
            quote! { #i => { let s = v.abs(); (-#b * v * s, -2.0 * #b * s) } }
        }
        Drag::SphereCorrelation {
            k_per_m,
            re_per_speed_s_per_m,
        } => {
            let k = float("k_per_m", k_per_m)?;
            let c = float("re_per_speed_s_per_m", re_per_speed_s_per_m)?;
            // Clift-Gauvin: h(s) = C_d(c s) s^2, written to be finite at s = 0.
            quote! {
                #i => {
                    let s = v.abs();
                    let sign = if v < 0.0 { -1.0 } else { 1.0 };
                    let c: f64 = #c;
                    let cp = libm::pow(c, 0.687);
                    let t1 = 24.0 / c * (s + 0.15 * cp * libm::pow(s, 1.687));
                    let dt1 = 24.0 / c * (1.0 + 0.15 * 1.687 * cp * libm::pow(s, 0.687));
                    let (t2, dt2) = if s > 0.0 {
                        let w = 42500.0 * libm::pow(c * s, -1.16);
                        (0.42 * s * s / (1.0 + w),
                         0.42 * (2.0 * s * (1.0 + w) + 1.16 * s * w) / ((1.0 + w) * (1.0 + w)))
                    } else { (0.0, 0.0) };
                    (-#k * sign * (t1 + t2), -#k * (dt1 + dt2))
                }
            }
        }
    })
}

/// The source of one generated controller module.
pub fn emit_module(input: &EmitInput) -> Result<String, EmitError> {
    let config = input.config;
    let model = Model::from_config(config);
    let w = OcpWeights::from_config(config);
    let c = &config.controller;
    let m = model.capsule_count();
    let nx = 2 * m;
    let n = c.horizon_steps;
    let k = c.plan_steps;
    let dt = float("sample_time_s", c.sample_time_s)?;
    let substeps = c.rk4_substeps;
    let u_max = float("max_gradient_t_per_m", model.u_max_t_per_m)?;
    let g = floats("g", &model.capsules.iter().map(|c| c.g).collect::<Vec<_>>())?;
    let q = floats("q", &w.q)?;
    let r = float("r", w.r)?;
    let p = floats("p", &w.p)?;
    let pos_bound = float("position_bound_m", c.position_bound_m)?;
    let speed_bound = float("speed_bound_m_per_s", c.speed_bound_m_per_s)?;
    let sqp = c.sqp_iterations;
    let qp_max = qp_max_iterations(n);
    let tracking = float("tracking_time_s", config.scanner.tracking_time_s)?;
    let delay = float("extra_delay_s", config.scanner.extra_delay_s)?;
    let noise = float("position_noise_m", config.measurement.position_noise_m)?;
    let sigma = float("switching_sigma", c.switching_sigma)?;
    let hash = hex(&input.config_hash);
    let solver_hash = hex(&crate::tables::solver_hash(config));
    let drag_arms = model
        .capsules
        .iter()
        .enumerate()
        .map(|(i, cap)| drag_arm(i, &cap.drag))
        .collect::<Result<Vec<_>, _>>()?;
    let switching = crate::tables::switching_constants(config, &model);
    let l_f = float("l_f", switching.l_f)?;
    let l_l = float("l_l", switching.l_l)?;
    let l_v = float("l_v", switching.l_v)?;
    let x_diam = float("x_diameter", switching.x_diameter)?;
    let use_tables = input.tables.is_some();
    let ws_min = float("workspace.position_min_m", config.workspace.position_min_m)?;
    let ws_max = float("workspace.position_max_m", config.workspace.position_max_m)?;

    let spec = quote! {
        /// Dimensions, model constants and weights (SI) of this controller.
        pub mod spec {
            /// Number of capsules.
            pub const M: usize = #m;
            /// Number of states [x1, v1, x2, v2, ...].
            pub const NX: usize = #nx;
            /// Online window (inputs re-optimized per step).
            pub const N: usize = #n;
            /// Plan length (samples).
            pub const K: usize = #k;
            /// Controller sample time, s.
            pub const DT_S: f64 = #dt;
            /// RK4 sub-steps per sample.
            pub const RK4_SUBSTEPS: usize = #substeps;
            /// Gradient bound, T/m.
            pub const U_MAX_T_PER_M: f64 = #u_max;
            /// Magnetic acceleration per gradient, m/s^2 per T/m.
            pub const G: [f64; M] = [#(#g),*];
            /// Stage weights on the relative state (SI).
            pub const Q: [f64; NX] = [#(#q),*];
            /// Input weight per (T/m)^2.
            pub const R: f64 = #r;
            /// Terminal weights (SI).
            pub const P: [f64; NX] = [#(#p),*];
            /// State bound on each relative position, m.
            pub const POSITION_BOUND_M: f64 = #pos_bound;
            /// State bound on each speed, m/s.
            pub const SPEED_BOUND_M_PER_S: f64 = #speed_bound;
            /// SQP iterations per control step.
            pub const SQP_ITERATIONS: usize = #sqp;
            /// Active-set iterations allowed per QP.
            pub const QP_MAX_ITERATIONS: usize = #qp_max;
            /// Halvings tried in the line search.
            pub const LINE_SEARCH_TRIES: usize = 4;
            /// Multipliers below this count as zero in the active-set QP.
            pub const QP_MULTIPLIER_TOLERANCE: f64 = 1.0e-12;
            /// Whether plans come from offline tables (false: the paper's NMPC).
            pub const USE_TABLES: bool = #use_tables;
            /// Tracking phase duration, s.
            pub const TRACKING_TIME_S: f64 = #tracking;
            /// Extra compute/transfer delay after tracking, s.
            pub const EXTRA_DELAY_S: f64 = #delay;
            /// Position measurement noise (standard deviation), m.
            pub const POSITION_NOISE_M: f64 = #noise;
            /// sigma of the switching rule (17).
            pub const SWITCHING_SIGMA: f64 = #sigma;
            /// Lipschitz constants of section III: dynamics, stage cost, terminal cost.
            pub const L_F: f64 = #l_f;
            pub const L_L: f64 = #l_l;
            pub const L_V: f64 = #l_v;
            /// ||2 alpha||, the diameter of the state set X.
            pub const X_DIAMETER: f64 = #x_diam;
            /// Workspace: every capsule position of a target or start lies in
            /// [WORKSPACE_MIN_M, WORKSPACE_MAX_M], m.
            pub const WORKSPACE_MIN_M: f64 = #ws_min;
            pub const WORKSPACE_MAX_M: f64 = #ws_max;
            /// SHA-256 of the config this module was generated from.
            pub const CONFIG_SHA256: &str = #hash;
            /// SHA-256 of the parts of that config that shape this solver
            /// (see `tables::solver_hash` in the generator): a config runs
            /// on this module exactly when its solver hash is this one.
            pub const SOLVER_SHA256: &str = #solver_hash;

            /// Drag acceleration of capsule `i` at speed `v` (m/s^2) and its slope d a / d v.
            #[inline]
            pub fn drag(i: usize, v: f64) -> (f64, f64) {
                match i {
                    #(#drag_arms)*
                    _ => (0.0, 0.0),
                }
            }
        }
    };

    let tables = emit_tables(input.tables, k, &format_ident!("{}", input.qp_map_ident))?;
    let solver_file = syn::parse_file(SOLVER_TEMPLATE)
        .map_err(|e| EmitError::Parse(format!("solver template: {e}")))?;
    let solver_attrs = &solver_file.attrs;
    let solver_items = &solver_file.items;
    let qp_file =
        syn::parse_file(QP_TEMPLATE).map_err(|e| EmitError::Parse(format!("qp template: {e}")))?;
    let qp_attrs = &qp_file.attrs;
    let qp_items = &qp_file.items;
    let lookup_file = syn::parse_file(LOOKUP_TEMPLATE)
        .map_err(|e| EmitError::Parse(format!("lookup template: {e}")))?;
    let lookup_attrs = &lookup_file.attrs;
    let lookup_items = &lookup_file.items;
    if let (Some(e), Some(t)) = (input.explicit, input.tables) {
        // The slots parallel the sparse index's kept cells and the fine grid.
        debug_assert_eq!(e.index_slot.len(), t.index_cells.len());
        debug_assert_eq!(e.coasted_index_slot.len(), t.index_cells.len());
        debug_assert_eq!(e.fine_slot.len(), t.fine.plans.len());
    }
    let explicit_tables = explicit::emit_explicit_tables(input.explicit, n, nx, k, qp_max)?;
    let explicit_file = syn::parse_file(EXPLICIT_TEMPLATE)
        .map_err(|e| EmitError::Parse(format!("explicit template: {e}")))?;
    let explicit_attrs = &explicit_file.attrs;
    let explicit_items = &explicit_file.items;
    let module = quote! {
        #spec
        #tables
        #explicit_tables
        pub mod qp {
            #(#qp_attrs)*
            #(#qp_items)*
        }
        pub mod lookup {
            #(#lookup_attrs)*
            #(#lookup_items)*
        }
        pub mod solver {
            #(#solver_attrs)*
            #(#solver_items)*
        }
        pub mod explicit {
            #(#explicit_attrs)*
            #(#explicit_items)*
        }
    };
    let file: syn::File =
        syn::parse2(module).map_err(|e| EmitError::Parse(format!("generated module: {e}")))?;
    let preset = match c.preset {
        Preset::Default => "default",
        Preset::Paper => "paper",
    };
    Ok(format!(
        "// @generated by capsule-mpc-generator {} from a config with sha256 {hash} (preset `{preset}`).\n\
         // Do not edit: run `capsule-mpc generate` (see README).\n\n{}",
        env!("CARGO_PKG_VERSION"),
        prettyplease::unparse(&file)
    ))
}

fn emit_tables(
    tables: Option<&Tables>,
    k: usize,
    qp_map: &proc_macro2::Ident,
) -> Result<TokenStream, EmitError> {
    let empty_axis = Axis {
        start: 0.0,
        step: 1.0,
        count: 1,
    };
    let (plan_axis, pos_axis, spd_axis) = match tables {
        Some(t) => (
            t.plan_axis.clone(),
            t.index_position_axis.clone(),
            t.index_speed_axis.clone(),
        ),
        None => (empty_axis.clone(), empty_axis.clone(), empty_axis),
    };
    let plan_axis_t = axis_tokens("plan_axis", &plan_axis)?;
    let pos_axis_t = axis_tokens("index_position_axis", &pos_axis)?;
    let spd_axis_t = axis_tokens("index_speed_axis", &spd_axis)?;
    let leg_axis = tables.map_or(empty_axis_for_legs(), |t| t.legs.axis.clone());
    let leg_axis_t = axis_tokens("legs.axis", &leg_axis)?;
    let (min_times, first_legs, chain_times) = match tables {
        Some(t) => (
            times(
                "plan min time",
                &t.plans.iter().map(|p| p.min_time_s).collect::<Vec<_>>(),
            )?,
            t.legs.first_leg.clone(),
            times("chain time", &t.legs.chain_time_s)?,
        ),
        None => (Vec::new(), vec![crate::legs::NO_LEG], vec![float_inf()]),
    };
    let leg_cells = first_legs.len();
    let fine_axis = tables.map_or(empty_axis_for_legs(), |t| t.fine.axis.clone());
    let fine_axis_t = axis_tokens("fine.axis", &fine_axis)?;
    let plan_rows_of = |name: &str, plans: &[Vec<f64>]| -> Result<Vec<TokenStream>, EmitError> {
        plans
            .iter()
            .map(|u| {
                let us = floats(name, u)?;
                Ok(quote! { [#(#us),*] })
            })
            .collect()
    };
    let (fine_rows, coasted_fine_rows, fine_reached) = match tables {
        Some(t) => (
            plan_rows_of("fine plan u", &t.fine.plans)?,
            plan_rows_of("coasted fine plan u", &t.fine.coasted_plans)?,
            t.fine
                .plans
                .iter()
                .zip(&t.fine.coasted_plans)
                .map(|(a, b)| a.iter().any(|v| *v != 0.0) && b.iter().any(|v| *v != 0.0))
                .collect::<Vec<bool>>(),
        ),
        None => (Vec::new(), Vec::new(), Vec::new()),
    };
    let fine_count = fine_rows.len();
    let (coast_s, coasted_rows, coasted_index) = match tables {
        Some(t) => (
            float("coasted.coast_s", t.coasted.coast_s)?,
            t.coasted
                .plans
                .iter()
                .map(|p| {
                    let us = floats("coasted plan u", &p.plan.u)?;
                    Ok(quote! { [#(#us),*] })
                })
                .collect::<Result<Vec<_>, EmitError>>()?,
            t.coasted
                .index
                .iter()
                .map(|&(plan, offset)| ((plan as u32) << 16) | offset as u32)
                .collect::<Vec<u32>>(),
        ),
        None => (float("coast_s", 0.0)?, Vec::new(), vec![u32::MAX]),
    };
    let (plan_rows, reached, index): (Vec<TokenStream>, Vec<bool>, Vec<u32>) = match tables {
        Some(t) => {
            let rows = t
                .plans
                .iter()
                .map(|p| {
                    let us = floats("plan u", &p.plan.u)?;
                    Ok(quote! { [#(#us),*] })
                })
                .collect::<Result<Vec<_>, EmitError>>()?;
            let reached = t.plans.iter().map(|p| p.reached).collect();
            let index = t
                .index
                .iter()
                .map(|&(plan, offset)| ((plan as u32) << 16) | offset as u32)
                .collect();
            (rows, reached, index)
        }
        // One dummy cell pointing at no plan (plan index past PLAN_COUNT).
        None => (Vec::new(), Vec::new(), vec![u32::MAX]),
    };
    let index_cells: Vec<u64> = match tables {
        Some(t) => t.index_cells.clone(),
        // The one dummy cell: the centre of the 1-cell grid.
        None => vec![0],
    };
    let plan_count = plan_rows.len();
    let cells = index.len();
    debug_assert_eq!(cells, index_cells.len());
    debug_assert_eq!(coasted_index.len(), cells);
    let table_bytes = 2 * (plan_count * k * 8 + cells * 4 + fine_count * k * 8)
        + cells * 8
        + plan_count * 9
        + fine_count
        + leg_cells * 10;
    let plan_count_ident = format_ident!("PLAN_COUNT");
    Ok(quote! {
        /// Offline tables: plans from rest over the relative-position grid and
        /// the warm-start index over relative positions and speeds.
        pub mod tables {
            use super::spec::K;
            /// A uniform grid axis.
            #[derive(Debug, Clone, Copy)]
            pub struct Axis { pub start: f64, pub step: f64, pub count: usize }
            /// Grid of each capsule's relative start position (plans start at rest).
            pub const PLAN_AXIS: Axis = #plan_axis_t;
            /// Number of stored plans.
            pub const #plan_count_ident: usize = #plan_count;
            /// Index axes: relative positions (m) and speeds (m/s).
            pub const INDEX_POSITION_AXIS: Axis = #pos_axis_t;
            pub const INDEX_SPEED_AXIS: Axis = #spd_axis_t;
            /// Bytes of table data in this module.
            pub const TABLE_BYTES: usize = #table_bytes;
            /// Gradient plans, T/m.
            pub static PLAN_U: [[f64; K]; PLAN_COUNT] = [#(#plan_rows),*];
            /// Whether each plan reaches its target.
            pub static PLAN_REACHED: [bool; PLAN_COUNT] = [#(#reached),*];
            /// Minimum rest-to-rest time of each plan into the settle band
            /// (1 mm, 5 mm/s), s; infinite where not reached.
            pub static PLAN_MIN_TIME_S: [f64; PLAN_COUNT] = [#(#min_times),*];
            /// Fine grid of small moves from rest near the target (the end
            /// game): relative positions, m.
            pub const FINE_AXIS: Axis = #fine_axis_t;
            pub const FINE_COUNT: usize = #fine_count;
            /// Fine plans back to back and with the coast, T/m.
            pub static FINE_PLAN_U: [[f64; K]; FINE_COUNT] = [#(#fine_rows),*];
            pub static COASTED_FINE_PLAN_U: [[f64; K]; FINE_COUNT] = [#(#coasted_fine_rows),*];
            /// Whether both fine plans of a grid point move (the centre's do not).
            pub static FINE_REACHED: [bool; FINE_COUNT] = [#(#fine_reached),*];
            /// Lattice of each capsule's displacement x_start - x_target, m.
            pub const LEG_AXIS: Axis = #leg_axis_t;
            /// Per lattice displacement: the plan of the first leg of the
            /// fastest monotone chain (u16::MAX: none, or no displacement).
            pub static FIRST_LEG: [u16; #leg_cells] = [#(#first_legs),*];
            /// Per lattice displacement: the chain's summed minimum time, s.
            pub static CHAIN_TIME_S: [f64; #leg_cells] = [#(#chain_times),*];
            /// Kept cells of the sparse warm-start index: ascending row-major
            /// numbers over the index axes (e1, v1, e2, v2, ...).
            pub static INDEX_CELLS: [u64; #cells] = [#(#index_cells),*];
            /// Per kept cell: plan << 16 | step offset.
            pub static INDEX: [u32; #cells] = [#(#index),*];
            /// Constant sampling's tables: the same grid, plans solved with
            /// a zero-gradient coast of COAST_S after every sample.
            pub const COAST_S: f64 = #coast_s;
            pub static COASTED_PLAN_U: [[f64; K]; PLAN_COUNT] = [#(#coasted_rows),*];
            pub static COASTED_INDEX: [u32; #cells] = [#(#coasted_index),*];
            /// Per kept index cell: most QP iterations measured offline (empty
            /// when not measured; see `qp_iteration_map.rs`).
            pub static QP_ITERATION_MAP: &[u8] = crate::qp_iteration_map::#qp_map;
        }
    })
}

/// `qp_iteration_map.rs`: per warm-start index cell of the default
/// controller, the most active-set iterations one QP took in the solves
/// `capsule-mpc generate` ran there with the compiled solver (`None`: not
/// measured, because the binary was built from a different solver). The
/// paper preset has no index, so its map is empty.
pub fn emit_qp_iteration_map(controller: Option<&[u8]>) -> Result<String, EmitError> {
    let measured = controller.is_some();
    let counts = controller.unwrap_or(&[]);
    let max = Literal::u8_unsuffixed(counts.iter().copied().max().unwrap_or(0));
    let cells = counts.iter().map(|&c| Literal::u8_unsuffixed(c));
    let tokens = quote! {
        /// Whether `CONTROLLER` was measured with the solver it describes.
        pub const MEASURED: bool = #measured;
        /// Per warm-start index cell of `controller`: the most active-set
        /// iterations one QP took in the offline solves there (cold and
        /// warm, every schedule); 0 where nothing was solved.
        pub static CONTROLLER: &[u8] = &[#(#cells),*];
        /// Largest entry of `CONTROLLER`.
        pub const CONTROLLER_MAX: u8 = #max;
        /// The paper preset has no index cells.
        pub static PAPER_PRESET: &[u8] = &[];
        /// The three-capsule preset's map is not measured (its cells are
        /// not the benchmarked controller's).
        pub static THREE_CAPSULES: &[u8] = &[];
    };
    let file: syn::File =
        syn::parse2(tokens).map_err(|e| EmitError::Parse(format!("QP iteration map: {e}")))?;
    Ok(format!(
        "// @generated by capsule-mpc-generator {}: QP iterations per warm-start index cell,\n\
         // measured by `capsule-mpc generate` with the compiled solver. Do not edit.\n\n{}",
        env!("CARGO_PKG_VERSION"),
        prettyplease::unparse(&file)
    ))
}

/// The generated crate's `lib.rs`: the static part of the crate.
pub fn emit_lib() -> String {
    LIB_TEMPLATE.to_string()
}
