//! The table file's layout: one little-endian file per controller module,
//! written by the generator and read in place by the online solver.
//!
//! ```text
//! 0   magic            8 bytes  "CMPCTBL\0"
//! 8   format version   u32
//! 12  section count    u32
//! 16  config SHA-256   32 bytes (of the config the tables were made from)
//! 48  dims             4 x u32: M, NX, N, K
//! 64  directory        section count x (id u32, element bytes u32, offset u64, length u64)
//! ..  sections         each at an 8-byte aligned offset, zero padding between
//! end SHA-256          32 bytes of everything before it
//! ```
//!
//! Every number is little endian; floats are IEEE 754 binary64. Readers
//! never depend on the alignment of the bytes in memory.

/// First eight bytes of every table file.
pub const MAGIC: [u8; 8] = *b"CMPCTBL\0";
/// The layout version this build reads and writes.
pub const FORMAT_VERSION: u32 = 7;
/// Bytes of the fixed header before the directory.
pub const HEADER_BYTES: usize = 64;
/// Bytes of one directory entry.
pub const DIRECTORY_ENTRY_BYTES: usize = 24;
/// Bytes of the SHA-256 trailer.
pub const CHECKSUM_BYTES: usize = 32;
/// Offset of the config hash in the header.
pub const CONFIG_HASH_OFFSET: usize = 16;
/// Offset of the dimensions (M, NX, N, K) in the header.
pub const DIMS_OFFSET: usize = 48;
/// Sections start at multiples of this.
pub const SECTION_ALIGN: usize = 8;

/// A uniform grid axis: `count` points from `start` by `step`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    pub start: f64,
    pub step: f64,
    pub count: usize,
}

/// The one-point axis of a module without tables.
pub const EMPTY_AXIS: Axis = Axis {
    start: 0.0,
    step: 1.0,
    count: 1,
};

/// Bytes of one stored axis: start f64, step f64, count u64.
pub const AXIS_BYTES: usize = 24;
/// The axes in the `Axes` section, in this order.
pub const AXIS_PLAN: usize = 0;
pub const AXIS_INDEX_POSITION: usize = 1;
pub const AXIS_INDEX_SPEED: usize = 2;
pub const AXIS_LEG: usize = 3;
pub const AXIS_FINE: usize = 4;
pub const AXIS_COUNT: usize = 5;

/// Scalars in the `Scalars` section (f64 each), in this order.
pub const SCALAR_COAST_S: usize = 0;
pub const SCALAR_L_F: usize = 1;
pub const SCALAR_L_L: usize = 2;
pub const SCALAR_L_V: usize = 3;
pub const SCALAR_X_DIAMETER: usize = 4;
pub const SCALAR_COUNT: usize = 5;

/// Slot value of a cell without an explicit sample.
pub const NO_SLOT: u16 = u16::MAX;
/// Index entry of a cell without a plan (plan << 16 | offset).
pub const NO_PLAN: u32 = u32::MAX;
/// Leg entry of a displacement without a chain.
pub const NO_LEG: u16 = u16::MAX;
/// Settle sample of a plan whose rollout is outside the band at its end.
pub const NO_SETTLE: u16 = u16::MAX;

