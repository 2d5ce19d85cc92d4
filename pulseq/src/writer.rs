//! Builds the `.seq` text from a [`PlayedRun`] and writes it atomically.

use crate::run::{
    PlayedRun, PulseqError, SequenceOptions, PROTON_GYROMAGNETIC_RATIO_HZ_PER_T, PULSEQ_VERSION,
};
use crate::shape::stored_samples;
use md5::{Digest, Md5};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// A written sequence: the file text and what it holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// The complete `.seq` file.
    pub text: String,
    /// Number of blocks.
    pub blocks: usize,
    /// Blocks holding one actuation sample each.
    pub actuation_blocks: usize,
    /// Blocks holding one tracking event each.
    pub tracking_blocks: usize,
    /// Blocks holding only a pause.
    pub delay_blocks: usize,
    /// Sum of the block durations, s.
    pub duration_s: f64,
    /// Longest gradient ramp in the file, s.
    pub longest_ramp_s: f64,
}

/// Definitions the writer sets itself; metadata may not use these keys.
const WRITER_KEYS: [&str; 10] = [
    "AdcRasterTime",
    "BlockDurationRaster",
    "GradientRasterTime",
    "RadiofrequencyRasterTime",
    "TotalDuration",
    "CapsuleMpcGammaHzPerT",
    "CapsuleMpcMaxGradientTPerM",
    "CapsuleMpcSlewRateTPerMPerS",
    "CapsuleMpcSampleTimeS",
    "CapsuleMpcTrackingPlaceholder",
];

/// Tolerance, in raster units, for a time to count as on the raster (absorbs
/// the rounding of times accumulated in floating point).
const RASTER_TOLERANCE: f64 = 1e-6;

/// `value_s / raster_s` as a whole number, or an error naming `what`.
fn whole(
    what: impl FnOnce() -> String,
    value_s: f64,
    raster_s: f64,
    raster: &'static str,
) -> Result<u64, PulseqError> {
    let x = value_s / raster_s;
    let n = x.round();
    if value_s.is_finite()
        && (0.0..1e15).contains(&n)
        && (x - n).abs() <= RASTER_TOLERANCE.max(1e-12 * x.abs())
    {
        Ok(n as u64)
    } else {
        Err(PulseqError::OffRaster {
            what: what(),
            value_s,
            raster,
            raster_s,
        })
    }
}

/// The number of gradient raster times in `value_s`, or the writer's
/// `OffRaster` error naming `what`: for callers that check a timing before
/// they build a run (a time the writer would refuse later).
pub fn gradient_raster_steps(what: &str, value_s: f64, raster_s: f64) -> Result<u64, PulseqError> {
    whole(|| what.to_string(), value_s, raster_s, "gradient raster")
}

/// `value` must be finite and in `(lo, hi]`.
fn check_range(name: &'static str, value: f64, lo: f64, hi: f64) -> Result<(), PulseqError> {
    if value.is_finite() && value > lo && value <= hi {
        Ok(())
    } else {
        Err(PulseqError::InvalidSetting {
            name,
            value,
            reason: format!("allowed range is ({lo:e}, {hi:e}]"),
        })
    }
}

/// `value` must be finite and in `[0, hi]`.
fn check_non_negative(name: &'static str, value: f64, hi: f64) -> Result<(), PulseqError> {
    if value.is_finite() && (0.0..=hi).contains(&value) {
        Ok(())
    } else {
        Err(PulseqError::InvalidSetting {
            name,
            value,
            reason: format!("allowed range is [0, {hi:e}]"),
        })
    }
}

/// Most RF raster samples the placeholder pulse may have (its shape is
/// stored sample by sample before compression).
const MAX_RF_SAMPLES: u64 = 1_000_000;

/// A number as the file writes it: exact (shortest round-trip form), without
/// an exponent for ordinary magnitudes, `0` for both zeros.
fn num(v: f64) -> String {
    if v == 0.0 {
        "0".to_string()
    } else if (1e-4..1e15).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Sample(usize),
    Tracking(usize),
}

impl Kind {
    fn describe(self) -> String {
        match self {
            Kind::Sample(i) => format!("actuation sample {i}"),
            Kind::Tracking(i) => format!("tracking phase {i}"),
        }
    }
}

