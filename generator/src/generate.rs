//! `capsule-mpc generate`: tables + emitted crate, written atomically, and the
//! `--check` comparison against what is committed.

use crate::config::{Config, CostUnits, Preset};
use crate::emit::{
    emit_lib, emit_manifest, emit_module, emit_qp_iteration_map, EmitError, EmitInput,
};
use crate::explicit::{build_explicit, ExplicitTables};
use crate::table_file;
use crate::tables::{build_tables, config_hash, Progress, TableError, Tables};
use std::path::{Path, PathBuf};

/// Table I weights of the paper (states in cm, cm/s; u in T/m).
pub const PAPER_Q_PER_CAPSULE: [f64; 2] = [0.02, 0.001];
pub const PAPER_R: f64 = 1.0e-5;
/// P = 1e-3 Q in the paper.
pub const PAPER_P_OVER_Q: f64 = 1.0e-3;
/// The paper's horizon, samples.
pub const PAPER_HORIZON: usize = 10;
/// SQP iterations per step for the paper preset (it solves its NLP to
/// convergence each step; 10 Gauss-Newton steps get there on N = 10).
pub const PAPER_SQP_ITERATIONS: usize = 10;

/// The paper's NMPC taken literally, on the same capsules and scanner.
pub fn paper_preset(config: &Config) -> Config {
    let mut c = config.clone();
    let m = c.capsule_count();
    let ctl = &mut c.controller;
    ctl.preset = Preset::Paper;
    ctl.horizon_steps = PAPER_HORIZON;
    ctl.plan_steps = PAPER_HORIZON;
    ctl.cost_units = CostUnits::Cm;
    ctl.q = PAPER_Q_PER_CAPSULE.repeat(m);
    ctl.r = PAPER_R;
    ctl.p = ctl.q.iter().map(|q| q * PAPER_P_OVER_Q).collect();
    ctl.sqp_iterations = PAPER_SQP_ITERATIONS;
    c
}

#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error(transparent)]
    Emit(#[from] EmitError),
    #[error("{path}: {reason}")]
    Io { path: String, reason: String },
    #[error(transparent)]
    Tables(#[from] TableError),
}

fn io_err(path: &Path, e: std::io::Error) -> GenerateError {
    GenerateError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

/// Files of the generated crate, relative paths and contents.
pub struct GeneratedFiles {
    pub files: Vec<(PathBuf, Vec<u8>)>,
    pub tables: Tables,
    /// The explicit tier's data emitted into the module (empty for modules
    /// without an explicit tier: `three_capsules`).
    pub explicit: ExplicitTables,
}

/// Where the per-cell QP iteration map goes, relative to the crate.
pub const QP_ITERATION_MAP_PATH: &str = "src/qp_iteration_map.rs";

impl GeneratedFiles {
    /// The bytes of `rel` (a path relative to the crate), if emitted.
    pub fn file(&self, rel: &str) -> Option<&[u8]> {
        self.files
            .iter()
            .find(|(p, _)| p == Path::new(rel))
            .map(|(_, b)| b.as_slice())
    }

    /// Puts a measured QP iteration map in place of the placeholder.
    pub fn set_qp_iteration_map(&mut self, controller: &[u8]) -> Result<(), GenerateError> {
        let text = emit_qp_iteration_map(Some(controller))?.into_bytes();
        match self
            .files
            .iter_mut()
            .find(|(p, _)| p == Path::new(QP_ITERATION_MAP_PATH))
        {
            Some((_, bytes)) => *bytes = text,
            None => self
                .files
                .push((PathBuf::from(QP_ITERATION_MAP_PATH), text)),
        }
        Ok(())
    }
}

/// A product controller module of the generated crate. Each is compiled
/// into every binary; a run picks the one whose solver hash matches its
/// config (see `tables::solver_hash`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerModule {
    /// `controller`: the default two-capsule config (and the C ABI's).
    Controller,
    /// `three_capsules`: the three-capsule preset.
    ThreeCapsules,
}

impl ControllerModule {
    pub const ALL: [ControllerModule; 2] = [
        ControllerModule::Controller,
        ControllerModule::ThreeCapsules,
    ];

    /// The module's name in the generated crate.
    pub fn module_name(self) -> &'static str {
        match self {
            ControllerModule::Controller => "controller",
            ControllerModule::ThreeCapsules => "three_capsules",
        }
    }

    /// The name on the command line (`generate --module`).
    pub fn cli_name(self) -> &'static str {
        match self {
            ControllerModule::Controller => "controller",
            ControllerModule::ThreeCapsules => "three-capsules",
        }
    }

    /// The config the module is generated from unless `--config` says
    /// otherwise (embedded in the binary).
    pub fn default_config(self) -> Config {
        match self {
            ControllerModule::Controller => Config::embedded_default(),
            ControllerModule::ThreeCapsules => Config::embedded_three_capsules(),
        }
    }

    /// The emitted module, relative to the crate.
    pub fn source_path(self) -> String {
        format!("src/{}.rs", self.module_name())
    }

    /// The module's table file, relative to the crate.
    pub fn tables_path(self) -> String {
        table_file_name(self.module_name())
    }

    /// Its entry in `qp_iteration_map.rs`.
    fn qp_map_ident(self) -> &'static str {
        match self {
            ControllerModule::Controller => "CONTROLLER",
            ControllerModule::ThreeCapsules => "THREE_CAPSULES",
        }
    }
}