/// The sections of a table file. `P` plans, `C` kept index cells, `F`
/// fine grid points, `L` leg lattice cells, `E` explicit samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Section {
    /// The five axes (see `AXIS_*`).
    Axes = 1,
    /// Scalars (see `SCALAR_*`).
    Scalars = 2,
    /// Gradients of the back-to-back plans, `f64 [P][K]`, T/m.
    PlanU = 3,
    /// Whether each plan reaches its target, `u8 [P]`.
    PlanReached = 4,
    /// Minimum rest-to-rest time into the settle band, `f64 [P]`, s
    /// (infinite where not reached).
    PlanMinTime = 5,
    /// The same three for constant sampling's plans (a coast after each sample).
    CoastedPlanU = 6,
    CoastedPlanReached = 7,
    CoastedPlanMinTime = 8,
    /// Kept cells of the sparse warm-start index, ascending row-major
    /// numbers over (e1, v1, e2, v2, ...), `u64 [C]`.
    IndexCells = 9,
    /// Per kept cell: plan << 16 | step offset, `u32 [C]` (and constant sampling's).
    Index = 10,
    CoastedIndex = 11,
    /// Fine end-game plans from rest, `f64 [F][K]` (back to back, coasted).
    FinePlanU = 12,
    CoastedFinePlanU = 13,
    /// Whether both fine plans of a grid point move, `u8 [F]`.
    FineReached = 14,
    /// Per leg lattice displacement: the first leg's plan (`u16 [L]`) and the
    /// chain's summed minimum time (`f64 [L]`, s).
    FirstLeg = 15,
    ChainTime = 16,
    /// The explicit tier: one record per stored sample (see `ExplicitLayout`).
    ExplicitSamples = 17,
    /// Every sample's relative state, `f64 [E][NX]`.
    ExplicitState = 18,
    /// Per kept index cell / fine point: the slot of its sample, u16.
    ExplicitIndexSlot = 19,
    CoastedExplicitIndexSlot = 20,
    FineExplicitSlot = 21,
    CoastedFineExplicitSlot = 22,
    /// Generator-only data (re-emission without re-solving): plan states
    /// `f64 [P][K+1][NX]`, per-plan (cost f64, SQP iterations u32, arrival
    /// samples u32), and the generator's version string.
    PlanStates = 23,
    PlanMeta = 24,
    CoastedPlanStates = 25,
    CoastedPlanMeta = 26,
    GeneratorVersion = 27,
    /// Per plan: the sample from which its rollout from rest at its grid
    /// point stays in the settle band to the plan's end, `u16 [P]`
    /// (`NO_SETTLE`: not at the end), back to back and coasted. Where a
    /// chain of legs is cut (`lookup::chain_plan`).
    PlanSettle = 28,
    CoastedPlanSettle = 29,
}

impl Section {
    /// Every section, in file order.
    pub const ALL: [Section; 29] = [
        Section::Axes,
        Section::Scalars,
        Section::PlanU,
        Section::PlanReached,
        Section::PlanMinTime,
        Section::CoastedPlanU,
        Section::CoastedPlanReached,
        Section::CoastedPlanMinTime,
        Section::IndexCells,
        Section::Index,
        Section::CoastedIndex,
        Section::FinePlanU,
        Section::CoastedFinePlanU,
        Section::FineReached,
        Section::FirstLeg,
        Section::ChainTime,
        Section::ExplicitSamples,
        Section::ExplicitState,
        Section::ExplicitIndexSlot,
        Section::CoastedExplicitIndexSlot,
        Section::FineExplicitSlot,
        Section::CoastedFineExplicitSlot,
        Section::PlanStates,
        Section::PlanMeta,
        Section::CoastedPlanStates,
        Section::CoastedPlanMeta,
        Section::GeneratorVersion,
        Section::PlanSettle,
        Section::CoastedPlanSettle,
    ];
    pub const COUNT: usize = Section::ALL.len();
    /// The explicit tier's sections.
    pub const EXPLICIT: [Section; 6] = [
        Section::ExplicitSamples,
        Section::ExplicitState,
        Section::ExplicitIndexSlot,
        Section::CoastedExplicitIndexSlot,
        Section::FineExplicitSlot,
        Section::CoastedFineExplicitSlot,
    ];

    /// Position in `ALL` (and in the directory).
    pub const fn position(self) -> usize {
        self as usize - 1
    }

    /// Bytes of one element (the explicit samples' record size depends on
    /// N and NX: see `ExplicitLayout::record_bytes`; 0 here).
    pub const fn element_bytes(self) -> usize {
        match self {
            Section::Axes => AXIS_BYTES,
            Section::PlanReached
            | Section::CoastedPlanReached
            | Section::FineReached
            | Section::GeneratorVersion => 1,
            Section::FirstLeg
            | Section::ExplicitIndexSlot
            | Section::CoastedExplicitIndexSlot
            | Section::FineExplicitSlot
            | Section::CoastedFineExplicitSlot
            | Section::PlanSettle
            | Section::CoastedPlanSettle => 2,
            Section::Index | Section::CoastedIndex => 4,
            Section::PlanMeta | Section::CoastedPlanMeta => PLAN_META_BYTES,
            Section::ExplicitSamples => 0,
            _ => 8,
        }
    }

