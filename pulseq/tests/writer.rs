//! The writer on hand-made runs, read back by a minimal Pulseq reader written
//! here (the Python round trip through pypulseq is tests/pulseq/run.sh).

use capsule_mpc_pulseq::{
    build_sequence, write_sequence_file, ActuationSample, PlayedRun, PulseqError, ScannerLimits,
    SequenceOptions, TrackingPhase, TrackingPlaceholder, PROTON_GYROMAGNETIC_RATIO_HZ_PER_T,
};
use md5::{Digest, Md5};
use std::collections::HashMap;

const GAMMA: f64 = PROTON_GYROMAGNETIC_RATIO_HZ_PER_T;
const U_MAX: f64 = 0.04;
const SLEW: f64 = 200.0;
const RASTER: f64 = 10e-6;
const DT: f64 = 0.02;

fn options() -> SequenceOptions {
    SequenceOptions {
        limits: ScannerLimits::new(U_MAX, SLEW, RASTER),
        tracking: TrackingPlaceholder::default(),
    }
}

/// Samples back to back from t = 0 (ideal sampling).
fn ideal_run(u: &[f64]) -> PlayedRun {
    PlayedRun {
        sample_time_s: DT,
        samples: u
            .iter()
            .enumerate()
            .map(|(k, &g)| ActuationSample {
                start_s: k as f64 * DT,
                gradient_t_per_m: g,
            })
            .collect(),
        tracking: vec![],
        duration_s: u.len() as f64 * DT,
        metadata: vec![("CapsuleMpcSampling".into(), "ideal".into())],
    }
}

/// Constant sampling: per period, tracking (20 ms), a pause (5 ms), then
/// `per_period` samples. Returns the run and the expected tracking starts.
fn constant_run(u: &[f64], per_period: usize) -> PlayedRun {
    let mut run = PlayedRun {
        sample_time_s: DT,
        ..PlayedRun::default()
    };
    let mut now = 0.0;
    for chunk in u.chunks(per_period) {
        run.tracking.push(TrackingPhase {
            start_s: now,
            duration_s: 0.02,
        });
        now += 0.025;
        for &g in chunk {
            run.samples.push(ActuationSample {
                start_s: now,
                gradient_t_per_m: g,
            });
            now += DT;
        }
    }
    run.duration_s = now;
    run
}

/// What a reader sees in a `.seq` file.
#[derive(Debug)]
struct Parsed {
    version: (u32, u32, u32),
    definitions: HashMap<String, String>,
    /// (id, duration in block rasters, rf, gx, gy, gz, adc, ext)
    blocks: Vec<[u64; 8]>,
    rf: Vec<Vec<f64>>,
    gradients: HashMap<u64, (f64, u64, u64, f64)>,
    adc: Vec<Vec<f64>>,
    shapes: HashMap<u64, Vec<f64>>,
    signature: Option<String>,
    /// The text the signature covers.
    signed: String,
}

fn decompress(num: usize, packed: &[f64]) -> Vec<f64> {
    if packed.len() == num {
        return packed.to_vec();
    }
    let mut diffs = Vec::new();
    let mut i = 0;
    while i < packed.len() {
        if i + 1 < packed.len() && packed[i + 1] == packed[i] {
            for _ in 0..(packed[i + 2] as usize + 2) {
                diffs.push(packed[i]);
            }
            i += 3;
        } else {
            diffs.push(packed[i]);
            i += 1;
        }
    }
    assert_eq!(diffs.len(), num, "shape decompresses to its num_samples");
    let mut sum = 0.0;
    diffs
        .into_iter()
        .map(|d| {
            sum += d;
            sum
        })
        .collect()
}

