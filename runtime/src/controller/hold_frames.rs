//! The hold's drift along one coordinate, told from the raw frames. An
//! arrival that keeps a relative speed of most of a mm/s drifts apart in
//! the hold, which brakes it at 1-2e-4 m/s^2 along the drag direction (see
//! `station`) to a stop 1.5-2 mm apart, at the band's edge, and not at all
//! along three capsules' third combination (see `third_combination`);
//! the disturbance then carries a capsule out seconds later, and the
//! manoeuvre that follows starts the settle again late. The filters'
//! relative speed near rest can be off by the size of that speed (0.2 mm
//! frames tens of ms apart, and a process noise that lets them follow
//! manoeuvres), so the hold's entry test cannot see it. A line through the
//! hold's first second or so of raw frames along the coordinate tells the
//! drift to about 0.1-0.3 mm/s; where even its optimistic end leaves the
//! band, the hold is left at once, and the shot or plan that follows
//! re-enters it about 0.2 s later instead of seconds.

use super::settings::HOLD_LINE_MIN_FRAMES;

/// Frames kept since the hold was entered: every frame of the
/// `HOLD_DRIFT_FIT_S` and `HOLD_THIRD_FIT_S` judged, for cycles of one
/// 20 ms sample or longer (with shorter ones, the latest).
pub const HOLD_FRAME_LOG: usize = 40;

/// The hold's frames along one coordinate: (time since entry s,
/// coordinate), oldest overwritten first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldFrames {
    frames: [[f64; 2]; HOLD_FRAME_LOG],
    /// Frames logged since the hold was entered (may exceed the log).
    count: usize,
    /// Whether this hold's drift has been judged (once per hold, see
    /// `HOLD_DRIFT_FIT_S`).
    pub judged: bool,
    /// Whether it is judged once more (`HOLD_DRIFT_RECHECK_S`).
    pub recheck: bool,
}

/// A straight line through the frames: the coordinate at the last frame
/// and its rate, with the rate's standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftLine {
    pub coordinate: f64,
    pub rate: f64,
    pub rate_std: f64,
}

impl HoldFrames {
    pub const fn new() -> Self {
        HoldFrames {
            frames: [[0.0; 2]; HOLD_FRAME_LOG],
            count: 0,
            judged: false,
            recheck: false,
        }
    }

    /// Forgets every frame (hold entry).
    pub fn clear(&mut self) {
        self.count = 0;
        self.judged = false;
        self.recheck = false;
    }

    /// Logs a frame at `t_s` since entry with coordinate `xi`.
    pub fn push(&mut self, t_s: f64, xi: f64) {
        self.frames[self.count % HOLD_FRAME_LOG] = [t_s, xi];
        self.count += 1;
    }

    /// Whether the log holds `fit_s` of frames, or as many as it keeps.
    pub fn covers(&self, fit_s: f64) -> bool {
        let kept = self.count.min(HOLD_FRAME_LOG);
        if kept == HOLD_FRAME_LOG {
            return true;
        }
        let (mut first, mut last) = (f64::INFINITY, f64::NEG_INFINITY);
        for f in self.frames.iter().take(kept) {
            first = first.min(f[0]);
            last = last.max(f[0]);
        }
        kept > 1 && last - first >= fit_s
    }

    /// The earlier of `from_s` and the time of the `n`-th latest frame
    /// logged (frames are logged in time order), so that a line from there
    /// runs through at least `n` frames while the log holds them: longer
    /// cycles or lost frames stretch the stretch instead of leaving it too
    /// short to fit.
    pub fn start_of_latest(&self, from_s: f64, n: usize) -> f64 {
        if n == 0 || self.count.min(HOLD_FRAME_LOG) < n {
            return from_s;
        }
        from_s.min(self.frames[(self.count - n) % HOLD_FRAME_LOG][0])
    }

    /// Least-squares line through the logged frames, each with standard
    /// deviation `xi_std`; None with fewer than `HOLD_LINE_MIN_FRAMES` or
    /// no time spread.
    pub fn line(&self, xi_std: f64) -> Option<DriftLine> {
        self.line_since(f64::NEG_INFINITY, xi_std)
    }

    /// As [`Self::line`], through the frames logged at `from_s` or later.
    pub fn line_since(&self, from_s: f64, xi_std: f64) -> Option<DriftLine> {
        let kept = self.count.min(HOLD_FRAME_LOG);
        let (mut n, mut st, mut sx, mut last_t) = (0.0, 0.0, 0.0, f64::NEG_INFINITY);
        for f in self.frames.iter().take(kept).filter(|f| f[0] >= from_s) {
            n += 1.0;
            st += f[0];
            sx += f[1];
            last_t = last_t.max(f[0]);
        }
        if n < HOLD_LINE_MIN_FRAMES as f64 {
            return None;
        }
        let (tm, xm) = (st / n, sx / n);
        let (mut stt, mut stx) = (0.0, 0.0);
        for f in self.frames.iter().take(kept).filter(|f| f[0] >= from_s) {
            stt += (f[0] - tm) * (f[0] - tm);
            stx += (f[0] - tm) * (f[1] - xm);
        }
        if stt <= 0.0 {
            return None;
        }
        let rate = stx / stt;
        Some(DriftLine {
            coordinate: xm + rate * (last_t - tm),
            rate,
            rate_std: xi_std / libm::sqrt(stt),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_through_the_frames_is_their_least_squares_drift() {
        let mut log = HoldFrames::new();
        for k in 0..HOLD_LINE_MIN_FRAMES - 1 {
            log.push(0.04 * k as f64, 1.0e-3 - 0.5e-3 * 0.04 * k as f64);
        }
        assert!(log.line(0.2e-3).is_none(), "too few frames for a line");
        // Past the log's capacity the oldest frames are overwritten: a
        // drift that changed speed is fitted on the recent frames only.
        for k in 0..3 * HOLD_FRAME_LOG {
            let t = 0.04 * k as f64;
            let slope = if k < HOLD_FRAME_LOG { 2.0e-3 } else { -0.5e-3 };
            log.push(t, slope * t);
        }
        let line = log.line(0.2e-3).expect("line");
        assert!((line.rate + 0.5e-3).abs() < 1e-12, "rate {}", line.rate);
        let last_t = 0.04 * (3 * HOLD_FRAME_LOG - 1) as f64;
        assert!((line.coordinate + 0.5e-3 * last_t).abs() < 1e-12);
        // The log's frames, 40 ms apart: the rate's deviation is the
        // frames' over the square root of their time spread.
        let spread: f64 = (0..HOLD_FRAME_LOG)
            .map(|k| {
                let d = 0.04 * k as f64 - 0.04 * (HOLD_FRAME_LOG - 1) as f64 / 2.0;
                d * d
            })
            .sum();
        assert!((line.rate_std - 0.2e-3 / spread.sqrt()).abs() < 1e-12);
        // The latest frames: 40 ms apart, so the 8th latest is 0.28 s back.
        assert_eq!(log.start_of_latest(last_t, 1), last_t);
        assert!((log.start_of_latest(last_t, 8) - (last_t - 0.28)).abs() < 1e-12);
        assert_eq!(log.start_of_latest(0.0, 8), 0.0);
        log.clear();
        assert!(log.line(0.2e-3).is_none(), "cleared at hold entry");
        assert_eq!(
            log.start_of_latest(1.0, 8),
            1.0,
            "too few frames: unchanged"
        );
        assert!(!log.judged && !log.recheck);
    }
}
