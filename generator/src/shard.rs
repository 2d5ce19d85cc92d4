//! Sharded generation: the work of [`build_tables`](crate::tables::build_tables)
//! split over processes (cluster jobs), with the same bytes as the
//! single-process run whatever the shard count.
//!
//! # Rounds and units
//!
//! The continuation of [`grid_min_time_plans`](crate::mintime::grid_min_time_plans)
//! solves ring r of a grid from the plans of rings < r, so the work runs in
//! *rounds*; every unit of a round reads only the merged results of earlier
//! rounds, never a unit of its own round:
//!
//! | round            | unit                                   | reads            |
//! |------------------|----------------------------------------|------------------|
//! | `0 .. K-1`       | point of ring r = round + 1, every plan set that has that ring | rings < r |
//! | `K` (finish)     | improvement sweep of one point, then both mirror points finished at rest and rolled out | all rings |
//! | `K + 1` (index)  | one kept warm-start index cell (back-to-back and coasted) | finished plans |
//!
//! where K is the largest ring count over the four plan sets (main and
//! coasted over the plan grid, back-to-back and coasted over the fine
//! grid). The kept index cells (those near the finished plans' samples,
//! `occupied_cells`) are recomputed from the finish round's results by
//! every reader, deterministically. The legs and the file are assembled by
//! the merge. Each unit is a
//! pure function of the config and the earlier rounds (the functions the
//! single-process path calls), so which shard computes it, and how many
//! threads it has, does not change a bit.
//!
//! A round's units are listed in a fixed order and dealt round-robin: shard
//! I of N takes units I, I + N, I + 2N, ... (neighbouring points cost alike,
//! so every shard gets a similar mix). Each round may use its own N.
//!
//! # Part files
//!
//! A shard writes one part file: bincode(Part) + a SHA-256 trailer, with a
//! header naming the part format, the table format, the config hash, the
//! round and the shard. Reading a set of parts checks every one of these,
//! and that each earlier round is complete (shards 0..N-1, each once, one
//! N), before any result is used.

use crate::config::Config;
use crate::index::CellChooser;
use crate::mintime::MinTimePlan;
use crate::model::Model;
use crate::tables::{
    config_hash, hex, PlanEntry, PlanSet, Problems, Progress, Tables, TABLE_FORMAT_VERSION,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// First bytes of every part file.
pub const PART_MAGIC: [u8; 8] = *b"CAPSPART";
/// Bumped whenever the part layout or the round plan changes.
pub const PART_FORMAT_VERSION: u32 = 1;

/// `I/N`: shard I (0-based) of N.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardSpec {
    pub index: usize,
    pub count: usize,
}

impl std::fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for ShardSpec {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<ShardSpec, ShardError> {
        let bad = |why: &str| ShardError::Invalid(format!("--shard {s:?}: {why}"));
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected I/N, shard I (from 0) of N, e.g. 0/4"))?;
        let parse = |v: &str, what: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| bad(&format!("{what} {v:?} is not a non-negative integer")))
        };
        let (index, count) = (parse(i, "shard index")?, parse(n, "shard count")?);
        if count == 0 {
            return Err(bad("the shard count must be at least 1"));
        }
        if index >= count {
            return Err(bad(&format!(
                "shard index {index} must be below the shard count {count} (shards are 0..{})",
                count - 1
            )));
        }
        Ok(ShardSpec { index, count })
    }
}

/// Errors of sharded generation; each names the offending value or file.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    #[error("{0}")]
    Invalid(String),
    #[error("part file {path}: {reason}")]
    Part { path: String, reason: String },
    #[error("{path}: {reason}")]
    Io { path: String, reason: String },
}