fn parse(text: &str) -> Parsed {
    let (signed, _) = text.split_once("\n[SIGNATURE]").expect("signed file");
    let mut p = Parsed {
        version: (0, 0, 0),
        definitions: HashMap::new(),
        blocks: vec![],
        rf: vec![],
        gradients: HashMap::new(),
        adc: vec![],
        shapes: HashMap::new(),
        signature: None,
        signed: signed.to_string(),
    };
    let mut section = String::new();
    let mut shape: Option<(u64, usize, Vec<f64>)> = None;
    let finish = |shape: &mut Option<(u64, usize, Vec<f64>)>,
                  shapes: &mut HashMap<u64, Vec<f64>>| {
        if let Some((id, n, data)) = shape.take() {
            assert!(
                shapes.insert(id, decompress(n, &data)).is_none(),
                "shape ids are unique"
            );
        }
    };
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with('#') {
            continue;
        }
        if line.starts_with('[') {
            finish(&mut shape, &mut p.shapes);
            section = line.to_string();
            continue;
        }
        if line.is_empty() {
            finish(&mut shape, &mut p.shapes);
            continue;
        }
        let nums = || -> Vec<f64> {
            line.split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect()
        };
        match section.as_str() {
            "[VERSION]" => {
                let (k, v) = line.split_once(' ').unwrap();
                let v: u32 = v.parse().unwrap();
                match k {
                    "major" => p.version.0 = v,
                    "minor" => p.version.1 = v,
                    "revision" => p.version.2 = v,
                    other => panic!("unknown version key {other}"),
                }
            }
            "[DEFINITIONS]" => {
                let (k, v) = line.split_once(' ').unwrap();
                assert!(p.definitions.insert(k.into(), v.into()).is_none());
            }
            "[BLOCKS]" => {
                let v: Vec<u64> = line
                    .split_whitespace()
                    .map(|t| t.parse().unwrap())
                    .collect();
                p.blocks
                    .push(v.try_into().expect("8 columns in a 1.4 block"));
            }
            "[RF]" => p.rf.push(nums()),
            "[ADC]" => p.adc.push(nums()),
            "[GRADIENTS]" => {
                let v = nums();
                assert_eq!(v.len(), 5);
                p.gradients
                    .insert(v[0] as u64, (v[1], v[2] as u64, v[3] as u64, v[4]));
            }
            "[SHAPES]" => {
                if let Some(id) = line.strip_prefix("shape_id ") {
                    shape = Some((id.parse().unwrap(), 0, vec![]));
                } else if let Some(n) = line.strip_prefix("num_samples ") {
                    shape.as_mut().unwrap().1 = n.parse().unwrap();
                } else {
                    shape.as_mut().unwrap().2.push(line.parse().unwrap());
                }
            }
            "[SIGNATURE]" => {
                if let Some(h) = line.strip_prefix("Hash ") {
                    p.signature = Some(h.to_string());
                }
            }
            other => panic!("unexpected section {other}"),
        }
    }
    finish(&mut shape, &mut p.shapes);
    p
}

impl Parsed {
    fn def(&self, key: &str) -> f64 {
        self.definitions[key].parse().unwrap()
    }

    /// Start time of each block, s, and the total duration.
    fn block_starts(&self) -> (Vec<f64>, f64) {
        let raster = self.def("BlockDurationRaster");
        let mut now = 0u64;
        let mut starts = vec![];
        for b in &self.blocks {
            starts.push(now as f64 * raster);
            now += b[1];
        }
        (starts, now as f64 * raster)
    }

    /// Corner points (t s, gx T/m) of the x gradient; zero where no gradient plays.
    fn gx_points(&self) -> Vec<(f64, f64)> {
        let g_raster = self.def("GradientRasterTime");
        let (starts, _) = self.block_starts();
        let mut points = vec![];
        for (b, start) in self.blocks.iter().zip(starts) {
            if b[3] == 0 {
                continue;
            }
            let (amp, shape_id, time_id, delay_us) = self.gradients[&b[3]];
            assert_eq!(delay_us, 0.0);
            assert_ne!(time_id, 0, "actuation gradients are time-shaped");
            let shape = &self.shapes[&shape_id];
            let times = &self.shapes[&time_id];
            assert_eq!(shape.len(), times.len());
            assert_eq!(
                times[0], 0.0,
                "an extended trapezoid starts at its block's start"
            );
            assert_eq!(
                times.last().unwrap() * g_raster,
                b[1] as f64 * self.def("BlockDurationRaster"),
                "the gradient fills its block"
            );
            for (t, v) in times.iter().zip(shape) {
                assert!(v.abs() <= 1.0 + 1e-12, "shapes are normalised");
                assert_eq!(t.fract(), 0.0, "corners on the gradient raster");
                points.push((start + t * g_raster, amp * v / GAMMA));
            }
        }
        points
    }