/// One sample or phase on the gradient-raster timeline.
#[derive(Debug, Clone, Copy)]
struct Item {
    kind: Kind,
    start: u64,
    ticks: u64,
}

impl Item {
    fn end(&self) -> u64 {
        self.start + self.ticks
    }
}

/// Event and shape libraries, with identical entries shared.
#[derive(Default)]
struct Libraries {
    shapes: Vec<(usize, Vec<f64>)>,
    shape_ids: HashMap<String, usize>,
    gradients: Vec<String>,
    gradient_ids: HashMap<String, usize>,
}

impl Libraries {
    fn shape(&mut self, samples: &[f64]) -> usize {
        let key: Vec<String> = samples.iter().map(|&v| num(v)).collect();
        let key = key.join(" ");
        if let Some(&id) = self.shape_ids.get(&key) {
            return id;
        }
        self.shapes.push((samples.len(), stored_samples(samples)));
        let id = self.shapes.len();
        self.shape_ids.insert(key, id);
        id
    }

    /// An extended trapezoid through `points` (tick, Hz/m); `None` when it is zero.
    fn gradient(&mut self, points: &[(u64, f64)]) -> Option<usize> {
        let amplitude = points.iter().fold(0.0_f64, |m, p| m.max(p.1.abs()));
        if amplitude == 0.0 {
            return None;
        }
        let values: Vec<f64> = points.iter().map(|p| p.1 / amplitude).collect();
        let times: Vec<f64> = points.iter().map(|p| p.0 as f64).collect();
        let shape_id = self.shape(&values);
        let time_id = self.shape(&times);
        let line = format!("{} {shape_id} {time_id} 0", num(amplitude));
        if let Some(&id) = self.gradient_ids.get(&line) {
            return Some(id);
        }
        self.gradients.push(line.clone());
        let id = self.gradients.len();
        self.gradient_ids.insert(line, id);
        Some(id)
    }
}

fn validate(opts: &SequenceOptions) -> Result<(), PulseqError> {
    let l = &opts.limits;
    check_range("max_gradient_t_per_m", l.max_gradient_t_per_m, 0.0, 10.0)?;
    check_range(
        "slew_rate_t_per_m_per_s",
        l.slew_rate_t_per_m_per_s,
        0.0,
        1e5,
    )?;
    check_range("gradient_raster_s", l.gradient_raster_s, 1e-7, 1e-3)?;
    check_range(
        "block_duration_raster_s",
        l.block_duration_raster_s,
        0.0,
        1e-3,
    )?;
    check_range("rf_raster_s", l.rf_raster_s, 1e-9, 1e-4)?;
    check_range("adc_raster_s", l.adc_raster_s, 1e-10, 1e-4)?;
    let t = &opts.tracking;
    check_range("tracking.rf_duration_s", t.rf_duration_s, 0.0, 1.0)?;
    check_range("tracking.adc_duration_s", t.adc_duration_s, 0.0, 1.0)?;
    check_range("tracking.flip_angle_deg", t.flip_angle_deg, 0.0, 180.0)?;
    check_range(
        "tracking.adc_samples",
        f64::from(t.adc_samples),
        0.0,
        f64::from(u32::MAX),
    )?;
    check_non_negative("tracking.rf_delay_s", t.rf_delay_s, 1.0)?;
    check_non_negative("tracking.rf_to_adc_s", t.rf_to_adc_s, 1.0)?;
    Ok(())
}

/// The tracking block's event lines, computed once.
struct TrackingEvents {
    rf_samples: usize,
    rf_amplitude_hz: f64,
    rf_delay_us: u64,
    adc_dwell_ns: u64,
    adc_delay_us: u64,
    /// From the block start to the last ADC sample's end, s.
    needed_s: f64,
}

