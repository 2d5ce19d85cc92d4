//! The table file of one controller module: the generator writes it, the
//! online solver reads it in place (`capsule_mpc_solver::format`), and
//! `generate --reuse-tables` reads it back. One source of truth: the same
//! bytes serve all three, and a human-readable summary beside it makes a
//! regeneration diff reviewable.

use crate::config::Config;
use crate::explicit::ExplicitTables;
use crate::grid::{unflatten, Axis, PlanEntry};
use crate::legs::{LegTable, NO_LEG};
use crate::mintime::{arrival_sample, SETTLE_BAND};
use crate::ocp::{OcpWeights, Plan};
use crate::tables::{
    config_hash, hex, CoastedTables, FineTables, SwitchingConstants, TableError, TableHeader,
    Tables,
};
use capsule_mpc_solver::format::{self, Section, NO_PLAN};
use capsule_mpc_solver::tables::{Dims, Tables as FileTables};
use capsule_mpc_solver::write::TableWriter;
use std::fmt::Write as _;

/// The dimensions a config's module has (M, NX, N, K).
pub fn dims(config: &Config) -> Dims {
    let m = config.capsule_count();
    Dims {
        m,
        nx: 2 * m,
        n: config.controller.horizon_steps,
        k: config.controller.plan_steps,
    }
}

fn file_axis(a: &Axis) -> format::Axis {
    format::Axis {
        start: a.start,
        step: a.step,
        count: a.count,
    }
}

fn grid_axis(a: format::Axis) -> Axis {
    Axis {
        start: a.start,
        step: a.step,
        count: a.count,
    }
}

/// The sample from which a stored plan's states stay in the settle band
/// (`format::NO_SETTLE` when its last state is outside).
fn settle_sample(states: &[Vec<f64>]) -> u16 {
    match arrival_sample(states, &SETTLE_BAND) {
        Some(k) => u16::try_from(k).unwrap_or(format::NO_SETTLE),
        None => format::NO_SETTLE,
    }
}

fn index_entry(&(plan, offset): &(u16, u16)) -> u32 {
    ((plan as u32) << 16) | offset as u32
}

