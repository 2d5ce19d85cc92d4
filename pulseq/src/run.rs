//! What the writer takes: the played run, the scanner's limits, the
//! placeholder tracking event, and the errors naming what is at fault.

/// Proton gyromagnetic ratio gamma / (2 pi), Hz/T: Pulseq gradient amplitudes
/// are in Hz/m, `g_hz_per_m = gamma * g_t_per_m`.
pub const PROTON_GYROMAGNETIC_RATIO_HZ_PER_T: f64 = 42.577478e6;

/// Pulseq file format version written (major, minor, revision).
pub const PULSEQ_VERSION: (u32, u32, u32) = (1, 4, 1);

/// Default gradient (and block duration) raster, s.
pub const DEFAULT_GRADIENT_RASTER_S: f64 = 10e-6;
/// Default RF raster, s.
pub const DEFAULT_RF_RASTER_S: f64 = 1e-6;
/// Default ADC raster, s.
pub const DEFAULT_ADC_RASTER_S: f64 = 100e-9;

/// One actuation sample: the x gradient held from `start_s` for one sample time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuationSample {
    /// Start of the sample from the start of the run, s.
    pub start_s: f64,
    /// Commanded gradient u = dBz/dx, T/m.
    pub gradient_t_per_m: f64,
}

/// One tracking phase (no actuation while it lasts).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingPhase {
    /// Start of the phase from the start of the run, s.
    pub start_s: f64,
    /// Length of the phase, s.
    pub duration_s: f64,
}

/// The run as it was played on the scanner's timeline.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlayedRun {
    /// Length of one actuation sample (the zero-order hold), s.
    pub sample_time_s: f64,
    /// Actuation samples (any order; they must not overlap each other or a
    /// tracking phase).
    pub samples: Vec<ActuationSample>,
    /// Tracking phases.
    pub tracking: Vec<TrackingPhase>,
    /// End of the run from its start, s: at or after the end of the last
    /// sample or phase (the rest becomes a delay block).
    pub duration_s: f64,
    /// `(key, value)` pairs written to `[DEFINITIONS]`: keys are letters,
    /// digits and `_`; values are one line of printable text.
    pub metadata: Vec<(String, String)>,
}

/// The scanner's limits and raster times the file must respect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScannerLimits {
    /// Largest gradient magnitude, T/m.
    pub max_gradient_t_per_m: f64,
    /// Largest gradient slew rate, T/m/s.
    pub slew_rate_t_per_m_per_s: f64,
    /// Gradient raster, s: every ramp corner lies on it, and so must every
    /// start and duration of the run.
    pub gradient_raster_s: f64,
    /// Block duration raster, s.
    pub block_duration_raster_s: f64,
    /// RF raster, s.
    pub rf_raster_s: f64,
    /// ADC dwell-time raster, s.
    pub adc_raster_s: f64,
}

impl ScannerLimits {
    /// Limits with the given amplitude, slew rate and gradient raster; the
    /// block duration raster is the gradient raster and the RF and ADC
    /// rasters are the common 1 us and 100 ns.
    pub fn new(
        max_gradient_t_per_m: f64,
        slew_rate_t_per_m_per_s: f64,
        gradient_raster_s: f64,
    ) -> ScannerLimits {
        ScannerLimits {
            max_gradient_t_per_m,
            slew_rate_t_per_m_per_s,
            gradient_raster_s,
            block_duration_raster_s: gradient_raster_s,
            rf_raster_s: DEFAULT_RF_RASTER_S,
            adc_raster_s: DEFAULT_ADC_RASTER_S,
        }
    }
}

/// The placeholder tracking event put in every tracking block: a hard RF pulse
/// followed by one ADC readout, no gradients. **A placeholder**: a site
/// replaces it with its own tracking sequence (see docs/pulseq.md).
///
/// Within the block: `rf_delay_s` of nothing (covers the RF dead time), the
/// RF pulse (`rf_duration_s`), `rf_to_adc_s` of nothing (covers RF ring-down
/// and ADC dead time), the ADC (`adc_samples` samples over `adc_duration_s`),
/// then nothing to the end of the phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingPlaceholder {
    /// Length of the hard RF pulse, s (a whole number of RF raster times).
    pub rf_duration_s: f64,
    /// Flip angle of the RF pulse, degrees.
    pub flip_angle_deg: f64,
    /// Length of the ADC readout, s (the dwell time is rounded to the ADC raster).
    pub adc_duration_s: f64,
    /// Number of ADC samples.
    pub adc_samples: u32,
    /// Time from the block start to the RF pulse, s.
    pub rf_delay_s: f64,
    /// Time from the end of the RF pulse to the first ADC sample, s.
    pub rf_to_adc_s: f64,
}

