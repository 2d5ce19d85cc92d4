//! Writes two hand-made runs as `.seq` files, each with a JSON `u(t)` in the
//! shape of `capsule-mpc simulate --json` (`t`, `u`, `phase`, `measurements`,
//! `sampling`), for `tests/pulseq/check_seq.py`:
//!
//! * `synthetic-ideal`: 60 actuation samples back to back (every amplitude
//!   step ramps across a sample boundary), no tracking;
//! * `synthetic-constant`: 12 periods of tracking (20 ms), a 4 ms pause, then
//!   3 actuation samples of 20 ms.
//!
//! Usage: `cargo run -p capsule-mpc-pulseq --example synthetic_run -- OUT_DIR`

use capsule_mpc_pulseq::{
    write_sequence_file, ActuationSample, PlayedRun, ScannerLimits, SequenceOptions, TrackingPhase,
    TrackingPlaceholder,
};
use serde_json::json;
use std::path::Path;

const U_MAX_T_PER_M: f64 = 0.04;
const SAMPLE_S: f64 = 0.02;

/// A deterministic waveform touching +-u_max, zero and repeated values.
fn gradient(k: usize) -> f64 {
    match k % 9 {
        0 => U_MAX_T_PER_M,
        1 => -U_MAX_T_PER_M,
        2 | 3 => 0.0123,
        4 => 0.0,
        _ => U_MAX_T_PER_M * (0.7 * k as f64).sin(),
    }
}

/// One segment of the run: (start s, length s, u T/m, "actuate" | "track").
type Segment = (f64, f64, f64, &'static str);

fn write(dir: &Path, name: &str, sampling: &str, segments: &[Segment]) -> Result<(), String> {
    let mut run = PlayedRun {
        sample_time_s: SAMPLE_S,
        metadata: vec![
            ("CapsuleMpcScenario".into(), "synthetic".into()),
            ("CapsuleMpcSampling".into(), sampling.into()),
        ],
        ..PlayedRun::default()
    };
    let (mut t, mut u, mut phase, mut measurements) = (vec![], vec![], vec![], vec![]);
    for &(start_s, length_s, g, kind) in segments {
        t.push(start_s);
        u.push(g);
        phase.push(kind);
        match kind {
            "actuate" => {
                run.samples.push(ActuationSample {
                    start_s,
                    gradient_t_per_m: g,
                });
                if sampling == "ideal" {
                    measurements.push(json!({ "t_s": start_s }));
                }
            }
            "track" if length_s > 0.01 => {
                run.tracking.push(TrackingPhase {
                    start_s,
                    duration_s: length_s,
                });
                measurements.push(json!({ "t_s": start_s }));
            }
            _ => {}
        }
        run.duration_s = start_s + length_s;
    }
    t.push(run.duration_s);
    u.push(*u.last().unwrap_or(&0.0));
    phase.push(*phase.last().unwrap_or(&"actuate"));

    let limits = ScannerLimits::new(U_MAX_T_PER_M, 200.0, 10e-6);
    let opts = SequenceOptions {
        limits,
        tracking: TrackingPlaceholder::default(),
    };
    let seq_path = dir.join(format!("{name}.seq"));
    let seq = write_sequence_file(&seq_path, &run, &opts).map_err(|e| e.to_string())?;
    let report = json!({
        "t": t, "u": u, "phase": phase, "measurements": measurements,
        "sampling": sampling, "scenario": "synthetic",
    });
    let json_path = dir.join(format!("{name}.json"));
    std::fs::write(&json_path, report.to_string())
        .map_err(|e| format!("{}: {e}", json_path.display()))?;
    println!(
        "wrote {} ({} blocks: {} actuation, {} tracking, {} pause; {:.3} s; longest ramp {:.0} us) and {}",
        seq_path.display(),
        seq.blocks,
        seq.actuation_blocks,
        seq.tracking_blocks,
        seq.delay_blocks,
        seq.duration_s,
        seq.longest_ramp_s * 1e6,
        json_path.display()
    );
    Ok(())
}

fn main() {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: synthetic_run OUT_DIR");
        std::process::exit(2);
    };
    let dir = Path::new(&dir);
    if let Err(e) = std::fs::create_dir_all(dir) {
        eprintln!("cannot create {}: {e}", dir.display());
        std::process::exit(1);
    }

    let ideal: Vec<Segment> = (0..60)
        .map(|k| (k as f64 * SAMPLE_S, SAMPLE_S, gradient(k), "actuate"))
        .collect();

    let mut constant: Vec<Segment> = Vec::new();
    let mut now = 0.0;
    let mut k = 0;
    for _ in 0..12 {
        constant.push((now, 0.02, 0.0, "track"));
        constant.push((now + 0.02, 0.004, 0.0, "track"));
        now += 0.024;
        for _ in 0..3 {
            constant.push((now, SAMPLE_S, gradient(k), "actuate"));
            now += SAMPLE_S;
            k += 1;
        }
    }

    for (name, sampling, segments) in [
        ("synthetic-ideal", "ideal", &ideal),
        ("synthetic-constant", "constant", &constant),
    ] {
        if let Err(e) = write(dir, name, sampling, segments) {
            eprintln!("{name}: {e}");
            std::process::exit(1);
        }
    }
}