/// The table file for `config`: `tables` None for a module without tables
/// (the paper preset: one dummy index cell and leg pointing at nothing),
/// `explicit` None without an explicit tier.
pub fn encode(
    config: &Config,
    tables: Option<&Tables>,
    explicit: Option<&ExplicitTables>,
) -> Vec<u8> {
    let d = dims(config);
    let mut w = TableWriter::new(d, config_hash(config));
    let Some(t) = tables else {
        let empty = format::EMPTY_AXIS;
        w.axes([empty; 5]);
        w.f64s(Section::Scalars, [0.0; format::SCALAR_COUNT]);
        w.u64s(Section::IndexCells, [0]);
        w.u32s(Section::Index, [NO_PLAN]);
        w.u32s(Section::CoastedIndex, [NO_PLAN]);
        w.u16s(Section::FirstLeg, [NO_LEG]);
        w.f64s(Section::ChainTime, [f64::INFINITY]);
        w.u8s(Section::GeneratorVersion, env!("CARGO_PKG_VERSION").bytes());
        return w.finish();
    };
    w.axes([
        file_axis(&t.plan_axis),
        file_axis(&t.index_position_axis),
        file_axis(&t.index_speed_axis),
        file_axis(&t.legs.axis),
        file_axis(&t.fine.axis),
    ]);
    let s = &t.switching;
    w.f64s(
        Section::Scalars,
        [t.coasted.coast_s, s.l_f, s.l_l, s.l_v, s.x_diameter],
    );
    let k = d.k;
    let plan_sets = [
        (
            &t.plans,
            Section::PlanU,
            Section::PlanReached,
            Section::PlanMinTime,
            Section::PlanStates,
            Section::PlanMeta,
            Section::PlanSettle,
        ),
        (
            &t.coasted.plans,
            Section::CoastedPlanU,
            Section::CoastedPlanReached,
            Section::CoastedPlanMinTime,
            Section::CoastedPlanStates,
            Section::CoastedPlanMeta,
            Section::CoastedPlanSettle,
        ),
    ];
    for (plans, u, reached, min_time, states, meta, settle) in plan_sets {
        for p in plans.iter() {
            assert_eq!(p.plan.u.len(), k, "plan length");
            assert_eq!(p.plan.states.len(), k + 1, "plan states");
            w.f64s(u, p.plan.u.iter().copied());
            w.u8s(reached, [p.reached as u8]);
            w.f64s(min_time, [p.min_time_s]);
            for row in &p.plan.states {
                assert_eq!(row.len(), d.nx, "plan state width");
                w.f64s(states, row.iter().copied());
            }
            w.plan_meta(
                meta,
                p.plan.cost,
                p.plan.iterations as u32,
                p.arrival_samples as u32,
            );
            w.u16s(settle, [settle_sample(&p.plan.states)]);
        }
    }
    w.u64s(Section::IndexCells, t.index_cells.iter().copied());
    w.u32s(Section::Index, t.index.iter().map(index_entry));
    w.u32s(
        Section::CoastedIndex,
        t.coasted.index.iter().map(index_entry),
    );
    for (rows, section) in [
        (&t.fine.plans, Section::FinePlanU),
        (&t.fine.coasted_plans, Section::CoastedFinePlanU),
    ] {
        for row in rows.iter() {
            assert_eq!(row.len(), k, "fine plan length");
            w.f64s(section, row.iter().copied());
        }
    }
    let fine_reached = t
        .fine
        .plans
        .iter()
        .zip(&t.fine.coasted_plans)
        .map(|(a, b)| (a.iter().any(|v| *v != 0.0) && b.iter().any(|v| *v != 0.0)) as u8);
    w.u8s(Section::FineReached, fine_reached);
    w.u16s(Section::FirstLeg, t.legs.first_leg.iter().copied());
    w.f64s(Section::ChainTime, t.legs.chain_time_s.iter().copied());
    if let Some(e) = explicit {
        for s in &e.samples {
            w.explicit_sample(
                &s.hessian,
                &s.gradient,
                &s.sensitivity,
                s.cost,
                &s.cost_gradient,
                &s.cost_hessian,
                s.source as u8,
                u16::try_from(s.plan).expect("explicit plan index fits u16"),
                u16::try_from(s.offset).expect("explicit offset fits u16"),
                &s.active,
            );
            w.f64s(Section::ExplicitState, s.state.iter().copied());
        }
        w.u16s(Section::ExplicitIndexSlot, e.index_slot.iter().copied());
        w.u16s(
            Section::CoastedExplicitIndexSlot,
            e.coasted_index_slot.iter().copied(),
        );
        w.u16s(Section::FineExplicitSlot, e.fine_slot.iter().copied());
        w.u16s(
            Section::CoastedFineExplicitSlot,
            e.coasted_fine_slot.iter().copied(),
        );
    }
    w.u8s(
        Section::GeneratorVersion,
        t.header.generator_version.bytes(),
    );
    w.finish()
}

fn file_error(e: capsule_mpc_solver::TableError, bytes: &[u8]) -> TableError {
    use capsule_mpc_solver::TableError as E;
    match e {
        E::Magic => {
            let mut found = [0u8; 8];
            found.copy_from_slice(&bytes[..8]);
            TableError::Magic { found }
        }
        E::Version { found } => TableError::Version {
            found,
            expected: format::FORMAT_VERSION,
        },
        other => TableError::Corrupt(other.to_string()),
    }
}

