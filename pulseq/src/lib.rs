//! Writes an executed capsule-mpc run as a [Pulseq] sequence file (format
//! version 1.4.1), so that the run can be inspected, checked and replayed by
//! Pulseq tools and interpreters.
//!
//! The input is a plain description of the run as it was played
//! ([`PlayedRun`]): the actuation samples (the x gradient `u = dBz/dx` held
//! for one sample time each), the tracking phases, and metadata strings. This
//! crate knows nothing else of the project.
//!
//! # What the file holds
//!
//! * One block per actuation sample, with an x gradient at the commanded
//!   amplitude (T/m converted to Hz/m with [`PROTON_GYROMAGNETIC_RATIO_HZ_PER_T`])
//!   as an *extended trapezoid* (a gradient given by corner points on a time
//!   shape). Amplitude steps between consecutive samples are ramped at no more
//!   than the slew-rate limit, and each ramp is **centred on the sample
//!   boundary**: half of it at the end of the earlier sample, half at the start
//!   of the later one, through the mean of the two amplitudes at the boundary.
//!   Away from the ramps the gradient equals the commanded `u` exactly, and
//!   the gradient-time integral of each step (which sets the impulse given to
//!   the capsules) is the zero-order hold's. Where a sample borders something
//!   other than another sample (a tracking phase, a pause, the start or the
//!   end of the run) the gradient must be zero at the boundary, so the whole
//!   ramp lies inside the sample: the gradient starts rising at the sample's
//!   start and has fallen to zero at its end. Ramps on the paper's scanner
//!   (40 mT/m, 200 T/m/s) last at most 0.2 ms of a 20 ms sample.
//! * One block per tracking phase, lasting the phase, holding a
//!   **placeholder** tracking event ([`TrackingPlaceholder`]): a hard RF
//!   excitation and an ADC readout, with no gradient. It stands for the site's
//!   own 1-D tracking sequence (excitation and projection readouts along the
//!   tracking axis, x), which a site must put in its place; the placeholder
//!   only fixes where tracking happens and how long it may take.
//! * Delay blocks (no events) for the time between phases that is neither
//!   actuation nor tracking (for example the computation delay after tracking).
//! * `[DEFINITIONS]` with the raster times, the total duration, the limits the
//!   file was checked against, and the run's metadata.
//! * A `[SIGNATURE]` (MD5 of the file above it), as Pulseq interpreters expect.
//!
//! The writer refuses, with an error naming the sample or phase and the limit,
//! anything it cannot play within the limits: an amplitude over the limit, a
//! step too large to ramp within the sample at the slew limit, times off the
//! raster, overlapping phases, a tracking phase too short for its event.
//!
//! [Pulseq]: https://pulseq.github.io/

mod run;
mod shape;
mod writer;

pub use run::*;
pub use writer::{build_sequence, gradient_raster_steps, write_sequence_file, Sequence};
