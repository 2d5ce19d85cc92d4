//! Safe, alignment-independent reading of a table file (see `format`).
//!
//! [`Tables::parse`] is a `const fn`: an emitted module parses its
//! `include_bytes!` blob at compile time, so a truncated file, another
//! format version, other dimensions or another config's tables fail the
//! build with a message. The SHA-256 trailer (a flipped bit inside a stored
//! float still parses, to a wrong plan) is checked once at run time by
//! [`Tables::verify`], before any number is used (`Controller::new`).

use crate::format::{
    Axis, ExplicitLayout, Section, AXIS_BYTES, AXIS_COUNT, CHECKSUM_BYTES, CONFIG_HASH_OFFSET,
    DIMS_OFFSET, DIRECTORY_ENTRY_BYTES, EMPTY_AXIS, FORMAT_VERSION, HEADER_BYTES, MAGIC,
    SCALAR_COUNT, SECTION_ALIGN,
};
use core::sync::atomic::{AtomicU8, Ordering};
use sha2::{Digest, Sha256};

/// Why a table file is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableError {
    /// Shorter than its header, directory and checksum.
    Truncated,
    /// The first eight bytes are not `format::MAGIC`.
    Magic,
    /// Another format version.
    Version { found: u32 },
    /// Made for other dimensions (M, NX, N, K).
    Dimensions,
    /// Made from another config (header hash differs from the module's).
    ConfigMismatch,
    /// The directory does not list the sections of this format.
    Directory { position: usize },
    /// A section lies outside the file, is misaligned, or has a length that
    /// is not a whole number of elements.
    SectionBounds { section: Section },
    /// Section lengths disagree with each other (counts of plans, cells, ...).
    SectionCounts { section: Section },
    /// The SHA-256 trailer is not the hash of the bytes before it.
    Checksum,
}

impl TableError {
    /// One line naming what is wrong (the format's own words).
    pub const fn message(&self) -> &'static str {
        match self {
            TableError::Truncated => {
                "table file is truncated (shorter than its header, directory and checksum)"
            }
            TableError::Magic => "not a capsule-mpc table file (magic bytes differ)",
            TableError::Version { .. } => "table file has another format version; regenerate",
            TableError::Dimensions => {
                "table file was made for other dimensions (M, NX, N, K); regenerate"
            }
            TableError::ConfigMismatch => "table file was made from a different config; regenerate",
            TableError::Directory { .. } => {
                "table file directory does not list this format's sections"
            }
            TableError::SectionBounds { .. } => {
                "table file section lies outside the file or is not whole elements"
            }
            TableError::SectionCounts { .. } => "table file sections disagree in their counts",
            TableError::Checksum => {
                "table file is corrupted: its SHA-256 trailer does not match its bytes; regenerate"
            }
        }
    }
}

impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())?;
        match self {
            TableError::Version { found } => {
                write!(f, " (found {found}, this build reads {FORMAT_VERSION})")
            }
            TableError::Directory { position } => write!(f, " (entry {position})"),
            TableError::SectionBounds { section } | TableError::SectionCounts { section } => {
                write!(f, " (section `{}`)", section.name())
            }
            _ => Ok(()),
        }
    }
}

/// Dimensions a table file is made for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// Capsules.
    pub m: usize,
    /// States, 2 M.
    pub nx: usize,
    /// Online window.
    pub n: usize,
    /// Plan length.
    pub k: usize,
}

/// Which stored plan set a look-up reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanSet {
    /// Back-to-back plans (ideal and variable sampling).
    BackToBack,
    /// One sample per phase with a coast after it (constant sampling).
    Coasted,
    /// The fine end-game plans, back to back and coasted.
    Fine,
    CoastedFine,
}

/// A parsed table file: the bytes and where each section lies.
#[derive(Debug, Clone, Copy)]
pub struct Tables<'a> {
    bytes: &'a [u8],
    /// Per section (in `Section::ALL` order): byte offset and length.
    offsets: [usize; Section::COUNT],
    lengths: [usize; Section::COUNT],
    pub dims: Dims,
    pub explicit_layout: ExplicitLayout,
    pub plan_axis: Axis,
    pub index_position_axis: Axis,
    pub index_speed_axis: Axis,
    pub leg_axis: Axis,
    pub fine_axis: Axis,
    /// Number of stored plans (per set), kept index cells, fine grid
    /// points, leg lattice cells and explicit samples.
    pub plan_count: usize,
    pub cell_count: usize,
    pub fine_count: usize,
    pub leg_count: usize,
    pub explicit_count: usize,
    /// The file's config hash.
    pub config_hash: [u8; 32],
}

const fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

const fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes([
        b[at],
        b[at + 1],
        b[at + 2],
        b[at + 3],
        b[at + 4],
        b[at + 5],
        b[at + 6],
        b[at + 7],
    ])
}

const fn le_f64(b: &[u8], at: usize) -> f64 {
    f64::from_bits(le_u64(b, at))
}

/// `base^exp` without overflow (saturates), for the grid size checks.
const fn saturating_pow(base: usize, exp: usize) -> usize {
    let mut r = 1usize;
    let mut i = 0;
    while i < exp {
        r = r.saturating_mul(base);
        i += 1;
    }
    r
}

impl<'a> Tables<'a> {
    /// Parses `bytes` as a table file for `dims` made from the config with
    /// SHA-256 `config_hash`: header, directory, section bounds and the
    /// counts the sections must agree on. Does not hash the contents (see
    /// [`Tables::verify`]).
    pub const fn parse(
        bytes: &'a [u8],
        dims: Dims,
        config_hash: &[u8; 32],
    ) -> Result<Tables<'a>, TableError> {
        let directory_end = HEADER_BYTES + Section::COUNT * DIRECTORY_ENTRY_BYTES;
        if bytes.len() < directory_end + CHECKSUM_BYTES {
            return Err(TableError::Truncated);
        }
        let mut i = 0;
        while i < MAGIC.len() {
            if bytes[i] != MAGIC[i] {
                return Err(TableError::Magic);
            }
            i += 1;
        }
        let version = le_u32(bytes, 8);
        if version != FORMAT_VERSION {
            return Err(TableError::Version { found: version });
        }
        if le_u32(bytes, 12) as usize != Section::COUNT {
            return Err(TableError::Directory {
                position: Section::COUNT,
            });
        }
        let file_dims = [
            le_u32(bytes, DIMS_OFFSET) as usize,
            le_u32(bytes, DIMS_OFFSET + 4) as usize,
            le_u32(bytes, DIMS_OFFSET + 8) as usize,
            le_u32(bytes, DIMS_OFFSET + 12) as usize,
        ];
        if file_dims[0] != dims.m
            || file_dims[1] != dims.nx
            || file_dims[2] != dims.n
            || file_dims[3] != dims.k
        {
            return Err(TableError::Dimensions);
        }
        let mut stored_hash = [0u8; 32];
        let mut i = 0;
        while i < 32 {
            stored_hash[i] = bytes[CONFIG_HASH_OFFSET + i];
            if stored_hash[i] != config_hash[i] {
                return Err(TableError::ConfigMismatch);
            }
            i += 1;
        }
        let explicit_layout = ExplicitLayout {
            n: dims.n,
            nx: dims.nx,
        };
        let payload_end = bytes.len() - CHECKSUM_BYTES;
        let mut offsets = [0usize; Section::COUNT];
        let mut lengths = [0usize; Section::COUNT];
        let mut p = 0;
        while p < Section::COUNT {
            let at = HEADER_BYTES + p * DIRECTORY_ENTRY_BYTES;
            let section = Section::ALL[p];
            let element = match section {
                Section::ExplicitSamples => explicit_layout.record_bytes(),
                s => s.element_bytes(),
            };
            if le_u32(bytes, at) != section as u32 || le_u32(bytes, at + 4) as usize != element {
                return Err(TableError::Directory { position: p });
            }
            let offset = le_u64(bytes, at + 8);
            let length = le_u64(bytes, at + 16);
            if offset > payload_end as u64
                || length > payload_end as u64 - offset
                || (offset as usize) < directory_end
                || !(offset as usize).is_multiple_of(SECTION_ALIGN)
                || !(length as usize).is_multiple_of(element)
            {
                return Err(TableError::SectionBounds { section });
            }
            offsets[p] = offset as usize;
            lengths[p] = length as usize;
            p += 1;
        }
        let mut t = Tables {
            bytes,
            offsets,
            lengths,
            dims,
            explicit_layout,
            plan_axis: EMPTY_AXIS,
            index_position_axis: EMPTY_AXIS,
            index_speed_axis: EMPTY_AXIS,
            leg_axis: EMPTY_AXIS,
            fine_axis: EMPTY_AXIS,
            plan_count: 0,
            cell_count: 0,
            fine_count: 0,
            leg_count: 0,
            explicit_count: 0,
            config_hash: stored_hash,
        };
        if t.elements(Section::Axes) != AXIS_COUNT {
            return Err(TableError::SectionCounts {
                section: Section::Axes,
            });
        }
        if t.elements(Section::Scalars) != SCALAR_COUNT {
            return Err(TableError::SectionCounts {
                section: Section::Scalars,
            });
        }
        t.plan_axis = t.axis(0);
        t.index_position_axis = t.axis(1);
        t.index_speed_axis = t.axis(2);
        t.leg_axis = t.axis(3);
        t.fine_axis = t.axis(4);
        let (k, nx) = (dims.k, dims.nx);
        t.plan_count = t.elements(Section::PlanReached);
        t.cell_count = t.elements(Section::IndexCells);
        t.fine_count = t.elements(Section::FineReached);
        t.leg_count = t.elements(Section::FirstLeg);
        t.explicit_count = t.elements(Section::ExplicitSamples);
        let (pc, cc, fc, ec) = (t.plan_count, t.cell_count, t.fine_count, t.explicit_count);
        // (section, expected element count, the other count allowed: a
        // module without explicit tier or coasted plans stores none)
        let checks: [(Section, usize, usize); 25] = [
            (Section::PlanU, pc * k, pc * k),
            (Section::PlanMinTime, pc, pc),
            (Section::CoastedPlanU, pc * k, 0),
            (Section::CoastedPlanReached, pc, 0),
            (Section::CoastedPlanMinTime, pc, 0),
            (Section::PlanSettle, pc, pc),
            (Section::CoastedPlanSettle, pc, 0),
            (Section::Index, cc, cc),
            (Section::CoastedIndex, cc, cc),
            (Section::FinePlanU, fc * k, fc * k),
            (Section::CoastedFinePlanU, fc * k, fc * k),
            (Section::ChainTime, t.leg_count, t.leg_count),
            (Section::ExplicitState, ec * nx, ec * nx),
            (Section::ExplicitIndexSlot, cc, 0),
            (Section::CoastedExplicitIndexSlot, cc, 0),
            (Section::FineExplicitSlot, fc, 0),
            (Section::CoastedFineExplicitSlot, fc, 0),
            (Section::PlanStates, pc * (k + 1) * nx, 0),
            (Section::PlanMeta, pc, 0),
            (Section::CoastedPlanStates, pc * (k + 1) * nx, 0),
            (Section::CoastedPlanMeta, pc, 0),
            (Section::Axes, AXIS_COUNT, AXIS_COUNT),
            (Section::Scalars, SCALAR_COUNT, SCALAR_COUNT),
            (Section::IndexCells, cc, cc),
            (Section::FirstLeg, t.leg_count, t.leg_count),
        ];
        let mut c = 0;
        while c < checks.len() {
            let (section, expected, alternative) = checks[c];
            let n = t.elements(section);
            if n != expected && n != alternative {
                return Err(TableError::SectionCounts { section });
            }
            c += 1;
        }
        // Grids are full lattices over the M capsules.
        let m = dims.m;
        if t.leg_count != saturating_pow(t.leg_axis.count, m) {
            return Err(TableError::SectionCounts {
                section: Section::FirstLeg,
            });
        }
        if pc > 0 && pc != saturating_pow(t.plan_axis.count, m) {
            return Err(TableError::SectionCounts {
                section: Section::PlanReached,
            });
        }
        if fc > 0 && fc != saturating_pow(t.fine_axis.count, m) {
            return Err(TableError::SectionCounts {
                section: Section::FineReached,
            });
        }
        Ok(t)
    }

    /// Checks the SHA-256 trailer over the whole file.
    pub fn verify(&self) -> Result<(), TableError> {
        let end = self.bytes.len() - CHECKSUM_BYTES;
        let digest = Sha256::digest(&self.bytes[..end]);
        if digest.as_slice() == &self.bytes[end..] {
            Ok(())
        } else {
            Err(TableError::Checksum)
        }
    }

    /// [`Tables::verify`] once per `state` (0: not checked, 1: good, 2:
    /// corrupt): the emitted module keeps one `AtomicU8` beside its blob.
    /// Only loads and stores, so it works on targets without atomic
    /// read-modify-write; two threads racing both hash, with one answer.
    pub fn verify_once(&self, state: &AtomicU8) -> Result<(), TableError> {
        match state.load(Ordering::Relaxed) {
            1 => Ok(()),
            2 => Err(TableError::Checksum),
            _ => {
                let r = self.verify();
                state.store(if r.is_ok() { 1 } else { 2 }, Ordering::Relaxed);
                r
            }
        }
    }

    /// The raw bytes (header to trailer).
    pub const fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Bytes of section data (what the tables hold, without header and padding).
    pub const fn data_bytes(&self) -> usize {
        let mut total = 0;
        let mut p = 0;
        while p < Section::COUNT {
            total += self.lengths[p];
            p += 1;
        }
        total
    }

    /// Bytes of `section` and its element count.
    pub const fn section_bytes(&self, section: Section) -> &'a [u8] {
        let p = section.position();
        let (start, len) = (self.offsets[p], self.lengths[p]);
        self.bytes.split_at(start).1.split_at(len).0
    }

    pub const fn elements(&self, section: Section) -> usize {
        let element = match section {
            Section::ExplicitSamples => self.explicit_layout.record_bytes(),
            s => s.element_bytes(),
        };
        self.lengths[section.position()] / element
    }

    const fn axis(&self, i: usize) -> Axis {
        let at = self.offsets[Section::Axes.position()] + i * AXIS_BYTES;
        Axis {
            start: le_f64(self.bytes, at),
            step: le_f64(self.bytes, at + 8),
            count: le_u64(self.bytes, at + 16) as usize,
        }
    }

    /// Byte position of element `i` of `section` (element size `size`);
    /// None past the section's end.
    #[inline(always)]
    fn at(&self, section: Section, i: usize, size: usize) -> Option<usize> {
        let p = section.position();
        let rel = i.checked_mul(size)?;
        if rel + size > self.lengths[p] {
            return None;
        }
        Some(self.offsets[p] + rel)
    }

    /// Element `i` of an f64 section; NaN past its end (parse bounds every
    /// section, and the look-ups check their indices first).
    #[inline(always)]
    pub fn f64_at(&self, section: Section, i: usize) -> f64 {
        match self.at(section, i, 8) {
            Some(at) => read_f64(self.bytes, at),
            None => f64::NAN,
        }
    }

    /// Element `i` of a u64 section (u64::MAX past its end).
    #[inline(always)]
    pub fn u64_at(&self, section: Section, i: usize) -> u64 {
        match self.at(section, i, 8) {
            Some(at) => read_u64(self.bytes, at),
            None => u64::MAX,
        }
    }

    /// Element `i` of a u32 section (u32::MAX past its end).
    #[inline(always)]
    pub fn u32_at(&self, section: Section, i: usize) -> u32 {
        match self.at(section, i, 4) {
            Some(at) => {
                let mut a = [0u8; 4];
                a.copy_from_slice(&self.bytes[at..at + 4]);
                u32::from_le_bytes(a)
            }
            None => u32::MAX,
        }
    }

    /// Element `i` of a u16 section (u16::MAX past its end).
    #[inline(always)]
    pub fn u16_at(&self, section: Section, i: usize) -> u16 {
        match self.at(section, i, 2) {
            Some(at) => u16::from_le_bytes([self.bytes[at], self.bytes[at + 1]]),
            None => u16::MAX,
        }
    }

    /// Element `i` of a u8 section (0 past its end).
    #[inline(always)]
    pub fn u8_at(&self, section: Section, i: usize) -> u8 {
        match self.at(section, i, 1) {
            Some(at) => self.bytes[at],
            None => 0,
        }
    }

    /// Scalar `i` of the `Scalars` section (see `format::SCALAR_*`).
    pub fn scalar(&self, i: usize) -> f64 {
        self.f64_at(Section::Scalars, i)
    }

    /// Gradient `k` of plan `p` in `set`, T/m (NaN outside the table).
    #[inline(always)]
    pub fn plan_u(&self, set: PlanSet, p: usize, k: usize) -> f64 {
        let section = match set {
            PlanSet::BackToBack => Section::PlanU,
            PlanSet::Coasted => Section::CoastedPlanU,
            PlanSet::Fine => Section::FinePlanU,
            PlanSet::CoastedFine => Section::CoastedFinePlanU,
        };
        if k >= self.dims.k {
            return f64::NAN;
        }
        self.f64_at(section, p * self.dims.k + k)
    }

    /// Inputs `k..k + out.len()` of plan `p` of `set` as one run (NaN past
    /// the plan's length, as `plan_u`).
    #[inline(always)]
    pub fn plan_u_run(&self, set: PlanSet, p: usize, k: usize, out: &mut [f64]) {
        let section = match set {
            PlanSet::BackToBack => Section::PlanU,
            PlanSet::Coasted => Section::CoastedPlanU,
            PlanSet::Fine => Section::FinePlanU,
            PlanSet::CoastedFine => Section::CoastedFinePlanU,
        };
        let first = p
            .checked_mul(self.dims.k)
            .and_then(|row| row.checked_add(k));
        match first {
            Some(first) if k + out.len() <= self.dims.k => self.f64_run(section, first, out),
            _ => out.fill(f64::NAN),
        }
    }

    /// Byte position of explicit sample `slot`'s record (None past the end).
    #[inline(always)]
    pub fn explicit_record(&self, slot: usize) -> Option<usize> {
        self.at(
            Section::ExplicitSamples,
            slot,
            self.explicit_layout.record_bytes(),
        )
    }

    /// The f64 at byte `at + field + 8 i` of the file (explicit records).
    #[inline(always)]
    pub fn record_f64(&self, at: usize, field: usize, i: usize) -> f64 {
        read_f64(self.bytes, at + field + 8 * i)
    }

    /// `out.len()` consecutive f64s from byte `at + field + 8 first` of
    /// the file (a run of an explicit record's field): one bounds check
    /// for the run instead of one per value; NaN past the file's end.
    #[inline(always)]
    pub fn record_f64s(&self, at: usize, field: usize, first: usize, out: &mut [f64]) {
        read_f64s(self.bytes, at + field + 8 * first, out);
    }

    /// Elements `first..first + out.len()` of an f64 section (NaN past its
    /// end), with one bounds check for the run.
    #[inline(always)]
    pub fn f64_run(&self, section: Section, first: usize, out: &mut [f64]) {
        let bytes = self.section_bytes(section);
        match first.checked_mul(8) {
            Some(at) => read_f64s(bytes, at, out),
            None => out.fill(f64::NAN),
        }
    }

    #[inline(always)]
    pub fn record_u16(&self, at: usize, field: usize) -> u16 {
        let b = at + field;
        u16::from_le_bytes([self.bytes[b], self.bytes[b + 1]])
    }

    #[inline(always)]
    pub fn record_u8(&self, at: usize, field: usize) -> u8 {
        self.bytes[at + field]
    }
}

#[inline(always)]
fn read_u64(bytes: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(a)
}

#[inline(always)]
fn read_f64(bytes: &[u8], at: usize) -> f64 {
    f64::from_bits(read_u64(bytes, at))
}

/// `out.len()` little-endian f64s from byte `at` of `bytes`; NaN for the
/// whole run when it does not fit.
#[inline(always)]
fn read_f64s(bytes: &[u8], at: usize, out: &mut [f64]) {
    let run = at
        .checked_add(8 * out.len())
        .and_then(|end| bytes.get(at..end));
    match run {
        Some(run) => {
            for (o, c) in out.iter_mut().zip(run.chunks_exact(8)) {
                let mut a = [0u8; 8];
                a.copy_from_slice(c);
                *o = f64::from_le_bytes(a);
            }
        }
        None => out.fill(f64::NAN),
    }
}
