//! Emission of the specialized solver crate (`generated/`).
//!
//! A module is data and a thin binding: its constants (`spec`), the table
//! file it reads with `include_bytes!` (written by `crate::table_file`),
//! an implementation of `capsule_mpc_solver::Spec` and the type alias of
//! its solver. The algorithm itself is hand-written code in
//! `capsule-mpc-solver`. Tokens are written with `quote`, checked by
//! parsing them with `syn` and formatted with `prettyplease`. Output is
//! deterministic (no timestamps) so that `generate --check` can compare
//! bytes.

use crate::config::{Config, Preset};
use crate::model::{Drag, Model};
use crate::ocp::OcpWeights;
use crate::tables::hex;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

mod literal;

pub use literal::EmitError;
use literal::{float, floats};

/// Active-set iterations allowed per window QP (each iteration adds or drops
/// one bound, so 3N covers every practical sequence; the generator checks the
/// measured maximum over the grid against it).
pub fn qp_max_iterations(horizon: usize) -> usize {
    3 * horizon
}

/// Everything a generated module needs besides its table file.
pub struct EmitInput<'a> {
    pub config: &'a Config,
    /// Whether plans come from tables (false: the paper preset).
    pub use_tables: bool,
    pub config_hash: [u8; 32],
    /// Path of this module's per-cell QP iteration map in
    /// `qp_iteration_map.rs` (see [`emit_qp_iteration_map`]).
    pub qp_map_ident: &'a str,
    /// The table file's name, beside the crate's `Cargo.toml`.
    pub table_file: &'a str,
}