/// Reads the table file at `path` (see [`decode`]).
pub fn read(path: &std::path::Path, config: &Config) -> Result<Tables, TableError> {
    let bytes = std::fs::read(path).map_err(|e| TableError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    decode(&bytes, config)
}

/// Reads a table file back into the generator's tables for `config`
/// (format, dimensions, config hash and checksum are checked first). A
/// module without tables has none to read.
pub fn decode(bytes: &[u8], config: &Config) -> Result<Tables, TableError> {
    let d = dims(config);
    let expected = config_hash(config);
    let f = match FileTables::parse(bytes, d, &expected) {
        Ok(f) => f,
        Err(capsule_mpc_solver::TableError::ConfigMismatch) => {
            let found = bytes
                .get(format::CONFIG_HASH_OFFSET..format::CONFIG_HASH_OFFSET + 32)
                .unwrap_or(&[]);
            return Err(TableError::ConfigMismatch {
                found: hex(found),
                expected: hex(&expected),
            });
        }
        Err(e) => return Err(file_error(e, bytes)),
    };
    f.verify().map_err(|_| {
        let end = bytes.len() - format::CHECKSUM_BYTES;
        TableError::Checksum {
            stored: hex(&bytes[end..]),
            computed: hex(&<sha2::Sha256 as sha2::Digest>::digest(&bytes[..end])),
        }
    })?;
    if f.plan_count == 0 {
        return Err(TableError::Corrupt(
            "the file holds no plans (a module without tables)".into(),
        ));
    }
    if f.elements(Section::PlanStates) == 0 || f.elements(Section::CoastedPlanU) == 0 {
        return Err(TableError::Corrupt(
            "the file lacks the generator's plan data".into(),
        ));
    }
    let (k, nx, m) = (d.k, d.nx, d.m);
    let plan_axis = grid_axis(f.plan_axis);
    let plans_of = |u: Section,
                    reached: Section,
                    min_time: Section,
                    states: Section,
                    meta: Section|
     -> Vec<PlanEntry> {
        (0..f.plan_count)
            .map(|p| {
                let meta_bytes = &f.section_bytes(meta)
                    [p * format::PLAN_META_BYTES..(p + 1) * format::PLAN_META_BYTES];
                let word = |at: usize| {
                    u32::from_le_bytes(meta_bytes[at..at + 4].try_into().expect("4 bytes"))
                };
                let e0 = unflatten(p, &vec![plan_axis.count; m])
                    .iter()
                    .flat_map(|&i| [plan_axis.value(i), 0.0])
                    .collect();
                PlanEntry {
                    e0,
                    plan: Plan {
                        u: (0..k).map(|j| f.f64_at(u, p * k + j)).collect(),
                        states: (0..=k)
                            .map(|r| {
                                (0..nx)
                                    .map(|c| f.f64_at(states, (p * (k + 1) + r) * nx + c))
                                    .collect()
                            })
                            .collect(),
                        cost: f64::from_le_bytes(meta_bytes[0..8].try_into().expect("8 bytes")),
                        iterations: word(8) as usize,
                    },
                    reached: f.u8_at(reached, p) != 0,
                    arrival_samples: word(12) as usize,
                    min_time_s: f.f64_at(min_time, p),
                }
            })
            .collect()
    };
    let index_of = |s: Section| -> Vec<(u16, u16)> {
        (0..f.cell_count)
            .map(|c| {
                let v = f.u32_at(s, c);
                ((v >> 16) as u16, (v & 0xffff) as u16)
            })
            .collect()
    };
    let rows_of = |s: Section| -> Vec<Vec<f64>> {
        (0..f.fine_count)
            .map(|p| (0..k).map(|j| f.f64_at(s, p * k + j)).collect())
            .collect()
    };
    let version = String::from_utf8_lossy(f.section_bytes(Section::GeneratorVersion)).into_owned();
    Ok(Tables {
        header: TableHeader {
            magic: format::MAGIC,
            format_version: format::FORMAT_VERSION,
            config_hash: f.config_hash,
            generator_version: version,
        },
        plan_steps: k,
        plan_axis: plan_axis.clone(),
        plans: plans_of(
            Section::PlanU,
            Section::PlanReached,
            Section::PlanMinTime,
            Section::PlanStates,
            Section::PlanMeta,
        ),
        index_position_axis: grid_axis(f.index_position_axis),
        index_speed_axis: grid_axis(f.index_speed_axis),
        index_cells: (0..f.cell_count)
            .map(|c| f.u64_at(Section::IndexCells, c))
            .collect(),
        index: index_of(Section::Index),
        switching: SwitchingConstants {
            l_f: f.scalar(format::SCALAR_L_F),
            l_l: f.scalar(format::SCALAR_L_L),
            l_v: f.scalar(format::SCALAR_L_V),
            x_diameter: f.scalar(format::SCALAR_X_DIAMETER),
        },
        legs: LegTable {
            axis: grid_axis(f.leg_axis),
            first_leg: (0..f.leg_count)
                .map(|c| f.u16_at(Section::FirstLeg, c))
                .collect(),
            chain_time_s: (0..f.leg_count)
                .map(|c| f.f64_at(Section::ChainTime, c))
                .collect(),
        },
        coasted: CoastedTables {
            coast_s: f.scalar(format::SCALAR_COAST_S),
            plans: plans_of(
                Section::CoastedPlanU,
                Section::CoastedPlanReached,
                Section::CoastedPlanMinTime,
                Section::CoastedPlanStates,
                Section::CoastedPlanMeta,
            ),
            index: index_of(Section::CoastedIndex),
        },
        fine: FineTables {
            axis: grid_axis(f.fine_axis),
            plans: rows_of(Section::FinePlanU),
            coasted_plans: rows_of(Section::CoastedFinePlanU),
        },
    })
}

/// Range of the finite values of an f64 section and how many are infinite.
fn f64_range(f: &FileTables, s: Section) -> Option<(f64, f64, usize)> {
    let n = f.elements(s);
    if n == 0 {
        return None;
    }
    let (mut lo, mut hi, mut inf) = (f64::INFINITY, f64::NEG_INFINITY, 0);
    for i in 0..n {
        let v = f.f64_at(s, i);
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        } else {
            inf += 1;
        }
    }
    Some((lo, hi, inf))
}