fn part_err(path: &Path, reason: impl Into<String>) -> ShardError {
    ShardError::Part {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// One round of the work (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Round {
    /// Points of ring r (from 1) of every plan set that has it.
    Ring(usize),
    /// Improvement sweep and finishing of every point.
    Finish,
    /// Warm-start index cells.
    Index,
}

/// One unit of work: a grid point (ring and finish rounds) or an index
/// cell (index round) of a plan set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Unit {
    pub set: PlanSet,
    pub item: u32,
}

/// The result of one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Output {
    /// The minimum-time plan of a ring point (None: not reached).
    Ring(Option<MinTimePlan>),
    /// The finished entries of a point and of its mirror image (one entry
    /// for the centre, its own mirror).
    Finish(Vec<PlanEntry>),
    /// An index cell.
    Cell((u16, u16)),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartHeader {
    pub magic: [u8; 8],
    pub part_format_version: u32,
    pub table_format_version: u32,
    pub config_hash: [u8; 32],
    pub generator_version: String,
    pub round: u32,
    pub rounds: u32,
    pub shard: u32,
    pub shards: u32,
}

/// The results of one shard of one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Part {
    pub header: PartHeader,
    pub units: Vec<Unit>,
    pub outputs: Vec<Output>,
}

impl Part {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes =
            bincode::serde::encode_to_vec(self, bincode::config::standard()).expect("part encodes");
        let checksum: [u8; 32] = Sha256::digest(&bytes).into();
        bytes.extend_from_slice(&checksum);
        bytes
    }

    /// Magic and versions are checked from the header's first fields
    /// before the checksum, so a part of another version is named as such;
    /// then the checksum and the config hash.
    pub fn from_bytes(bytes: &[u8], config: &Config, path: &Path) -> Result<Part, ShardError> {
        let standard = bincode::config::standard();
        let corrupt = |why: String| part_err(path, format!("truncated or corrupted ({why})"));
        let (magic, _): ([u8; 8], usize) = bincode::serde::decode_from_slice(bytes, standard)
            .map_err(|e| corrupt(e.to_string()))?;
        if magic != PART_MAGIC {
            return Err(part_err(
                path,
                format!("magic {magic:?} is not a capsule-mpc part file's ({PART_MAGIC:?})"),
            ));
        }
        let ((_, part_version, table_version), _): (([u8; 8], u32, u32), usize) =
            bincode::serde::decode_from_slice(bytes, standard)
                .map_err(|e| corrupt(e.to_string()))?;
        if part_version != PART_FORMAT_VERSION || table_version != TABLE_FORMAT_VERSION {
            return Err(part_err(
                path,
                format!(
                    "part format version {part_version} for table format {table_version}; this \
                     build reads part format {PART_FORMAT_VERSION} for table format \
                     {TABLE_FORMAT_VERSION} (recompute the parts with this build)"
                ),
            ));
        }
        let payload_len = bytes
            .len()
            .checked_sub(32)
            .ok_or_else(|| corrupt(format!("{} bytes", bytes.len())))?;
        let (payload, stored) = bytes.split_at(payload_len);
        let computed: [u8; 32] = Sha256::digest(payload).into();
        if stored != computed {
            return Err(corrupt(format!(
                "payload SHA-256 is {}, the file stores {}",
                hex(&computed),
                hex(stored)
            )));
        }
        let (part, used): (Part, usize) = bincode::serde::decode_from_slice(payload, standard)
            .map_err(|e| corrupt(e.to_string()))?;
        if used != payload.len() {
            return Err(corrupt(format!("{} trailing bytes", payload.len() - used)));
        }
        let expected = config_hash(config);
        if part.header.config_hash != expected {
            return Err(part_err(
                path,
                format!(
                    "made from another config (hash {}, this config's hash {})",
                    hex(&part.header.config_hash),
                    hex(&expected)
                ),
            ));
        }
        Ok(part)
    }

    pub fn read(path: &Path, config: &Config) -> Result<Part, ShardError> {
        let bytes = std::fs::read(path).map_err(|e| ShardError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Part::from_bytes(&bytes, config, path)
    }

    /// Writes the part through a temporary file and a rename.
    pub fn write(&self, path: &Path) -> Result<(), ShardError> {
        crate::generate::write_file_atomically(path, &self.to_bytes()).map_err(|e| ShardError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
    }
}

/// The round plan of a config and the state the rounds build up.
pub struct Sharding<'a> {
    problems: Problems<'a>,
    rounds: Vec<Round>,
}