fn tracking_events(opts: &SequenceOptions) -> Result<TrackingEvents, PulseqError> {
    let t = &opts.tracking;
    let l = &opts.limits;
    let rf_samples = whole(
        || "tracking.rf_duration_s".into(),
        t.rf_duration_s,
        l.rf_raster_s,
        "RF raster",
    )?;
    if !(1..=MAX_RF_SAMPLES).contains(&rf_samples) {
        return Err(PulseqError::InvalidSetting {
            name: "tracking.rf_duration_s",
            value: t.rf_duration_s,
            reason: format!(
                "{rf_samples} RF raster samples; between 1 and {MAX_RF_SAMPLES} are allowed"
            ),
        });
    }
    let rf_delay_us = whole(
        || "tracking.rf_delay_s".into(),
        t.rf_delay_s,
        1e-6,
        "1 us grid",
    )?;
    let adc_start_s = t.rf_delay_s + t.rf_duration_s + t.rf_to_adc_s;
    let adc_delay_us = whole(
        || "tracking ADC start (rf_delay_s + rf_duration_s + rf_to_adc_s)".into(),
        adc_start_s,
        1e-6,
        "1 us grid",
    )?;
    whole(
        || "tracking ADC start (rf_delay_s + rf_duration_s + rf_to_adc_s)".into(),
        adc_start_s,
        l.rf_raster_s,
        "RF raster",
    )?;
    let dwell_rasters = (t.adc_duration_s / f64::from(t.adc_samples) / l.adc_raster_s)
        .round()
        .max(1.0);
    let dwell_s = dwell_rasters * l.adc_raster_s;
    let adc_dwell_ns = whole(
        || "ADC dwell time (adc_duration_s / adc_samples, on the ADC raster)".into(),
        dwell_s,
        1e-9,
        "1 ns grid",
    )?;
    Ok(TrackingEvents {
        rf_samples: rf_samples as usize,
        rf_amplitude_hz: t.flip_angle_deg / 360.0 / t.rf_duration_s,
        rf_delay_us,
        adc_dwell_ns,
        adc_delay_us,
        needed_s: adc_delay_us as f64 * 1e-6
            + adc_dwell_ns as f64 * 1e-9 * f64::from(t.adc_samples),
    })
}

fn check_metadata(metadata: &[(String, String)]) -> Result<(), PulseqError> {
    let mut seen = std::collections::HashSet::new();
    for (key, value) in metadata {
        let bad = |reason: &str| PulseqError::Metadata {
            key: key.clone(),
            reason: reason.to_string(),
        };
        if key.is_empty() || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(bad("keys are one or more ASCII letters, digits or `_`"));
        }
        if WRITER_KEYS.contains(&key.as_str()) {
            return Err(bad("the writer sets this definition itself"));
        }
        if !seen.insert(key.as_str()) {
            return Err(bad("given twice"));
        }
        if value.trim().is_empty() || value.chars().any(|c| c.is_control()) {
            return Err(bad(
                "values are one line of printable text, not empty, without control characters",
            ));
        }
    }
    Ok(())
}