/// A human-readable summary of a table file: dimensions, axes, per section
/// its element count, bytes and value range, and the hashes. Committed
/// beside the file, so a regeneration's diff shows what changed.
pub fn summary(bytes: &[u8], config: &Config, name: &str) -> Result<String, TableError> {
    let d = dims(config);
    let f = FileTables::parse(bytes, d, &config_hash(config)).map_err(|e| file_error(e, bytes))?;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# @generated by capsule-mpc-generator: summary of `{name}`. Do not edit."
    );
    let _ = writeln!(
        out,
        "format version {}, {} bytes",
        format::FORMAT_VERSION,
        bytes.len()
    );
    let _ = writeln!(out, "config sha256 {}", hex(&f.config_hash));
    let _ = writeln!(
        out,
        "file sha256 {}",
        hex(&bytes[bytes.len() - format::CHECKSUM_BYTES..])
    );
    let _ = writeln!(out, "dims M {} NX {} N {} K {}", d.m, d.nx, d.n, d.k);
    let w = OcpWeights::from_config(config);
    let _ = writeln!(out, "weights q {:?} r {:?} p {:?}", w.q, w.r, w.p);
    let axes = [
        ("plan", f.plan_axis),
        ("index position", f.index_position_axis),
        ("index speed", f.index_speed_axis),
        ("leg", f.leg_axis),
        ("fine", f.fine_axis),
    ];
    for (n, a) in axes {
        let _ = writeln!(
            out,
            "axis {n}: start {:?} step {:?} count {}",
            a.start, a.step, a.count
        );
    }
    let _ = writeln!(
        out,
        "counts: plans {} (reached {}), index cells {}, fine points {}, leg cells {}, explicit samples {}",
        f.plan_count,
        (0..f.plan_count).filter(|&p| f.u8_at(Section::PlanReached, p) != 0).count(),
        f.cell_count,
        f.fine_count,
        f.leg_count,
        f.explicit_count
    );
    let _ = writeln!(
        out,
        "section                          elements        bytes  range"
    );
    for s in Section::ALL {
        let n = f.elements(s);
        let bytes_len = f.section_bytes(s).len();
        let range = match s.element_bytes() {
            8 if !matches!(s, Section::IndexCells) => match f64_range(&f, s) {
                Some((lo, hi, inf)) if inf > 0 => format!("[{lo:.6e}, {hi:.6e}], {inf} infinite"),
                Some((lo, hi, _)) => format!("[{lo:.6e}, {hi:.6e}]"),
                None => String::new(),
            },
            _ => String::new(),
        };
        let _ = writeln!(
            out,
            "{:<30} {:>10} {:>12}  {}",
            s.name(),
            n,
            bytes_len,
            range
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tables::{TABLE_FORMAT_VERSION, TABLE_MAGIC};
    use sha2::{Digest, Sha256};

    /// A distinctive stored value, found in the encoding by its bytes.
    const MARKER_T_PER_M: f64 = 0.012_345_678_9;

    /// The embedded config cut to two-sample plans and a one-sample window,
    /// so that hand-made tables fit its dimensions.
    fn small_config() -> Config {
        let mut config = Config::embedded_default();
        config.controller.plan_steps = 2;
        config.controller.horizon_steps = 1;
        config
    }

    /// Small tables for `small_config` (M = 2, K = 2): one plan, three
    /// index cells (the file checks do not depend on the contents).
    fn small_tables(config: &Config) -> Tables {
        let plan = PlanEntry {
            e0: vec![0.01, 0.0, 0.01, 0.0],
            plan: Plan {
                u: vec![MARKER_T_PER_M, -0.02],
                states: vec![
                    vec![0.01, 0.0, 0.01, 0.0],
                    vec![0.005, -0.1, 0.006, -0.09],
                    vec![0.0, 0.0, 0.0, 0.0],
                ],
                cost: 1.5,
                iterations: 3,
            },
            reached: true,
            arrival_samples: 2,
            min_time_s: 0.04,
        };
        let one = Axis {
            start: 0.01,
            step: 0.01,
            count: 1,
        };
        Tables {
            header: TableHeader {
                magic: TABLE_MAGIC,
                format_version: TABLE_FORMAT_VERSION,
                config_hash: config_hash(config),
                generator_version: "test".to_string(),
            },
            plan_steps: 2,
            plan_axis: one.clone(),
            plans: vec![plan.clone()],
            index_position_axis: Axis::symmetric(0.01, 0.01),
            index_speed_axis: Axis::symmetric(0.1, 0.1),
            index_cells: vec![0, 4, 8],
            index: vec![(0, 0), (0, 1), (u16::MAX, 0)],
            switching: SwitchingConstants {
                l_f: 1.0,
                l_l: 2.0,
                l_v: 3.0,
                x_diameter: 0.1,
            },
            legs: LegTable {
                axis: one.clone(),
                first_leg: vec![0],
                chain_time_s: vec![f64::INFINITY],
            },
            coasted: CoastedTables {
                coast_s: 0.02,
                plans: vec![PlanEntry {
                    min_time_s: f64::INFINITY,
                    reached: false,
                    ..plan
                }],
                index: vec![(0, 1), (u16::MAX, 0), (0, 0)],
            },
            fine: FineTables {
                axis: one,
                plans: vec![vec![0.0, 0.01]],
                coasted_plans: vec![vec![0.01, 0.0]],
            },
        }
    }

    #[test]
    fn tables_round_trip_with_a_checksum_trailer() {
        let config = small_config();
        let tables = small_tables(&config);
        let bytes = encode(&config, Some(&tables), None);
        let payload = &bytes[..bytes.len() - 32];
        let digest: [u8; 32] = Sha256::digest(payload).into();
        assert_eq!(&bytes[payload.len()..], &digest[..]);
        assert_eq!(decode(&bytes, &config).unwrap(), tables);
    }

    /// The case the checksum exists for: one flipped bit inside a stored
    /// float still parses (to a different plan), and is refused.
    #[test]
    fn a_flipped_bit_inside_a_float_is_refused_by_the_checksum() {
        let config = small_config();
        let mut bytes = encode(&config, Some(&small_tables(&config)), None);
        let marker = MARKER_T_PER_M.to_le_bytes();
        let at = bytes
            .windows(8)
            .position(|w| w == marker)
            .expect("the marker float is stored as 8 little-endian bytes");
        bytes[at] ^= 1;
        let err = decode(&bytes, &config).unwrap_err();
        assert!(matches!(err, TableError::Checksum { .. }), "{err}");
        assert!(err.to_string().contains("SHA-256"), "{err}");
    }

    /// Every single-bit flip anywhere in the file is refused: in the
    /// header, the directory and the axes (whose counts the section lengths
    /// must match) by those checks, elsewhere by the checksum.
    #[test]
    fn every_single_bit_flip_is_refused() {
        let config = small_config();
        let bytes = encode(&config, Some(&small_tables(&config)), None);
        let data_start = format::HEADER_BYTES
            + format::DIRECTORY_ENTRY_BYTES * Section::COUNT
            + format::AXIS_BYTES * format::AXIS_COUNT;
        for bit in 0..8 * bytes.len() {
            let mut flipped = bytes.clone();
            flipped[bit / 8] ^= 1 << (bit % 8);
            let err = decode(&flipped, &config).unwrap_err();
            if bit >= 8 * data_start {
                assert!(
                    matches!(err, TableError::Checksum { .. }),
                    "bit {bit}: {err}"
                );
            }
        }
    }

    #[test]
    fn every_truncation_is_refused() {
        let config = small_config();
        let bytes = encode(&config, Some(&small_tables(&config)), None);
        for len in 0..bytes.len() {
            let err = decode(&bytes[..len], &config).unwrap_err();
            let text = err.to_string();
            assert!(
                text.contains("truncated") || text.contains("corrupted"),
                "{len}: {err}"
            );
        }
    }

    /// A file of another format version (the bincode files of earlier
    /// versions among them) is named as such, not as corrupt.
    #[test]
    fn another_format_version_is_refused_with_the_version_error() {
        let config = small_config();
        let mut bytes = encode(&config, Some(&small_tables(&config)), None);
        bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
        let err = decode(&bytes, &config).unwrap_err();
        assert!(
            matches!(
                err,
                TableError::Version {
                    found: 1,
                    expected: TABLE_FORMAT_VERSION
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("format version 1"), "{err}");
    }

    /// A wrong magic is reported as such, whatever follows it.
    #[test]
    fn a_wrong_magic_is_refused_with_the_magic_error() {
        let config = small_config();
        let mut bytes = encode(&config, Some(&small_tables(&config)), None);
        bytes[..8].copy_from_slice(b"\x89PNG\r\n\x1a\n");
        let err = decode(&bytes, &config).unwrap_err();
        assert!(matches!(err, TableError::Magic { .. }), "{err}");
        let err = decode(b"CMPCTBL", &config).unwrap_err();
        assert!(matches!(err, TableError::Corrupt(_)), "{err}");
    }

    #[test]
    fn another_config_is_refused() {
        let config = small_config();
        let mut other = config.clone();
        other.capsule[0].sphere_radius_m *= 2.0;
        let bytes = encode(&config, Some(&small_tables(&config)), None);
        let err = decode(&bytes, &other).unwrap_err();
        assert!(matches!(err, TableError::ConfigMismatch { .. }), "{err}");
    }

    /// The summary names every section and the hashes.
    #[test]
    fn the_summary_lists_every_section() {
        let config = small_config();
        let bytes = encode(&config, Some(&small_tables(&config)), None);
        let text = summary(&bytes, &config, "test.tables.bin").unwrap();
        for s in capsule_mpc_solver::format::Section::ALL {
            assert!(text.contains(s.name()), "{}", s.name());
        }
        assert!(text.contains(&hex(&config_hash(&config))));
    }
}