/// The table file of module `name`, relative to the crate.
pub fn table_file_name(name: &str) -> String {
    format!("{name}.tables.bin")
}

/// The human-readable summary committed beside a table file.
pub fn summary_file_name(name: &str) -> String {
    format!("{name}.tables.txt")
}

/// A module's source, table file and summary.
fn module_files(
    name: &str,
    config: &Config,
    tables: Option<&Tables>,
    explicit: Option<&ExplicitTables>,
    qp_map_ident: &str,
) -> Result<Vec<(PathBuf, Vec<u8>)>, GenerateError> {
    let table_name = table_file_name(name);
    let source = emit_module(&EmitInput {
        config,
        use_tables: tables.is_some(),
        config_hash: config_hash(config),
        qp_map_ident,
        table_file: &table_name,
    })?;
    let bytes = table_file::encode(config, tables, explicit);
    let summary = table_file::summary(&bytes, config, &table_name)?;
    Ok(vec![
        (PathBuf::from(format!("src/{name}.rs")), source.into_bytes()),
        (PathBuf::from(summary_file_name(name)), summary.into_bytes()),
        (PathBuf::from(table_name), bytes),
    ])
}

/// Builds the tables and emits every file of the generated crate.
pub fn generate(config: &Config, progress: &dyn Progress) -> Result<GeneratedFiles, GenerateError> {
    generate_module(ControllerModule::Controller, config, progress)
}

/// Builds the tables of `module` and emits its files.
pub fn generate_module(
    module: ControllerModule,
    config: &Config,
    progress: &dyn Progress,
) -> Result<GeneratedFiles, GenerateError> {
    let tables = build_tables(config, progress);
    emit_module_files(module, config, tables)
}

/// Emits the files of `module` from already-built tables: for the default
/// `controller` every file of the crate (the paper preset, derived from its
/// config, the static part and the QP iteration map included); for the
/// others their module and tables only.
pub fn emit_module_files(
    module: ControllerModule,
    config: &Config,
    tables: Tables,
) -> Result<GeneratedFiles, GenerateError> {
    if module == ControllerModule::Controller {
        return emit_all(config, tables);
    }
    // No explicit tier outside the default controller: the explicit
    // generator addresses samples with u16 slots (at most 65 535) and the
    // M = 3 data would be large; `refine = none` is refused there.
    let files = module_files(
        module.module_name(),
        config,
        Some(&tables),
        None,
        module.qp_map_ident(),
    )?;
    Ok(GeneratedFiles {
        files,
        tables,
        explicit: ExplicitTables::default(),
    })
}

/// Emits every file from already-built tables of the default `controller`.
pub fn emit_all(config: &Config, tables: Tables) -> Result<GeneratedFiles, GenerateError> {
    // Derived from the tables at emission: the linearization is cheap next
    // to the tables.
    let explicit = build_explicit(config, &tables);
    let mut files = vec![
        (PathBuf::from("Cargo.toml"), emit_manifest().into_bytes()),
        (PathBuf::from("src/lib.rs"), emit_lib().into_bytes()),
    ];
    files.extend(module_files(
        "controller",
        config,
        Some(&tables),
        Some(&explicit),
        ControllerModule::Controller.qp_map_ident(),
    )?);
    let paper = paper_preset(config);
    files.extend(module_files(
        "paper_preset",
        &paper,
        None,
        None,
        "PAPER_PRESET",
    )?);
    files.push((
        PathBuf::from(QP_ITERATION_MAP_PATH),
        emit_qp_iteration_map(None)?.into_bytes(),
    ));
    Ok(GeneratedFiles {
        files,
        tables,
        explicit,
    })
}

/// Writes each file via a temporary file in the same directory and a rename,
/// so an interrupted run never leaves a half-written file.
pub fn write_atomically(dir: &Path, files: &GeneratedFiles) -> Result<(), GenerateError> {
    for (rel, bytes) in &files.files {
        write_file_atomically(&dir.join(rel), bytes)?;
    }
    Ok(())
}

/// Writes `bytes` to `path` via a temporary file in the same directory and
/// a rename (creating the directory if needed).
pub fn write_file_atomically(path: &Path, bytes: &[u8]) -> Result<(), GenerateError> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(parent).map_err(|e| io_err(parent, e))?;
    let tmp = parent.join(format!(
        ".{}.tmp-{}",
        path.file_name().and_then(|n| n.to_str()).unwrap_or("file"),
        std::process::id()
    ));
    std::fs::write(&tmp, bytes).map_err(|e| io_err(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io_err(path, e)
    })
}

/// Relative paths whose committed content differs from `files` (or is missing).
pub fn differences(dir: &Path, files: &GeneratedFiles) -> Vec<PathBuf> {
    files
        .files
        .iter()
        .filter(|(rel, bytes)| {
            std::fs::read(dir.join(rel)).ok().as_deref() != Some(bytes.as_slice())
        })
        .map(|(rel, _)| rel.clone())
        .collect()
}