    fn gx_at(&self, t: f64) -> f64 {
        let pts = self.gx_points();
        for w in pts.windows(2) {
            let ((t0, g0), (t1, g1)) = (w[0], w[1]);
            if t0 <= t && t <= t1 && t1 > t0 {
                return g0 + (g1 - g0) * (t - t0) / (t1 - t0);
            }
        }
        0.0
    }
}

/// Every check a reader can make without knowing the run: version, rasters,
/// signature, continuity of the x gradient, limits.
fn check_generic(p: &Parsed, limits: &ScannerLimits) {
    assert_eq!(p.version, (1, 4, 1));
    assert_eq!(p.def("GradientRasterTime"), limits.gradient_raster_s);
    assert_eq!(p.def("BlockDurationRaster"), limits.block_duration_raster_s);
    assert_eq!(p.def("RadiofrequencyRasterTime"), limits.rf_raster_s);
    assert_eq!(p.def("AdcRasterTime"), limits.adc_raster_s);
    let md5: String = Md5::digest(p.signed.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(p.signature.as_deref(), Some(md5.as_str()));
    let (_, total) = p.block_starts();
    assert!((p.def("TotalDuration") - total).abs() < 1e-12);

    // Continuity: a gradient ending non-zero is followed at once by one
    // starting at the same value; slopes within the limit.
    let pts = p.gx_points();
    if let (Some(first), Some(last)) = (pts.first(), pts.last()) {
        assert_eq!(first.1, 0.0, "the sequence starts at zero gradient");
        assert_eq!(last.1, 0.0, "the sequence ends at zero gradient");
    }
    for w in pts.windows(2) {
        let ((t0, g0), (t1, g1)) = (w[0], w[1]);
        assert!(g0.abs() <= limits.max_gradient_t_per_m * (1.0 + 1e-12));
        if t1 - t0 < 1e-12 {
            assert!(
                (g1 - g0).abs() < 1e-12 * U_MAX,
                "no jump at t = {t0}: {g0} -> {g1}"
            );
        } else {
            let slope = (g1 - g0).abs() / (t1 - t0);
            assert!(
                slope <= limits.slew_rate_t_per_m_per_s * (1.0 + 1e-9),
                "slope {slope} T/m/s at t = {t0}"
            );
        }
    }
}

/// The x gradient equals each sample's u over the sample except within
/// `margin_s` of its ends.
fn check_samples(p: &Parsed, run: &PlayedRun, margin_s: f64) {
    for (k, s) in run.samples.iter().enumerate() {
        for f in [0.0, 0.25, 0.5, 0.75, 1.0] {
            let t = s.start_s + margin_s + f * (run.sample_time_s - 2.0 * margin_s);
            let g = p.gx_at(t);
            assert!(
                (g - s.gradient_t_per_m).abs() <= 1e-12,
                "sample {k} at t = {t}: gx {g} T/m, u {} T/m",
                s.gradient_t_per_m
            );
        }
    }
}

#[test]
fn ideal_sampling_back_to_back_samples() {
    let u = [0.04, -0.04, 0.0123, 0.0123, 0.0, -0.02, 0.039, 0.0];
    let run = ideal_run(&u);
    let opts = options();
    let seq = build_sequence(&run, &opts).unwrap();
    assert_eq!(seq.blocks, u.len());
    assert_eq!(seq.actuation_blocks, u.len());
    assert_eq!((seq.tracking_blocks, seq.delay_blocks), (0, 0));
    assert!((seq.duration_s - 0.16).abs() < 1e-12);
    // 40 -> -40 mT/m at 200 T/m/s: 0.4 ms, centred on the boundary.
    assert!((seq.longest_ramp_s - 0.4e-3).abs() < 1e-12);

    let p = parse(&seq.text);
    check_generic(&p, &opts.limits);
    check_samples(&p, &run, 0.2e-3);
    assert!(p.rf.is_empty() && p.adc.is_empty());
    assert!(p
        .blocks
        .iter()
        .all(|b| b[1] == 2000 && b[2] == 0 && b[6] == 0));
    // The ramp is centred: at the boundary between samples 0 and 1 the
    // gradient is the mean of the two, and the step's area is preserved.
    assert!(p.gx_at(0.02).abs() < 1e-15);
    assert!((p.gx_at(0.02 - 0.1e-3) - 0.02).abs() < 1e-12);
    // Equal neighbours (samples 2 and 3) need no ramp.
    assert!((p.gx_at(0.06) - 0.0123).abs() < 1e-15);
    // The first sample ramps up from zero inside itself, the last sample is 0.
    assert!((p.gx_at(0.1e-3) - 0.02).abs() < 1e-12);
    assert_eq!(p.definitions["CapsuleMpcSampling"], "ideal");
}

#[test]
fn constant_sampling_with_tracking_and_pauses() {
    let u = [0.04, 0.04, -0.01, -0.04, 0.0, 0.02, 0.03];
    let run = constant_run(&u, 3);
    let opts = options();
    let seq = build_sequence(&run, &opts).unwrap();
    // 3 periods: tracking + pause + up to 3 samples.
    assert_eq!(seq.tracking_blocks, 3);
    assert_eq!(seq.delay_blocks, 3);
    assert_eq!(seq.actuation_blocks, u.len());
    assert_eq!(seq.blocks, 3 + 3 + u.len());
    assert!((seq.duration_s - run.duration_s).abs() < 1e-12);

    let p = parse(&seq.text);
    check_generic(&p, &opts.limits);
    check_samples(&p, &run, 0.2e-3);
    let (starts, _) = p.block_starts();
    let tracking: Vec<(f64, &[u64; 8])> = starts
        .iter()
        .zip(&p.blocks)
        .filter(|(_, b)| b[6] != 0)
        .map(|(s, b)| (*s, b))
        .collect();
    assert_eq!(tracking.len(), 3);
    for ((start, b), phase) in tracking.iter().zip(&run.tracking) {
        assert!((start - phase.start_s).abs() < 1e-12);
        assert_eq!(b[1], 2000, "the block lasts the tracking phase");
        assert_eq!((b[2], b[3]), (1, 0), "RF, no gradient");
    }
    // Placeholder: 1 ms hard pulse of 5 degrees after 100 us, ADC of 256
    // samples at 40 us from 1.2 ms.
    assert_eq!(p.rf.len(), 1);
    let rf = &p.rf[0];
    assert_eq!(rf.len(), 8);
    assert!(
        (rf[1] * 1e-3 * 360.0 - 5.0).abs() < 1e-9,
        "flip angle 5 deg"
    );
    assert_eq!(p.shapes[&(rf[2] as u64)], vec![1.0; 1000]);
    assert_eq!(p.shapes[&(rf[3] as u64)], vec![0.0; 1000]);
    assert_eq!((rf[4], rf[5]), (0.0, 100.0));
    assert_eq!(p.adc, vec![vec![1.0, 256.0, 40000.0, 1200.0, 0.0, 0.0]]);
    // The gradient is zero across every tracking block and pause.
    for phase in &run.tracking {
        for f in [0.0, 0.3, 0.7, 1.0] {
            assert!(p.gx_at(phase.start_s + f * 0.025).abs() < 1e-12);
        }
    }
    // Ramps at the edges of an actuation phase lie inside the samples: the
    // first sample (40 mT/m) ramps up over 0.2 ms from its start.
    let first = run.samples[0].start_s;
    assert!((p.gx_at(first + 0.1e-3) - 0.02).abs() < 1e-12);
    assert!((p.gx_at(first + 0.2e-3) - 0.04).abs() < 1e-12);
}

#[test]
fn identical_samples_share_their_events() {
    let run = ideal_run(&[0.0, 0.01, 0.01, 0.01, 0.01, 0.0]);
    let seq = build_sequence(&run, &options()).unwrap();
    let p = parse(&seq.text);
    // Samples 2 and 3 are identical flat blocks; 1 and 4 differ (ramp in/out).
    assert_eq!(p.blocks[2][3], p.blocks[3][3]);
    assert_ne!(p.blocks[1][3], p.blocks[2][3]);
    assert_eq!(p.gradients.len(), 5);
}

#[test]
fn a_zero_run_has_no_gradient_events() {
    let run = ideal_run(&[0.0; 4]);
    let seq = build_sequence(&run, &options()).unwrap();
    let p = parse(&seq.text);
    check_generic(&p, &options().limits);
    assert!(p.gradients.is_empty() && p.shapes.is_empty());
    assert!(p.blocks.iter().all(|b| b[3] == 0));
}

#[test]
fn gradient_over_the_amplitude_limit_is_refused_naming_the_sample() {
    let mut run = ideal_run(&[0.01, 0.02, 0.03, 0.041, 0.01]);
    let err = build_sequence(&run, &options()).unwrap_err();
    assert!(
        matches!(err, PulseqError::Amplitude { index: 3, .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("actuation sample 3") && msg.contains("0.041") && msg.contains("0.04 T/m"),
        "{msg}"
    );

    run.samples[3].gradient_t_per_m = -0.05;
    assert!(matches!(
        build_sequence(&run, &options()),
        Err(PulseqError::Amplitude { index: 3, .. })
    ));
    // At the limit exactly is fine.
    run.samples[3].gradient_t_per_m = -0.04;
    assert!(build_sequence(&run, &options()).is_ok());
}

#[test]
fn step_too_large_for_the_slew_limit_is_refused_naming_the_sample() {
    // 1 T/m/s: a 40 mT/m ramp takes 40 ms, longer than a 20 ms sample.
    let mut opts = options();
    opts.limits.slew_rate_t_per_m_per_s = 1.0;
    // Sample 1 (10 mT/m) ramps in from 0 over 5 ms and out towards -30 mT/m over 20 ms.
    let run = ideal_run(&[0.0, 0.01, -0.03, 0.0]);
    let err = build_sequence(&run, &opts).unwrap_err();
    let PulseqError::SlewRate {
        index,
        needed_s,
        sample_s,
        ..
    } = err
    else {
        panic!("{err:?}")
    };
    assert_eq!(
        index, 1,
        "sample 1 cannot ramp out towards sample 2 in time"
    );
    assert!(needed_s > sample_s);
    let msg = err.to_string();
    assert!(
        msg.contains("actuation sample 1") && msg.contains("slew-rate limit of 1 T/m/s"),
        "{msg}"
    );

    // A short hand-made sample (100 us) cannot hold a full-scale reversal at 200 T/m/s.
    let mut run = ideal_run(&[0.04, -0.04]);
    run.sample_time_s = 100e-6;
    run.samples[1].start_s = 100e-6;
    run.duration_s = 200e-6;
    let err = build_sequence(&run, &options()).unwrap_err();
    assert!(
        matches!(err, PulseqError::SlewRate { index: 0, .. }),
        "{err:?}"
    );
}

#[test]
fn non_finite_gradient_is_refused_naming_the_sample() {
    for bad in [f64::NAN, f64::INFINITY] {
        let run = ideal_run(&[0.0, bad, 0.0]);
        let err = build_sequence(&run, &options()).unwrap_err();
        assert!(
            matches!(err, PulseqError::NotFinite { index: 1, .. }),
            "{err:?}"
        );
        assert!(err.to_string().contains("actuation sample 1"));
    }
}

#[test]
fn times_off_the_raster_are_refused_naming_the_item() {
    let mut run = ideal_run(&[0.01, 0.02]);
    run.samples[1].start_s += 3e-6;
    let err = build_sequence(&run, &options()).unwrap_err();
    assert!(
        matches!(&err, PulseqError::OffRaster { what, .. } if what == "actuation sample 1 start"),
        "{err:?}"
    );

    let mut run = constant_run(&[0.01], 1);
    run.tracking[0].duration_s = 0.0200042;
    let err = build_sequence(&run, &options()).unwrap_err();
    assert!(
        matches!(&err, PulseqError::OffRaster { what, .. } if what == "tracking phase 0 duration"),
        "{err:?}"
    );

    let mut run = ideal_run(&[0.01]);
    run.sample_time_s = 0.020_005;
    assert!(matches!(
        build_sequence(&run, &options()),
        Err(PulseqError::OffRaster { .. })
    ));
    let mut run = ideal_run(&[0.01]);
    run.samples[0].start_s = -0.02;
    assert!(matches!(
        build_sequence(&run, &options()),
        Err(PulseqError::OffRaster { .. })
    ));
}

#[test]
fn overlaps_and_short_runs_are_refused() {
    let mut run = constant_run(&[0.01, 0.02], 2);
    run.samples[0].start_s = 0.01; // inside the tracking phase
    let err = build_sequence(&run, &options()).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, PulseqError::Overlap { .. })
            && msg.contains("actuation sample 0")
            && msg.contains("tracking phase 0"),
        "{msg}"
    );

    let mut run = ideal_run(&[0.01, 0.02]);
    run.duration_s = 0.03;
    assert!(matches!(
        build_sequence(&run, &options()),
        Err(PulseqError::EndsEarly { .. })
    ));

    let run = PlayedRun {
        sample_time_s: DT,
        ..PlayedRun::default()
    };
    assert_eq!(build_sequence(&run, &options()), Err(PulseqError::Empty));
}

#[test]
fn tracking_phase_too_short_for_the_placeholder_is_refused() {
    let mut run = constant_run(&[0.01], 1);
    run.tracking[0].duration_s = 0.005;
    let err = build_sequence(&run, &options()).unwrap_err();
    assert!(
        matches!(err, PulseqError::TrackingTooShort { index: 0, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("tracking phase 0"));
}

#[test]
fn invalid_settings_are_named() {
    let run = ideal_run(&[0.01]);
    type Edit = Box<dyn Fn(&mut SequenceOptions)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "max_gradient_t_per_m",
            Box::new(|o| o.limits.max_gradient_t_per_m = 0.0),
        ),
        (
            "slew_rate_t_per_m_per_s",
            Box::new(|o| o.limits.slew_rate_t_per_m_per_s = f64::NAN),
        ),
        (
            "gradient_raster_s",
            Box::new(|o| o.limits.gradient_raster_s = -1e-5),
        ),
        (
            "tracking.rf_duration_s",
            Box::new(|o| o.tracking.rf_duration_s = 0.0),
        ),
        (
            "tracking.adc_samples",
            Box::new(|o| o.tracking.adc_samples = 0),
        ),
        (
            "tracking.adc_duration_s",
            Box::new(|o| o.tracking.adc_duration_s = f64::INFINITY),
        ),
    ];
    for (name, edit) in cases {
        let mut opts = options();
        edit(&mut opts);
        let err = build_sequence(&run, &opts).unwrap_err();
        assert!(
            matches!(&err, PulseqError::InvalidSetting { name: n, .. } if *n == name),
            "{name}: {err:?}"
        );
        assert!(err.to_string().contains(name));
    }
    // Absurd values are errors, not huge allocations or overflows.
    let mut opts = options();
    opts.limits.rf_raster_s = 1e-8;
    opts.tracking.rf_duration_s = 0.5;
    let err = build_sequence(&constant_run(&[0.01], 1), &opts).unwrap_err();
    assert!(err.to_string().contains("tracking.rf_duration_s"), "{err}");
    let mut opts = options();
    opts.limits.slew_rate_t_per_m_per_s = 1e-300;
    let err = build_sequence(&run, &opts).unwrap_err();
    assert!(
        matches!(err, PulseqError::SlewRate { index: 0, .. }),
        "{err:?}"
    );
    let mut opts = options();
    opts.tracking.rf_delay_s = -1e-6;
    let err = build_sequence(&run, &opts).unwrap_err();
    assert!(err.to_string().contains("tracking.rf_delay_s"), "{err}");

    // An RF pulse off the RF raster.
    let mut opts = options();
    opts.tracking.rf_duration_s = 1.0005e-3 + 0.2e-6;
    let err = build_sequence(&run, &opts).unwrap_err();
    assert!(err.to_string().contains("tracking.rf_duration_s"), "{err}");
}

#[test]
fn metadata_keys_and_values_are_checked() {
    let bad = [
        ("", "x"),
        ("has space", "x"),
        ("TotalDuration", "1"),
        ("Ok", "two\nlines"),
        ("Ok", " "),
    ];
    for (key, value) in bad {
        let mut run = ideal_run(&[0.01]);
        run.metadata = vec![(key.into(), value.into())];
        let err = build_sequence(&run, &options()).unwrap_err();
        assert!(
            matches!(&err, PulseqError::Metadata { key: k, .. } if k == key),
            "{key:?}: {err:?}"
        );
    }
    let mut run = ideal_run(&[0.01]);
    run.metadata = vec![("A".into(), "1".into()), ("A".into(), "2".into())];
    assert!(matches!(
        build_sequence(&run, &options()),
        Err(PulseqError::Metadata { .. })
    ));
    run.metadata = vec![
        ("CapsuleMpcConfigSha256".into(), "sha256:00ff".into()),
        ("CapsuleMpcTarget".into(), "0.02 0 -0.01 0".into()),
    ];
    let p = parse(&build_sequence(&run, &options()).unwrap().text);
    assert_eq!(p.definitions["CapsuleMpcConfigSha256"], "sha256:00ff");
    assert_eq!(p.definitions["CapsuleMpcTarget"], "0.02 0 -0.01 0");
}

/// A small deterministic generator (no extra dependency).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn random_runs_reconstruct_within_limits() {
    let mut rng = Lcg(7);
    for case in 0..40 {
        let n = 1 + (rng.next() * 30.0) as usize;
        let u: Vec<f64> = (0..n)
            .map(|_| match (rng.next() * 4.0) as u32 {
                0 => 0.0,
                1 => U_MAX * if rng.next() < 0.5 { 1.0 } else { -1.0 },
                _ => U_MAX * (2.0 * rng.next() - 1.0),
            })
            .collect();
        let run = if case % 2 == 0 {
            ideal_run(&u)
        } else {
            constant_run(&u, 1 + case % 5)
        };
        let mut opts = options();
        opts.limits.slew_rate_t_per_m_per_s = [200.0, 100.0, 37.0][case % 3];
        let seq = build_sequence(&run, &opts).unwrap();
        let p = parse(&seq.text);
        check_generic(&p, &opts.limits);
        let margin = U_MAX / opts.limits.slew_rate_t_per_m_per_s + RASTER;
        check_samples(&p, &run, margin);
        assert_eq!(seq.tracking_blocks, run.tracking.len());
        assert!((seq.duration_s - run.duration_s).abs() < 1e-9);
    }
}

#[test]
fn the_file_is_written_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.seq");
    let run = constant_run(&[0.01, -0.02], 2);
    let seq = write_sequence_file(&path, &run, &options()).unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), seq.text);
    // Only the final file is left, and a second write replaces it.
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(names.len(), 1);
    write_sequence_file(&path, &ideal_run(&[0.0]), &options()).unwrap();
    assert_ne!(std::fs::read_to_string(&path).unwrap(), seq.text);

    // A bad run writes nothing; a missing directory is an I/O error naming the path.
    let bad = dir.path().join("bad.seq");
    assert!(write_sequence_file(&bad, &ideal_run(&[0.5]), &options()).is_err());
    assert!(!bad.exists());
    let missing = dir.path().join("no/such/dir/run.seq");
    let err = write_sequence_file(&missing, &run, &options()).unwrap_err();
    assert!(matches!(err, PulseqError::Io { .. }) && err.to_string().contains("no/such/dir"));
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}
