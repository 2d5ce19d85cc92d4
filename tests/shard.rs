//! Sharded generation (`generate --shard I/N --round R`, `--merge`): the
//! merged tables are byte-identical to the single-process run for M = 2 and
//! M = 3 and N = 1, 3, 4; bad shard specs and bad sets of parts are refused
//! with errors that name the value or the file.

use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::shard::{compute_shard, merge_parts, round_count, ShardSpec};
use capsule_mpc_generator::table_file::encode;
use capsule_mpc_generator::tables::{build_tables, Silent};
use std::path::{Path, PathBuf};
use std::process::Command;

fn config(name: &str) -> Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/configs")
        .join(name);
    Config::from_toml_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn shard(i: usize, n: usize) -> ShardSpec {
    ShardSpec { index: i, count: n }
}

/// Runs round `r` for shards 0..n, writing `dir/r{r}-s{i}-of-{n}.part`;
/// returns their paths.
fn run_round(config: &Config, r: usize, n: usize, inputs: &[PathBuf], dir: &Path) -> Vec<PathBuf> {
    (0..n)
        .map(|i| {
            let path = dir.join(format!("r{r}-s{i}-of-{n}.part"));
            compute_shard(config, r, shard(i, n), inputs, &Silent)
                .unwrap()
                .part
                .write(&path)
                .unwrap();
            path
        })
        .collect()
}

/// All rounds with `n(r)` shards each, then the merge.
fn sharded_bytes(config: &Config, n: impl Fn(usize) -> usize) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let mut parts = Vec::new();
    for r in 0..round_count(config) {
        let new = run_round(config, r, n(r), &parts, dir.path());
        parts.extend(new);
    }
    encode(config, Some(&merge_parts(config, &parts).unwrap()), None)
}

fn assert_merge_matches(config: &Config) {
    let single = encode(config, Some(&build_tables(config, &Silent)), None);
    for n in [1, 3, 4] {
        let merged = sharded_bytes(config, |_| n);
        assert!(merged == single, "{n} shards: merged tables differ");
    }
}

#[test]
fn merged_tables_match_the_single_process_run_for_two_capsules() {
    let config = config("shard-m2.toml");
    assert_merge_matches(&config);
    // Each round may use its own shard count.
    let single = encode(&config, Some(&build_tables(&config, &Silent)), None);
    assert!(
        sharded_bytes(&config, |r| 1 + r % 4) == single,
        "mixed shard counts"
    );
}

#[test]
fn merged_tables_match_the_single_process_run_for_three_capsules() {
    let config = config("shard-m3.toml");
    assert_eq!(config.capsule_count(), 3);
    assert_merge_matches(&config);
}

/// Round 0 of the M = 2 config in `n` shards.
fn round_zero(config: &Config, n: usize, dir: &Path) -> Vec<PathBuf> {
    run_round(config, 0, n, &[], dir)
}

fn err(config: &Config, round: usize, inputs: &[PathBuf]) -> String {
    compute_shard(config, round, shard(0, 1), inputs, &Silent)
        .err()
        .expect("refused")
        .to_string()
}

#[test]
fn bad_shard_specs_are_refused_naming_the_value() {
    for (spec, says) in [
        ("4/4", "shard index 4 must be below the shard count 4"),
        ("7/3", "shard index 7 must be below the shard count 3"),
        ("0/0", "at least 1"),
        ("1-4", "expected I/N"),
        ("a/4", "shard index \"a\""),
        ("1/x", "shard count \"x\""),
        ("-1/4", "shard index \"-1\""),
    ] {
        let e = spec.parse::<ShardSpec>().unwrap_err().to_string();
        assert!(e.contains(spec) && e.contains(says), "{spec}: {e}");
    }
    assert_eq!("2/4".parse::<ShardSpec>().unwrap(), shard(2, 4));
    let config = config("shard-m2.toml");
    let rounds = round_count(&config);
    let e = err(&config, rounds, &[]);
    assert!(e.contains(&format!("--round {rounds}")), "{e}");
}