/// Drag law of one capsule as a `DragLaw` expression.
fn drag_tokens(drag: &Drag) -> Result<TokenStream, EmitError> {
    Ok(match *drag {
        Drag::Quadratic { b_per_m } => {
            let b = float("b_per_m", b_per_m)?;
            quote! { DragLaw::Quadratic { b_per_m: #b } }
        }
        Drag::SphereCorrelation {
            k_per_m,
            re_per_speed_s_per_m,
        } => {
            let k = float("k_per_m", k_per_m)?;
            let c = float("re_per_speed_s_per_m", re_per_speed_s_per_m)?;
            quote! { DragLaw::SphereCorrelation { k_per_m: #k, re_per_speed_s_per_m: #c } }
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
    let disturbance = float("disturbance_bound", config.disturbance.design_bound_si())?;
    let sigma = float("switching_sigma", c.switching_sigma)?;
    let hash = hex(&input.config_hash);
    let hash_bytes = input.config_hash.iter().map(|&b| Literal::u8_unsuffixed(b));
    let solver_hash = hex(&crate::tables::solver_hash(config));
    let drags = model
        .capsules
        .iter()
        .map(|cap| drag_tokens(&cap.drag))
        .collect::<Result<Vec<_>, _>>()?;
    let switching = crate::tables::switching_constants(config, &model);
    let l_f = float("l_f", switching.l_f)?;
    let l_l = float("l_l", switching.l_l)?;
    let l_v = float("l_v", switching.l_v)?;
    let x_diam = float("x_diameter", switching.x_diameter)?;
    let use_tables = input.use_tables;
    let ws_min = float("workspace.position_min_m", config.workspace.position_min_m)?;
    let ws_max = float("workspace.position_max_m", config.workspace.position_max_m)?;
    let table_path = format!("../{}", input.table_file);
    let table_file = input.table_file;
    let qp_map = format_ident!("{}", input.qp_map_ident);

    let module = quote! {
        use capsule_mpc_solver::tables::{Dims, TableError, Tables};
        use capsule_mpc_solver::DragLaw;
        use core::sync::atomic::AtomicU8;

        /// Dimensions, model constants and weights (SI) of this controller.
        pub mod spec {
            use capsule_mpc_solver::DragLaw;
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
            /// Drag law of each capsule.
            pub const DRAG: [DragLaw; M] = [#(#drags),*];
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
            /// Disturbance bound the estimator assumes (the config's
            /// `[disturbance]`), SI: m/s and m/s^2 on the state derivative.
            pub const DISTURBANCE_BOUND_SI: f64 = #disturbance;
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
            /// The same as bytes (the table file's header must carry them).
            pub const CONFIG_HASH: [u8; 32] = [#(#hash_bytes),*];
            /// SHA-256 of the parts of that config that shape this solver
            /// (see `tables::solver_hash` in the generator): a config runs
            /// on this module exactly when its solver hash is this one.
            pub const SOLVER_SHA256: &str = #solver_hash;
            /// The table file (see `capsule_mpc_solver::format`).
            pub const TABLE_FILE: &[u8] = include_bytes!(#table_path);
            /// Its name beside the crate's manifest.
            pub const TABLE_FILE_NAME: &str = #table_file;

            /// Drag acceleration of capsule `i` at speed `v` (m/s^2) and its slope d a / d v.
            #[inline]
            pub fn drag(i: usize, v: f64) -> (f64, f64) {
                if i < M { DRAG[i].accel_and_slope(v) } else { (0.0, 0.0) }
            }
        }

        /// This module's constants and tables, as the solver reads them.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub struct Spec;

        /// Whether the table file's SHA-256 was checked (0 no, 1 good, 2 corrupt).
        static TABLES_VERIFIED: AtomicU8 = AtomicU8::new(0);

        impl capsule_mpc_solver::Spec<{ spec::M }, { spec::NX }> for Spec {
            const DT_S: f64 = spec::DT_S;
            const RK4_SUBSTEPS: usize = spec::RK4_SUBSTEPS;
            const U_MAX_T_PER_M: f64 = spec::U_MAX_T_PER_M;
            const G: [f64; spec::M] = spec::G;
            const DRAG: [DragLaw; spec::M] = spec::DRAG;
            const Q: [f64; spec::NX] = spec::Q;
            const R: f64 = spec::R;
            const P: [f64; spec::NX] = spec::P;
            const POSITION_BOUND_M: f64 = spec::POSITION_BOUND_M;
            const SPEED_BOUND_M_PER_S: f64 = spec::SPEED_BOUND_M_PER_S;
            const SQP_ITERATIONS: usize = spec::SQP_ITERATIONS;
            const QP_MAX_ITERATIONS: usize = spec::QP_MAX_ITERATIONS;
            const LINE_SEARCH_TRIES: usize = spec::LINE_SEARCH_TRIES;
            const QP_MULTIPLIER_TOLERANCE: f64 = spec::QP_MULTIPLIER_TOLERANCE;
            const USE_TABLES: bool = spec::USE_TABLES;
            const TRACKING_TIME_S: f64 = spec::TRACKING_TIME_S;
            const EXTRA_DELAY_S: f64 = spec::EXTRA_DELAY_S;
            const POSITION_NOISE_M: f64 = spec::POSITION_NOISE_M;
            const DISTURBANCE_BOUND_SI: f64 = spec::DISTURBANCE_BOUND_SI;
            const SWITCHING_SIGMA: f64 = spec::SWITCHING_SIGMA;
            const L_F: f64 = spec::L_F;
            const L_L: f64 = spec::L_L;
            const L_V: f64 = spec::L_V;
            const X_DIAMETER: f64 = spec::X_DIAMETER;
            const WORKSPACE_MIN_M: f64 = spec::WORKSPACE_MIN_M;
            const WORKSPACE_MAX_M: f64 = spec::WORKSPACE_MAX_M;
            const CONFIG_SHA256: &'static str = spec::CONFIG_SHA256;
            const SOLVER_SHA256: &'static str = spec::SOLVER_SHA256;
            const TABLES: Tables<'static> = TABLES;
            const QP_ITERATION_MAP: &'static [u8] = crate::qp_iteration_map::#qp_map;
            fn verify_tables() -> Result<(), TableError> {
                TABLES.verify_once(&TABLES_VERIFIED)
            }
        }

        /// The table file, parsed at compile time: a file of another format,
        /// dimensions or config fails the build with its reason.
        pub const TABLES: Tables<'static> = match Tables::parse(
            spec::TABLE_FILE,
            Dims { m: spec::M, nx: spec::NX, n: spec::N, k: spec::K },
            &spec::CONFIG_HASH,
        ) {
            Ok(t) => t,
            Err(e) => panic!("{}", e.message()),
        };

        /// This module's solver.
        pub type Solver = capsule_mpc_solver::Solver<Spec, { spec::M }, { spec::NX }, { spec::N }, { spec::K }>;
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
        pub const CONTROLLER: &[u8] = &[#(#cells),*];
        /// Largest entry of `CONTROLLER`.
        pub const CONTROLLER_MAX: u8 = #max;
        /// The paper preset has no index cells.
        pub const PAPER_PRESET: &[u8] = &[];
        /// The three-capsule preset's map is not measured (its cells are
        /// not the benchmarked controller's).
        pub const THREE_CAPSULES: &[u8] = &[];
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
    GENERATED_LIB.to_string()
}

/// The generated crate's manifest (static).
pub fn emit_manifest() -> String {
    GENERATED_MANIFEST.to_string()
}

const GENERATED_MANIFEST: &str = r#"# @generated by capsule-mpc-generator. Do not edit: run `capsule-mpc generate`.
[package]
name = "capsule-mpc-generated"
description = "Data and thin bindings of the capsule-mpc controllers, emitted by capsule-mpc generate"
version.workspace = true
edition.workspace = true
license.workspace = true

[dependencies]
capsule-mpc-solver = { path = "../solver" }
"#;

const GENERATED_LIB: &str = r#"// @generated by capsule-mpc-generator (static part). Do not edit: run `capsule-mpc generate`.

//! The controllers emitted by `capsule-mpc generate`: data and a thin
//! binding each, the algorithm being `capsule-mpc-solver`'s. `controller`
//! is the product's controller for the default two-capsule config (both
//! tiers); `three_capsules` the same for the shipped three-capsule preset
//! (`configs/three-capsules.toml`, `generate --module three-capsules`);
//! `paper_preset` is the paper's NMPC taken literally (N = 10, Table I
//! weights, no tables), kept for comparison. Each module holds its
//! constants (`spec`), reads its table file (`*.tables.bin` beside this
//! crate's manifest, summarized in `*.tables.txt`) and names its solver
//! type `Solver`; `spec::SOLVER_SHA256` names the config it was built for.
//!
//! No heap, no `unsafe`, no `std`.

#![no_std]
#![forbid(unsafe_code)]

// Emitted modules are formatted by prettyplease; keep rustfmt off them so
// `generate --check` compares exactly what the generator writes.
#[rustfmt::skip]
pub mod controller;
#[rustfmt::skip]
pub mod paper_preset;
#[rustfmt::skip]
pub mod three_capsules;
#[rustfmt::skip]
pub mod qp_iteration_map;

pub use capsule_mpc_solver::{Leg, PlanSolver, SolveReport, SolveStatus, Tier};
"#;