    /// The section's name in summaries and errors.
    pub const fn name(self) -> &'static str {
        match self {
            Section::Axes => "axes",
            Section::Scalars => "scalars",
            Section::PlanU => "plan_u",
            Section::PlanReached => "plan_reached",
            Section::PlanMinTime => "plan_min_time_s",
            Section::CoastedPlanU => "coasted_plan_u",
            Section::CoastedPlanReached => "coasted_plan_reached",
            Section::CoastedPlanMinTime => "coasted_plan_min_time_s",
            Section::IndexCells => "index_cells",
            Section::Index => "index",
            Section::CoastedIndex => "coasted_index",
            Section::FinePlanU => "fine_plan_u",
            Section::CoastedFinePlanU => "coasted_fine_plan_u",
            Section::FineReached => "fine_reached",
            Section::FirstLeg => "first_leg",
            Section::ChainTime => "chain_time_s",
            Section::ExplicitSamples => "explicit_samples",
            Section::ExplicitState => "explicit_state",
            Section::ExplicitIndexSlot => "explicit_index_slot",
            Section::CoastedExplicitIndexSlot => "coasted_explicit_index_slot",
            Section::FineExplicitSlot => "fine_explicit_slot",
            Section::CoastedFineExplicitSlot => "coasted_fine_explicit_slot",
            Section::PlanStates => "plan_states",
            Section::PlanMeta => "plan_meta",
            Section::CoastedPlanStates => "coasted_plan_states",
            Section::CoastedPlanMeta => "coasted_plan_meta",
            Section::GeneratorVersion => "generator_version",
            Section::PlanSettle => "plan_settle_sample",
            Section::CoastedPlanSettle => "coasted_plan_settle_sample",
        }
    }
}

/// Bytes of one plan's metadata: cost f64, SQP iterations u32, arrival samples u32.
pub const PLAN_META_BYTES: usize = 16;

/// Layout of one explicit sample record for window `n` and `nx` states:
/// f64 fields first (hessian upper triangle, gradient, sensitivity `[n][nx]`,
/// cost, cost gradient `[nx]`, cost Hessian `[nx][nx]`), then source u8, plan
/// u16, offset u16, next u16, active `i8 [n]`, zero padding to 8 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExplicitLayout {
    pub n: usize,
    pub nx: usize,
}

impl ExplicitLayout {
    /// Entries of the window Hessian's upper triangle.
    pub const fn hessian_len(&self) -> usize {
        self.n * (self.n + 1) / 2
    }
    pub const fn hessian(&self) -> usize {
        0
    }
    pub const fn gradient(&self) -> usize {
        self.hessian() + 8 * self.hessian_len()
    }
    pub const fn sensitivity(&self) -> usize {
        self.gradient() + 8 * self.n
    }
    pub const fn cost(&self) -> usize {
        self.sensitivity() + 8 * self.n * self.nx
    }
    pub const fn cost_gradient(&self) -> usize {
        self.cost() + 8
    }
    pub const fn cost_hessian(&self) -> usize {
        self.cost_gradient() + 8 * self.nx
    }
    pub const fn source(&self) -> usize {
        self.cost_hessian() + 8 * self.nx * self.nx
    }
    pub const fn plan(&self) -> usize {
        self.source() + 1
    }
    pub const fn offset(&self) -> usize {
        self.plan() + 2
    }
    pub const fn active(&self) -> usize {
        self.offset() + 2
    }
    /// Bytes of one record (a multiple of 8).
    pub const fn record_bytes(&self) -> usize {
        let end = self.active() + self.n;
        end.div_ceil(SECTION_ALIGN) * SECTION_ALIGN
    }
}