#[test]
fn incomplete_duplicate_and_mismatched_parts_are_refused() {
    let config = config("shard-m2.toml");
    let dir = tempfile::tempdir().unwrap();
    let halves = round_zero(&config, 2, dir.path());
    let thirds = round_zero(&config, 3, dir.path());

    // Missing: shard 1/2 of round 0.
    let e = err(&config, 1, &halves[..1]);
    assert!(
        e.contains("round 0 is incomplete") && e.contains("1/2"),
        "{e}"
    );
    // No part of a needed round at all.
    let e = err(&config, 1, &[]);
    assert!(e.contains("no part of round 0"), "{e}");
    // Duplicate.
    let e = err(
        &config,
        1,
        &[halves[0].clone(), halves[0].clone(), halves[1].clone()],
    );
    assert!(e.contains("given twice") && e.contains("0/2"), "{e}");
    // Parts of one round from two shard counts.
    let e = err(&config, 1, &[halves[0].clone(), thirds[1].clone()]);
    assert!(e.contains("one shard count"), "{e}");
    // A part of the round being computed (or later).
    let e = err(&config, 0, &halves);
    assert!(
        e.contains("is from round 0") && e.contains("round 0 reads no parts"),
        "{e}"
    );
    let round_one = run_round(&config, 1, 1, &halves, dir.path());
    let e = err(&config, 1, &[halves.clone(), round_one].concat());
    assert!(
        e.contains("is from round 1") && e.contains("round 1 reads only the parts of rounds 0..0"),
        "{e}"
    );
    // A merge without the later rounds.
    let e = merge_parts(&config, &halves).unwrap_err().to_string();
    assert!(e.contains("no part of round 1"), "{e}");
    // Complete round 0 in either shard count loads (round 1 then computes).
    assert!(compute_shard(&config, 1, shard(5, 6), &thirds, &Silent).is_ok());
}

#[test]
fn parts_of_another_config_version_or_corrupted_are_refused() {
    let config = config("shard-m2.toml");
    let dir = tempfile::tempdir().unwrap();
    let parts = round_zero(&config, 1, dir.path());
    let bytes = std::fs::read(&parts[0]).unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        p
    };

    // Another config: the part names the hashes.
    let mut other = config.clone();
    other.capsule[0].sphere_radius_m *= 1.1;
    let e = err(&other, 1, &parts);
    assert!(
        e.contains("another config") && e.contains(&parts[0].display().to_string()),
        "{e}"
    );

    // Another part format version (the byte after the 8-byte magic).
    let mut v = bytes.clone();
    v[8] = 99;
    let p = write("version.part", &v);
    let e = err(&config, 1, &[p]);
    assert!(
        e.contains("part format version 99") && e.contains("version.part"),
        "{e}"
    );

    // Not a part file.
    let p = write("tables.part", b"CAPSMPC\0 something else entirely");
    let e = err(&config, 1, &[p]);
    assert!(e.contains("not a capsule-mpc part file"), "{e}");

    // A flipped bit in the payload, and a truncation.
    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 4;
    let p = write("flipped.part", &flipped);
    let e = err(&config, 1, &[p]);
    assert!(e.contains("SHA-256") && e.contains("flipped.part"), "{e}");
    let p = write("short.part", &bytes[..bytes.len() / 3]);
    let e = err(&config, 1, &[p]);
    assert!(
        e.contains("truncated or corrupted") && e.contains("short.part"),
        "{e}"
    );

    // A missing file is named.
    let e = err(&config, 1, &[dir.path().join("absent.part")]);
    assert!(e.contains("absent.part"), "{e}");
}

fn cli(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_capsule-mpc"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr),
    )
}

#[test]
fn the_cli_runs_rounds_and_refuses_bad_arguments() {
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/configs/shard-m2.toml");
    let cfg = cfg.to_str().unwrap();
    let (ok, out) = cli(&["generate", "--config", cfg, "--rounds"]);
    assert!(ok, "{out}");
    let config = config("shard-m2.toml");
    assert!(
        out.starts_with(&format!("{}\n", round_count(&config))),
        "{out}"
    );
    assert!(out.contains("round 0: ring 1"), "{out}");

    let dir = tempfile::tempdir().unwrap();
    let part = dir.path().join("p.part");
    let part = part.to_str().unwrap();
    let (ok, out) = cli(&[
        "generate", "--config", cfg, "--shard", "4/4", "--round", "0", "--out", part,
    ]);
    assert!(
        !ok && out.contains("\"4/4\"") && out.contains("below the shard count 4"),
        "{out}"
    );
    let (ok, out) = cli(&[
        "generate", "--config", cfg, "--shard", "0/4", "--round", "0",
    ]);
    assert!(!ok && out.contains("needs --out PART"), "{out}");
    let (ok, out) = cli(&["generate", "--config", cfg, "--merge"]);
    assert!(!ok && out.contains("--merge needs the part files"), "{out}");
    let (ok, out) = cli(&[
        "generate", "--config", cfg, "--shard", "0/1", "--round", "0", "--out", part,
    ]);
    assert!(ok, "{out}");
    assert!(out.contains("round 0, shard 0/1"), "{out}");
    let (ok, out) = cli(&["generate", "--config", cfg, part]);
    assert!(!ok && out.contains("without --shard or --merge"), "{out}");
    let (ok, out) = cli(&[
        "generate",
        "--config",
        cfg,
        "--merge",
        "--out",
        dir.path().to_str().unwrap(),
        part,
    ]);
    assert!(!ok && out.contains("no part of round 1"), "{out}");
}