/// Builds the `.seq` text of `run` (see the crate documentation for the layout).
pub fn build_sequence(run: &PlayedRun, opts: &SequenceOptions) -> Result<Sequence, PulseqError> {
    validate(opts)?;
    check_metadata(&run.metadata)?;
    let limits = &opts.limits;
    let raster = limits.gradient_raster_s;
    let tracking = tracking_events(opts)?;

    check_range("sample_time_s", run.sample_time_s, 0.0, 1e3)?;
    let sample_ticks = whole(
        || "sample_time_s".into(),
        run.sample_time_s,
        raster,
        "gradient raster",
    )?;

    // Every sample and phase on the gradient-raster timeline.
    let mut items = Vec::with_capacity(run.samples.len() + run.tracking.len());
    for (index, s) in run.samples.iter().enumerate() {
        let u = s.gradient_t_per_m;
        if !u.is_finite() {
            return Err(PulseqError::NotFinite {
                index,
                start_s: s.start_s,
                gradient_t_per_m: u,
            });
        }
        if u.abs() > limits.max_gradient_t_per_m * (1.0 + 1e-9) {
            return Err(PulseqError::Amplitude {
                index,
                start_s: s.start_s,
                gradient_t_per_m: u,
                limit_t_per_m: limits.max_gradient_t_per_m,
            });
        }
        let kind = Kind::Sample(index);
        let start = whole(
            || kind.describe() + " start",
            s.start_s,
            raster,
            "gradient raster",
        )?;
        items.push(Item {
            kind,
            start,
            ticks: sample_ticks,
        });
    }
    for (index, p) in run.tracking.iter().enumerate() {
        let kind = Kind::Tracking(index);
        let start = whole(
            || kind.describe() + " start",
            p.start_s,
            raster,
            "gradient raster",
        )?;
        let ticks = whole(
            || kind.describe() + " duration",
            p.duration_s,
            raster,
            "gradient raster",
        )?;
        if (ticks as f64) * raster < tracking.needed_s * (1.0 - 1e-12) {
            return Err(PulseqError::TrackingTooShort {
                index,
                start_s: p.start_s,
                duration_s: p.duration_s,
                needed_s: tracking.needed_s,
            });
        }
        items.push(Item { kind, start, ticks });
    }
    items.sort_by_key(|item| item.start);

    // No overlaps: each item starts at or after the latest end so far.
    let mut latest: Option<Item> = None;
    for item in &items {
        if let Some(prev) = latest {
            if item.start < prev.end() {
                return Err(PulseqError::Overlap {
                    what: item.kind.describe(),
                    start_s: item.start as f64 * raster,
                    previous: prev.kind.describe(),
                    previous_end_s: prev.end() as f64 * raster,
                });
            }
        }
        if latest.is_none_or(|p| item.end() > p.end()) {
            latest = Some(*item);
        }
    }
    let end = whole(
        || "run duration_s".into(),
        run.duration_s,
        raster,
        "gradient raster",
    )?;
    if let Some(last) = latest {
        if end < last.end() {
            return Err(PulseqError::EndsEarly {
                duration_s: run.duration_s,
                what: last.kind.describe(),
                end_s: last.end() as f64 * raster,
            });
        }
    }
    if end == 0 {
        return Err(PulseqError::Empty);
    }

    let gradient_of = |item: &Item| match item.kind {
        Kind::Sample(i) => Some(run.samples[i].gradient_t_per_m),
        Kind::Tracking(_) => None,
    };
    let slew_per_tick = limits.slew_rate_t_per_m_per_s * raster;
    // Whole ticks for a ramp over `step` T/m, at most the slew rate.
    let ramp_ticks = |step: f64| -> u64 {
        if step == 0.0 {
            0
        } else {
            ((step / slew_per_tick) - 1e-9).ceil().max(1.0) as u64
        }
    };

    let mut libs = Libraries::default();
    let mut blocks: Vec<[u64; 8]> = Vec::new();
    let mut counts = (0usize, 0usize, 0usize); // actuation, tracking, delay
    let mut longest_ramp_ticks = 0u64;
    let block_units = |ticks: u64, what: &dyn Fn() -> String| {
        whole(
            || format!("{} (block duration)", what()),
            ticks as f64 * raster,
            limits.block_duration_raster_s,
            "block duration raster",
        )
    };
    let push_delay = |blocks: &mut Vec<[u64; 8]>, ticks: u64, what: &dyn Fn() -> String| {
        let units = block_units(ticks, what)?;
        blocks.push([blocks.len() as u64 + 1, units, 0, 0, 0, 0, 0, 0]);
        Ok::<(), PulseqError>(())
    };

    let mut now = 0u64;
    for (k, item) in items.iter().enumerate() {
        if item.start > now {
            push_delay(&mut blocks, item.start - now, &|| {
                format!("pause before {}", item.kind.describe())
            })?;
            counts.2 += 1;
        }
        let units = block_units(item.ticks, &|| item.kind.describe())?;
        match item.kind {
            Kind::Tracking(_) => {
                blocks.push([blocks.len() as u64 + 1, units, 1, 0, 0, 0, 1, 0]);
                counts.1 += 1;
            }
            Kind::Sample(index) => {
                let u = run.samples[index].gradient_t_per_m;
                let neighbour = |j: Option<usize>| {
                    j.and_then(|j| items.get(j))
                        .filter(|n| n.end() == item.start || n.start == item.end())
                        .and_then(gradient_of)
                };
                let before = neighbour(k.checked_sub(1));
                let after = neighbour(Some(k + 1));
                // Centred ramps towards an adjacent sample, whole ramps to zero otherwise.
                let (in_ticks, v_start, from) = match before {
                    Some(a) => (ramp_ticks((u - a).abs() / 2.0), (a + u) / 2.0, a),
                    None => (ramp_ticks(u.abs()), 0.0, 0.0),
                };
                let (out_ticks, v_end, to) = match after {
                    Some(b) => (ramp_ticks((b - u).abs() / 2.0), (u + b) / 2.0, b),
                    None => (ramp_ticks(u.abs()), 0.0, 0.0),
                };
                let ramp_total = in_ticks.saturating_add(out_ticks);
                if ramp_total > item.ticks {
                    return Err(PulseqError::SlewRate {
                        index,
                        start_s: run.samples[index].start_s,
                        gradient_t_per_m: u,
                        from_t_per_m: from,
                        to_t_per_m: to,
                        slew_rate_t_per_m_per_s: limits.slew_rate_t_per_m_per_s,
                        needed_s: ramp_total as f64 * raster,
                        sample_s: item.ticks as f64 * raster,
                    });
                }
                let whole_ramp =
                    |ticks: u64, centred: bool| if centred { 2 * ticks } else { ticks };
                longest_ramp_ticks = longest_ramp_ticks
                    .max(whole_ramp(in_ticks, before.is_some()))
                    .max(whole_ramp(out_ticks, after.is_some()));
                let gamma = PROTON_GYROMAGNETIC_RATIO_HZ_PER_T;
                let mut points: Vec<(u64, f64)> = vec![(0, v_start * gamma)];
                let mut add = |tick: u64, value: f64| {
                    if points.last().is_none_or(|p| tick > p.0) {
                        points.push((tick, value * gamma));
                    }
                };
                if in_ticks > 0 {
                    add(in_ticks, u);
                }
                if out_ticks > 0 {
                    add(item.ticks - out_ticks, u);
                }
                add(item.ticks, v_end);
                let gx = libs.gradient(&points).unwrap_or(0) as u64;
                blocks.push([blocks.len() as u64 + 1, units, 0, gx, 0, 0, 0, 0]);
                counts.0 += 1;
            }
        }
        now = item.end();
    }
    if end > now {
        push_delay(&mut blocks, end - now, &|| {
            "pause at the end of the run".into()
        })?;
        counts.2 += 1;
    }

    // RF shapes after the gradient shapes (only when there is tracking).
    let rf_shapes = if counts.1 > 0 {
        Some((
            libs.shape(&vec![1.0; tracking.rf_samples]),
            libs.shape(&vec![0.0; tracking.rf_samples]),
        ))
    } else {
        None
    };

    let duration_s = end as f64 * raster;
    let mut text = String::new();
    let (major, minor, revision) = PULSEQ_VERSION;
    let t = &opts.tracking;
    // Writing to a String cannot fail.
    let _ = write!(
        text,
        "# Pulseq sequence file\n\
         # Created by capsule-mpc-pulseq {}: an executed capsule-mpc run.\n\
         # Actuation: one block per sample, x gradient (Hz/m) as an extended trapezoid.\n\
         # Tracking: one block per tracking phase holding a PLACEHOLDER event (hard RF\n\
         # pulse + ADC, no gradients); replace it with the site's tracking sequence.\n\
         \n\
         [VERSION]\nmajor {major}\nminor {minor}\nrevision {revision}\n\n",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(text, "[DEFINITIONS]");
    let _ = writeln!(text, "AdcRasterTime {:e}", limits.adc_raster_s);
    let _ = writeln!(
        text,
        "BlockDurationRaster {:e}",
        limits.block_duration_raster_s
    );
    let _ = writeln!(text, "GradientRasterTime {:e}", limits.gradient_raster_s);
    let _ = writeln!(text, "RadiofrequencyRasterTime {:e}", limits.rf_raster_s);
    let _ = writeln!(text, "TotalDuration {}", num(duration_s));
    let _ = writeln!(
        text,
        "CapsuleMpcGammaHzPerT {}",
        num(PROTON_GYROMAGNETIC_RATIO_HZ_PER_T)
    );
    let _ = writeln!(
        text,
        "CapsuleMpcMaxGradientTPerM {}",
        num(limits.max_gradient_t_per_m)
    );
    let _ = writeln!(
        text,
        "CapsuleMpcSlewRateTPerMPerS {}",
        num(limits.slew_rate_t_per_m_per_s)
    );
    let _ = writeln!(text, "CapsuleMpcSampleTimeS {}", num(run.sample_time_s));
    let _ = writeln!(
        text,
        "CapsuleMpcTrackingPlaceholder hard RF pulse of {} s and {} deg, then ADC of {} samples over {} s",
        num(t.rf_duration_s),
        num(t.flip_angle_deg),
        t.adc_samples,
        num(t.adc_duration_s)
    );
    for (key, value) in &run.metadata {
        let _ = writeln!(text, "{key} {}", value.trim());
    }
    let _ = write!(
        text,
        "\n# Format of blocks:\n# NUM DUR RF  GX  GY  GZ  ADC  EXT\n[BLOCKS]\n"
    );
    for b in &blocks {
        let _ = writeln!(
            text,
            "{} {} {} {} {} {} {} {}",
            b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]
        );
    }
    if let Some((mag_id, phase_id)) = rf_shapes {
        let _ = write!(
            text,
            "\n# Format of RF events:\n\
             # id amplitude mag_id phase_id time_shape_id delay freq phase\n\
             # ..        Hz   ....     ....          ....    us   Hz   rad\n\
             [RF]\n1 {} {mag_id} {phase_id} 0 {} 0 0\n",
            num(tracking.rf_amplitude_hz),
            tracking.rf_delay_us
        );
    }
    if !libs.gradients.is_empty() {
        let _ = write!(
            text,
            "\n# Format of arbitrary gradients:\n\
             #   time_shape_id of 0 means default timing (stepping with grad_raster starting at 1/2 of grad_raster)\n\
             # id amplitude amp_shape_id time_shape_id delay\n\
             # ..      Hz/m       ..         ..          us\n\
             [GRADIENTS]\n"
        );
        for (i, line) in libs.gradients.iter().enumerate() {
            let _ = writeln!(text, "{} {line}", i + 1);
        }
    }
    if counts.1 > 0 {
        let _ = write!(
            text,
            "\n# Format of ADC events:\n\
             # id num dwell delay freq phase\n\
             # ..  ..    ns    us   Hz   rad\n\
             [ADC]\n1 {} {} {} 0 0\n",
            t.adc_samples, tracking.adc_dwell_ns, tracking.adc_delay_us
        );
    }
    if !libs.shapes.is_empty() {
        let _ = write!(text, "\n# Sequence Shapes\n[SHAPES]\n\n");
        for (i, (num_samples, data)) in libs.shapes.iter().enumerate() {
            let _ = writeln!(text, "shape_id {}\nnum_samples {num_samples}", i + 1);
            for &v in data {
                let _ = writeln!(text, "{}", num(v));
            }
            text.push('\n');
        }
    }
    let hash = Md5::digest(text.as_bytes());
    let hex: String = hash.iter().map(|b| format!("{b:02x}")).collect();
    let _ = write!(
        text,
        "\n[SIGNATURE]\n\
         # This is the hash of the Pulseq file, calculated right before the [SIGNATURE] section was added\n\
         # It can be reproduced/verified with md5sum if the file trimmed to the position right above [SIGNATURE]\n\
         # The new line character preceding [SIGNATURE] BELONGS to the signature (and needs to be stripped away for recalculating/verification)\n\
         Type md5\nHash {hex}\n"
    );

    Ok(Sequence {
        text,
        blocks: blocks.len(),
        actuation_blocks: counts.0,
        tracking_blocks: counts.1,
        delay_blocks: counts.2,
        duration_s,
        longest_ramp_s: longest_ramp_ticks as f64 * raster,
    })
}

/// Builds the sequence and writes it to `path` atomically (a temporary file
/// in the same directory, flushed, then renamed over `path`), so that a reader
/// never sees a half-written file.
pub fn write_sequence_file(
    path: &Path,
    run: &PlayedRun,
    opts: &SequenceOptions,
) -> Result<Sequence, PulseqError> {
    let sequence = build_sequence(run, opts)?;
    write_atomic(path, sequence.text.as_bytes())?;
    Ok(sequence)
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), PulseqError> {
    let io = |reason: String| PulseqError::Io {
        path: path.display().to_string(),
        reason,
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| io("not a file path".into()))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".tmp.{}", std::process::id()));
    let tmp_path = dir.join(tmp_name);
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp_path)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp_path, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp_path);
        return Err(io(e.to_string()));
    }
    Ok(())
}