/// Results of the rounds applied so far.
struct State {
    /// Minimum-time plans per plan set (ring rounds, mirrored).
    min_time: Vec<Vec<Option<MinTimePlan>>>,
    /// Finished entries per plan set (finish round).
    entries: Vec<Vec<Option<PlanEntry>>>,
    /// The kept index cells, known once the finish round is applied.
    index_cells: Option<Vec<u64>>,
    /// Index entries per indexed set, one per kept cell (index round).
    index: Vec<Vec<Option<(u16, u16)>>>,
}

impl<'a> Sharding<'a> {
    pub fn new(config: &'a Config, model: &'a Model) -> Sharding<'a> {
        let problems = Problems::new(config, model);
        let rings = PlanSet::ALL
            .iter()
            .map(|&s| problems.search(s).rings())
            .max()
            .unwrap_or(0);
        let mut rounds: Vec<Round> = (1..=rings).map(Round::Ring).collect();
        rounds.push(Round::Finish);
        rounds.push(Round::Index);
        Sharding { problems, rounds }
    }

    pub fn rounds(&self) -> &[Round] {
        &self.rounds
    }

    fn round(&self, r: usize) -> Result<Round, ShardError> {
        self.rounds.get(r).copied().ok_or_else(|| {
            ShardError::Invalid(format!(
                "--round {r}: this config has {} rounds (0..{})",
                self.rounds.len(),
                self.rounds.len() - 1
            ))
        })
    }

    /// Every unit of round `r`, in the fixed order shards are dealt from;
    /// `index_cells` is the number of kept index cells (the index round's
    /// units; they depend on the finished plans).
    fn units(
        &self,
        r: usize,
        index_cells: usize,
    ) -> Result<Box<dyn Iterator<Item = Unit> + '_>, ShardError> {
        let unit = |set, item: usize| Unit {
            set,
            item: u32::try_from(item).expect("unit index fits u32"),
        };
        Ok(match self.round(r)? {
            Round::Ring(ring) => Box::new(PlanSet::ALL.into_iter().flat_map(move |set| {
                let s = self.problems.search(set);
                let members = if ring <= s.rings() {
                    s.ring_members(ring)
                } else {
                    Vec::new()
                };
                members.into_iter().map(move |f| unit(set, f))
            })),
            Round::Finish => Box::new(PlanSet::ALL.into_iter().flat_map(move |set| {
                (0..self.problems.search(set).half()).map(move |f| unit(set, f))
            })),
            Round::Index => Box::new(
                PlanSet::INDEXED
                    .into_iter()
                    .flat_map(move |set| (0..index_cells).map(move |c| unit(set, c))),
            ),
        })
    }

    /// Number of units of round `r` (None for the index round: its cells
    /// are known only once the plans are finished).
    pub fn unit_count(&self, r: usize) -> Result<Option<usize>, ShardError> {
        Ok(match self.round(r)? {
            Round::Index => None,
            Round::Finish => Some(
                PlanSet::ALL
                    .iter()
                    .map(|&s| self.problems.search(s).half())
                    .sum(),
            ),
            Round::Ring(_) => Some(self.units(r, 0)?.count()),
        })
    }

    /// A one-line description of round `r` for logs and `--rounds`.
    pub fn describe(&self, r: usize) -> Result<String, ShardError> {
        let units = self.unit_count(r)?.unwrap_or(0);
        Ok(match self.round(r)? {
            Round::Ring(ring) => format!("round {r}: ring {ring} of the plan grids, {units} plans"),
            Round::Finish => format!(
                "round {r}: improvement sweep and finishing at rest, {units} points (each also \
                 finishes its mirror image)"
            ),
            Round::Index => format!(
                "round {r}: warm-start index, two entries per kept cell (the cells near the \
                 finished plans' samples)"
            ),
        })
    }

    fn assigned(&self, r: usize, shard: ShardSpec, state: &State) -> Result<Vec<Unit>, ShardError> {
        let cells = state.index_cells.as_ref().map_or(0, Vec::len);
        Ok(self
            .units(r, cells)?
            .skip(shard.index)
            .step_by(shard.count)
            .collect())
    }

    fn empty_state(&self) -> State {
        State {
            min_time: PlanSet::ALL
                .iter()
                .map(|&s| self.problems.search(s).initial())
                .collect(),
            entries: PlanSet::ALL
                .iter()
                .map(|&s| vec![None; self.problems.search(s).total()])
                .collect(),
            index_cells: None,
            index: Vec::new(),
        }
    }

    /// Reads `paths`, checks that they are exactly the complete rounds
    /// `0..upto`, and applies them in round order.
    fn load(&self, paths: &[PathBuf], upto: usize) -> Result<State, ShardError> {
        let config = self.problems.config;
        let rounds = self.rounds.len();
        let mut by_round: Vec<Vec<(&PathBuf, Part)>> = (0..upto).map(|_| Vec::new()).collect();
        for path in paths {
            let part = Part::read(path, config)?;
            let h = &part.header;
            if h.rounds as usize != rounds {
                return Err(part_err(
                    path,
                    format!(
                        "made for a plan of {} rounds; this config and build have {rounds}",
                        h.rounds
                    ),
                ));
            }
            let r = h.round as usize;
            if r >= upto {
                return Err(part_err(
                    path,
                    format!(
                        "is from round {r}, but {}",
                        match upto {
                            0 => "round 0 reads no parts".to_string(),
                            _ if upto == rounds => format!("the rounds are 0..{}", rounds - 1),
                            _ => format!(
                                "round {upto} reads only the parts of rounds 0..{}",
                                upto - 1
                            ),
                        }
                    ),
                ));
            }
            by_round[r].push((path, part));
        }
        let mut state = self.empty_state();
        for (r, parts) in by_round.iter_mut().enumerate() {
            let Some((first_path, first)) = parts.first() else {
                return Err(ShardError::Invalid(format!(
                    "no part of round {r} was given ({}; rounds 0..{} are needed)",
                    self.describe(r)?,
                    upto - 1
                )));
            };
            let n = first.header.shards as usize;
            let mut seen: Vec<Option<&PathBuf>> = vec![None; n.max(1)];
            for (path, part) in parts.iter() {
                let h = &part.header;
                if h.shards as usize != n {
                    return Err(part_err(
                        path,
                        format!(
                            "is shard {}/{} of round {r}, but {} is shard {}/{n} of that round: \
                             one round's parts must come from one shard count",
                            h.shard,
                            h.shards,
                            first_path.display(),
                            first.header.shard
                        ),
                    ));
                }
                let i = h.shard as usize;
                if i >= n {
                    return Err(part_err(path, format!("shard {i}/{n} is out of range")));
                }
                if let Some(other) = seen[i] {
                    return Err(part_err(
                        path,
                        format!(
                            "shard {i}/{n} of round {r} was given twice (also {})",
                            other.display()
                        ),
                    ));
                }
                seen[i] = Some(path);
            }
            let missing: Vec<String> = (0..n)
                .filter(|&i| seen[i].is_none())
                .map(|i| format!("{i}/{n}"))
                .collect();
            if !missing.is_empty() {
                return Err(ShardError::Invalid(format!(
                    "round {r} is incomplete: no part for shard(s) {} was given",
                    missing.join(", ")
                )));
            }
            // Apply in shard order (each unit is written once; the order
            // does not matter, but a fixed one costs nothing).
            parts.sort_by_key(|(_, p)| p.header.shard);
            for (path, part) in parts.iter() {
                let shard = ShardSpec {
                    index: part.header.shard as usize,
                    count: n,
                };
                self.apply(&mut state, r, shard, part)
                    .map_err(|why| part_err(path, why))?;
            }
            if self.rounds[r] == Round::Finish {
                // The index round's cells: those near the finished plans.
                let finished = PlanSet::INDEXED.map(|s| Self::finished(&state, s));
                let cells = self
                    .problems
                    .index_cells(PlanSet::INDEXED.map(|s| &finished[indexed_position(s)][..]));
                state.index = PlanSet::INDEXED
                    .iter()
                    .map(|_| vec![None; cells.len()])
                    .collect();
                state.index_cells = Some(cells);
            }
        }
        Ok(state)
    }

    /// Applies one part's outputs to the state, after checking that they
    /// are the units the round plan assigns to its shard.
    fn apply(
        &self,
        state: &mut State,
        r: usize,
        shard: ShardSpec,
        part: &Part,
    ) -> Result<(), String> {
        let expected = self.assigned(r, shard, state).map_err(|e| e.to_string())?;
        if part.units != expected || part.outputs.len() != expected.len() {
            return Err(format!(
                "holds {} units that are not the {} units of shard {shard} of round {r} for this \
                 config (made by another generator version?)",
                part.units.len(),
                expected.len()
            ));
        }
        let round = self.round(r).map_err(|e| e.to_string())?;
        for (unit, output) in part.units.iter().zip(&part.outputs) {
            let (s, item) = (unit.set.position(), unit.item as usize);
            let search = self.problems.search(unit.set);
            match (round, output) {
                (Round::Ring(_), Output::Ring(plan)) => {
                    search.store(&mut state.min_time[s], item, plan.clone());
                }
                (Round::Finish, Output::Finish(entries)) => {
                    let mirror = search.total() - 1 - item;
                    let want = if mirror == item { 1 } else { 2 };
                    if entries.len() != want {
                        return Err(format!(
                            "point {item} of {:?} has {} finished entries, not {want}",
                            unit.set,
                            entries.len()
                        ));
                    }
                    state.entries[s][item] = Some(entries[0].clone());
                    if mirror != item {
                        state.entries[s][mirror] = Some(entries[1].clone());
                    }
                }
                (Round::Index, Output::Cell(cell)) => {
                    let k = indexed_position(unit.set);
                    state.index[k][item] = Some(*cell);
                }
                _ => return Err(format!("holds an output of another kind than round {r}'s")),
            }
        }
        Ok(())
    }

    fn finished(state: &State, set: PlanSet) -> Vec<PlanEntry> {
        state.entries[set.position()]
            .iter()
            .map(|e| e.clone().expect("every point is finished"))
            .collect()
    }

    /// Computes shard `shard` of round `r` from the parts of every earlier
    /// round (`inputs`).
    pub fn compute(
        &self,
        r: usize,
        shard: ShardSpec,
        inputs: &[PathBuf],
        progress: &dyn Progress,
    ) -> Result<ShardRun, ShardError> {
        let round = self.round(r)?;
        let state = self.load(inputs, r)?;
        let units = self.assigned(r, shard, &state)?;
        progress.start(
            &format!("round {r}/{}, shard {shard}", self.rounds.len()),
            units.len(),
        );
        let p = &self.problems;
        let finished: Vec<Vec<PlanEntry>> = match round {
            Round::Index => PlanSet::INDEXED
                .iter()
                .map(|&s| Self::finished(&state, s))
                .collect(),
            _ => Vec::new(),
        };
        let choosers: Vec<CellChooser> = PlanSet::INDEXED
            .iter()
            .zip(&finished)
            .map(|(&s, plans)| CellChooser::new(p.ocp(s), plans, p.index_grid()))
            .collect();
        let cells = state.index_cells.as_deref().unwrap_or(&[]);
        let timed: Vec<(Output, f64)> = units
            .par_iter()
            .map(|unit| {
                let started = std::time::Instant::now();
                let (set, item) = (unit.set, unit.item as usize);
                let search = p.search(set);
                let plans = &state.min_time[set.position()];
                let out = match round {
                    Round::Ring(ring) => Output::Ring(search.ring_point(plans, item, ring)),
                    Round::Finish => {
                        // The point's plan after the improvement sweep, and
                        // its mirror image, exactly as the sweep stores them.
                        let plan = search
                            .improve_point(plans, item)
                            .or_else(|| plans[item].clone());
                        let mirror = search.total() - 1 - item;
                        let mut entries = vec![p.plan_entry(set, item, plan.as_ref())];
                        if mirror != item {
                            let image = plan.as_ref().map(MinTimePlan::mirrored);
                            entries.push(p.plan_entry(set, mirror, image.as_ref()));
                        }
                        Output::Finish(entries)
                    }
                    Round::Index => Output::Cell(choosers[indexed_position(set)].cell(cells[item])),
                };
                progress.tick();
                (out, started.elapsed().as_secs_f64())
            })
            .collect();
        let (outputs, unit_seconds): (Vec<Output>, Vec<f64>) = timed.into_iter().unzip();
        let config = p.config;
        let part = Part {
            header: PartHeader {
                magic: PART_MAGIC,
                part_format_version: PART_FORMAT_VERSION,
                table_format_version: TABLE_FORMAT_VERSION,
                config_hash: config_hash(config),
                generator_version: env!("CARGO_PKG_VERSION").to_string(),
                round: r as u32,
                rounds: self.rounds.len() as u32,
                shard: shard.index as u32,
                shards: shard.count as u32,
            },
            units,
            outputs,
        };
        Ok(ShardRun { part, unit_seconds })
    }

    /// The tables from the parts of every round: byte-identical to
    /// [`build_tables`](crate::tables::build_tables) of the same config.
    pub fn merge(&self, parts: &[PathBuf]) -> Result<Tables, ShardError> {
        let state = self.load(parts, self.rounds.len())?;
        let plan_sets = PlanSet::ALL.map(|s| Self::finished(&state, s));
        let indexes = PlanSet::INDEXED.map(|s| {
            state.index[indexed_position(s)]
                .iter()
                .map(|c| c.expect("every cell is computed"))
                .collect()
        });
        let cells = state.index_cells.expect("the finish round was applied");
        Ok(self.problems.assemble(plan_sets, cells, indexes))
    }
}

fn indexed_position(set: PlanSet) -> usize {
    PlanSet::INDEXED
        .iter()
        .position(|&s| s == set)
        .expect("an indexed set")
}

/// Number of rounds of sharded generation for `config`.
pub fn round_count(config: &Config) -> usize {
    let model = Model::from_config(config);
    Sharding::new(config, &model).rounds().len()
}

/// A computed shard: the part to write, and the wall time of each of its
/// units (for scaling reports; not stored, so parts stay deterministic).
pub struct ShardRun {
    pub part: Part,
    pub unit_seconds: Vec<f64>,
}

/// Computes shard `shard` of round `round` (see [`Sharding::compute`]).
pub fn compute_shard(
    config: &Config,
    round: usize,
    shard: ShardSpec,
    inputs: &[PathBuf],
    progress: &dyn Progress,
) -> Result<ShardRun, ShardError> {
    let model = Model::from_config(config);
    Sharding::new(config, &model).compute(round, shard, inputs, progress)
}

/// Assembles the tables from every round's parts (see [`Sharding::merge`]).
pub fn merge_parts(config: &Config, parts: &[PathBuf]) -> Result<Tables, ShardError> {
    let model = Model::from_config(config);
    Sharding::new(config, &model).merge(parts)
}