/// Default placeholder RF pulse length, s.
pub const DEFAULT_TRACKING_RF_DURATION_S: f64 = 1e-3;
/// Default placeholder ADC readout length, s.
pub const DEFAULT_TRACKING_ADC_DURATION_S: f64 = 10.24e-3;

impl Default for TrackingPlaceholder {
    fn default() -> Self {
        TrackingPlaceholder {
            rf_duration_s: DEFAULT_TRACKING_RF_DURATION_S,
            flip_angle_deg: 5.0,
            adc_duration_s: DEFAULT_TRACKING_ADC_DURATION_S,
            adc_samples: 256,
            rf_delay_s: 100e-6,
            rf_to_adc_s: 100e-6,
        }
    }
}

impl TrackingPlaceholder {
    /// Time the event needs from the start of its block to the end of the ADC, s.
    pub fn needed_s(&self) -> f64 {
        self.rf_delay_s + self.rf_duration_s + self.rf_to_adc_s + self.adc_duration_s
    }
}

/// Everything the writer needs besides the run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequenceOptions {
    pub limits: ScannerLimits,
    pub tracking: TrackingPlaceholder,
}

/// Why a run cannot be written. Each variant names the sample, phase, limit
/// or key at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PulseqError {
    #[error("`{name}` = {value} is invalid: {reason}")]
    InvalidSetting {
        name: &'static str,
        value: f64,
        reason: String,
    },
    #[error("actuation sample {index} (t = {start_s} s): gradient {gradient_t_per_m} T/m is not a finite number")]
    NotFinite {
        index: usize,
        start_s: f64,
        gradient_t_per_m: f64,
    },
    #[error("actuation sample {index} (t = {start_s} s): gradient {gradient_t_per_m} T/m exceeds the amplitude limit of {limit_t_per_m} T/m")]
    Amplitude {
        index: usize,
        start_s: f64,
        gradient_t_per_m: f64,
        limit_t_per_m: f64,
    },
    #[error("actuation sample {index} (t = {start_s} s): at the slew-rate limit of {slew_rate_t_per_m_per_s} T/m/s, ramping in from {from_t_per_m} T/m and out to {to_t_per_m} T/m around its gradient {gradient_t_per_m} T/m needs {needed_s} s of the sample, which lasts {sample_s} s")]
    SlewRate {
        index: usize,
        start_s: f64,
        gradient_t_per_m: f64,
        from_t_per_m: f64,
        to_t_per_m: f64,
        slew_rate_t_per_m_per_s: f64,
        needed_s: f64,
        sample_s: f64,
    },
    #[error("{what}: {value_s} s is not a non-negative whole number of the {raster_s} s {raster}")]
    OffRaster {
        what: String,
        value_s: f64,
        raster: &'static str,
        raster_s: f64,
    },
    #[error("{what} (from {start_s} s) overlaps {previous}, which ends at {previous_end_s} s")]
    Overlap {
        what: String,
        start_s: f64,
        previous: String,
        previous_end_s: f64,
    },
    #[error("tracking phase {index} (t = {start_s} s) lasts {duration_s} s; the placeholder tracking event needs {needed_s} s (RF delay, RF, RF-to-ADC gap, ADC)")]
    TrackingTooShort {
        index: usize,
        start_s: f64,
        duration_s: f64,
        needed_s: f64,
    },
    #[error("the run ends at {duration_s} s, before its last {what} ends at {end_s} s")]
    EndsEarly {
        duration_s: f64,
        what: String,
        end_s: f64,
    },
    #[error("the run is empty: no actuation sample, no tracking phase and no duration")]
    Empty,
    #[error("metadata key `{key}`: {reason}")]
    Metadata { key: String, reason: String },
    #[error("cannot write {path}: {reason}")]
    Io { path: String, reason: String },
}
