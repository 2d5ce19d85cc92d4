//! Station keeping in the terminal hold: the capsules' relative position
//! through drag.
//!
//! Near rest one gradient moves every capsule alike, so the hold's PD law
//! keeps the group's centre but not the capsules' positions relative to one
//! another, and a disturbance that differs between capsules (a constant
//! bias of the paper's size gives up to 0.7 mm/s of relative drift) walks
//! them out of the 1 mm band. What sets capsules apart is drag,
//! `-b_i v|v|`, which differs between them. A common velocity waveform
//! with zero mean that is fast one way for a short time and slow the other
//! way for longer has `mean(v|v|) != 0` and returns to where it started:
//! capsule i then feels a mean acceleration `-b_i mean(v|v|)`, so the
//! group's shape changes at a rate set by the waveform's asymmetry, while
//! its centre does not move. A PID on the relative error along the drag
//! direction `beta_i = b_i - mean(b)` sets that asymmetry, bounded so that
//! every speed stays below the settle band's 5 mm/s.
//!
//! Authority: with speeds below `V`, `|mean(v|v|)| <= 0.17 V^2` (fast for
//! 29 % of the time, the best split), so the relative acceleration it can
//! hold against is at most `(b_1 - b_2) x 0.17 V^2`: 5e-4 m/s^2 at the
//! band's 5 mm/s for the default capsules, 1.6-2.2e-4 m/s^2 with this
//! pattern at its 3.5 mm/s, against up to 7e-4 m/s^2 for the relative part
//! of a constant bias of the paper's size (||d|| <= 5e-4 in SI). A larger
//! relative bias cannot be held inside the band by any law that keeps the
//! speeds inside it.

/// Dither levels over one pattern, in units of the amplitude (one level per
/// actuation sample, reached by its end). Zero net displacement for every
/// gap (the ramps up and down cancel, and the levels weigh 2 x 1 against
/// 4 x 0.5); fast one third of the time, close to the best split (29 %).
pub const STATION_PATTERN: [f64; 6] = [1.0, 1.0, -0.5, -0.5, -0.5, -0.5];

/// Largest dither speed of two capsules, m/s: below the settle band's
/// 5 mm/s, with room for the centre law's own motion
/// (`STATION_SPEED_BUDGET_M_PER_S` caps each pattern by what that motion
/// leaves, `STATION_FAST_WITHIN_M` near the band's edge). Three capsules
/// play at the judged speed: their hold's walk of the third combination
/// is judged on that pattern, and at 3.5 mm/s one run of the scanner test
/// (`tests/three_capsules.rs`) took more than twice its bound.
pub const STATION_MAX_SPEED_M_PER_S: f64 = 3.5e-3;

/// Dither speed the hold's stopping test counts on (`can_stop`), m/s:
/// less than the dither plays. Off the model the learned factors tell the
/// differential drag only roughly, and the capsules' other motion often
/// leaves the dither less than its full speed; judged at the speed it
/// plays, holds were kept that the dither then could not, and left seconds
/// later (docs/decisions.md).
pub const STATION_JUDGED_SPEED_M_PER_S: f64 = 3.0e-3;

/// The dither plays above `STATION_JUDGED_SPEED_M_PER_S` only while every
/// capsule is within this distance of its target, m (a margin inside the
/// band's 1 mm: playing faster at the edge too failed a glitch recovery
/// that otherwise took 2.4 s, docs/decisions.md).
pub const STATION_FAST_WITHIN_M: f64 = 0.7e-3;

/// Speed budget of the hold, m/s: a pattern starts only with the amplitude
/// left after the capsules' other motion (their speeds about the dither's
/// and what the centre law will add), so that the sum stays inside the
/// settle band's 5 mm/s.
pub const STATION_SPEED_BUDGET_M_PER_S: f64 = 4.5e-3;

/// Bandwidth of the relative-position loop, rad/s (three poles there).
pub const STATION_BANDWIDTH_RAD_PER_S: f64 = 1.0;

/// Time constant of the low-pass on the relative rate estimate, s.
pub const STATION_RATE_FILTER_S: f64 = 0.3;

/// State of the station-keeping dither (part of the controller's memory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StationKeeper<const NX: usize> {
    /// Drag direction `beta_i / sum beta^2` per capsule (the first NX / 2
    /// entries), m (zero: no differential drag, the dither is off).
    drag_direction: [f64; NX],
    /// The coordinate the dither holds: the drag direction less its
    /// component along the capsules' gains (see `set_gains`), m.
    direction: [f64; NX],
    /// `direction_i * b_i`: each capsule's share of the differential drag
    /// (they sum to 1 when the drags differ), for `drag_authority`.
    drag_share: [f64; NX],
    /// Index into [`STATION_PATTERN`] of the next actuation sample.
    phase: usize,
    /// Signed amplitude of the current pattern, m/s.
    amplitude_m_per_s: f64,
    /// The dither's common velocity now (the model's), m/s.
    velocity_m_per_s: f64,
    /// The dither's common displacement now, m.
    displacement_m: f64,
    /// Integral of the relative error, m^2 s.
    integral: f64,
    /// Low-passed relative rate, m^2/s (NaN: no sample yet).
    rate: f64,
    /// Time since the pattern started from rest (hold entry), s.
    held_s: f64,
}

impl<const NX: usize> StationKeeper<NX> {
    /// From the capsules' drag coefficients `drag[i]`, 1/m.
    pub fn new(drag: &[f64]) -> Self {
        let m = NX / 2;
        let mean = drag.iter().take(m).sum::<f64>() / m.max(1) as f64;
        let mut direction = [0.0; NX];
        let mut norm2 = 0.0;
        for i in 0..m {
            direction[i] = drag[i] - mean;
            norm2 += direction[i] * direction[i];
        }
        // Capsules with (nearly) the same drag cannot be told apart.
        let distinct = norm2.is_finite() && norm2 > 1e-6 * mean * mean && mean > 0.0;
        for d in direction.iter_mut() {
            *d = if distinct { *d / norm2 } else { 0.0 };
        }
        let mut drag_share = [0.0; NX];
        for i in 0..m {
            drag_share[i] = direction[i] * drag[i];
        }
        StationKeeper {
            drag_direction: direction,
            direction,
            drag_share,
            phase: 0,
            amplitude_m_per_s: 0.0,
            velocity_m_per_s: 0.0,
            displacement_m: 0.0,
            integral: 0.0,
            rate: f64::NAN,
            held_s: 0.0,
        }
    }

    /// The capsules' gains the relative coordinate is taken across (m/s^2
    /// per T/m; None: equal gains, the model's). One gradient moves
    /// capsule i by g_i u, so the motion the gradient makes (the centre
    /// law's, the dither's own) is along g; the coordinate the dither
    /// holds is the drag direction less its component along g, so that
    /// it sees none of that motion. With equal gains the drag direction
    /// (zero mean) is already across it; with gains 15 % apart it is not,
    /// and the dither's own 3 mm/s read as a relative drift the hold could
    /// not stop (docs/decisions.md).
    pub fn set_gains(&mut self, gains: Option<&[f64]>) {
        self.direction = self.drag_direction;
        let Some(g) = gains else {
            return;
        };
        let m = NX / 2;
        let norm2: f64 = g.iter().take(m).map(|x| x * x).sum();
        if !(norm2.is_finite() && norm2 > 0.0) {
            return;
        }
        let along: f64 = self
            .drag_direction
            .iter()
            .zip(g)
            .take(m)
            .map(|(d, x)| d * x)
            .sum::<f64>()
            / norm2;
        for (d, x) in self.direction.iter_mut().zip(g).take(m) {
            *d -= along * x;
        }
    }

    /// Whether the dither can stop the capsules' relative motion in `e`
    /// (along the drag direction) with their relative position, where it
    /// stops, within `spread_m`: braking at the authority it is judged to
    /// have (`STATION_JUDGED_SPEED_M_PER_S`), the relative position stops at
    /// `q + w |w| / (2 a)`. A relative motion that would stop beyond it
    /// leaves the band whatever the hold does. `authority` scales a
    /// (`drag_authority`: 1 on the model). Capsules without differential
    /// drag: true (the hold cannot do better or worse).
    ///
    /// `rate_std`: how well the relative rate is known (see `rate_std`;
    /// 0 for the estimate alone): true when some rate within `rate_std` of
    /// the estimated one stops inside. The stopping point is monotonic in
    /// the rate, so the interval's ends (and zero between them) decide.
    pub fn can_stop(
        &self,
        e: &[f64; NX],
        dt_s: f64,
        gap_s: f64,
        spread_m: f64,
        authority: f64,
        rate_std: f64,
    ) -> bool {
        let (mut xi, mut rate) = (0.0, 0.0);
        for i in 0..NX / 2 {
            xi += self.direction[i] * e[2 * i];
            rate += self.direction[i] * e[2 * i + 1];
        }
        self.motion_stops_within(xi, rate, dt_s, gap_s, spread_m, authority, rate_std)
    }

    /// As [`Self::can_stop`], for the relative motion along the drag
    /// direction given directly: position `xi` and rate `rate` in the
    /// direction's units (see [`Self::along_direction`]).
    #[allow(clippy::too_many_arguments)]
    pub fn motion_stops_within(
        &self,
        xi: f64,
        rate: f64,
        dt_s: f64,
        gap_s: f64,
        spread_m: f64,
        authority: f64,
        rate_std: f64,
    ) -> bool {
        let mut reach = 0.0;
        for i in 0..NX / 2 {
            // Each capsule's share of the spread, in the direction's units.
            reach += libm::fabs(self.direction[i]) * 0.5 * spread_m;
        }
        if reach == 0.0 {
            return true;
        }
        let kappa = pattern_drag_gain(dt_s, gap_s);
        let limit =
            (authority * kappa * STATION_JUDGED_SPEED_M_PER_S * STATION_JUDGED_SPEED_M_PER_S)
                .max(f64::MIN_POSITIVE);
        let stop = |w: f64| xi + w * libm::fabs(w) / (2.0 * limit);
        let (lo, hi) = (
            stop(rate - rate_std.max(0.0)),
            stop(rate + rate_std.max(0.0)),
        );
        let nearest = if lo <= 0.0 && hi >= 0.0 {
            0.0
        } else {
            libm::fabs(lo).min(libm::fabs(hi))
        };
        nearest <= reach
    }

    /// The length of the drag direction (see `along_direction`), 1/m.
    pub fn direction_norm(&self) -> f64 {
        libm::sqrt(
            self.direction
                .iter()
                .take(NX / 2)
                .map(|d| d * d)
                .sum::<f64>(),
        )
    }

    /// The capsules' positions `p` (relative to their targets, m, one per
    /// capsule) along the drag direction: the coordinate the dither holds.
    pub fn along_direction(&self, p: &[f64]) -> f64 {
        self.direction
            .iter()
            .zip(p)
            .take(NX / 2)
            .map(|(d, x)| d * x)
            .sum()
    }

    /// Standard deviation of the relative rate `can_stop` projects, from
    /// each capsule's speed standard deviation (independent filters).
    pub fn rate_std(&self, speed_std_m_per_s: &[f64]) -> f64 {
        let var: f64 = speed_std_m_per_s
            .iter()
            .zip(&self.direction)
            .take(NX / 2)
            .map(|(s, d)| d * d * s * s)
            .sum();
        libm::sqrt(var)
    }

    /// The dither's relative authority with each capsule's drag scaled by
    /// its factor `scales[i][1]` (the learned [gain, drag] factors; 1 = the
    /// drags it was built from) against the model's: 1 on the model, less
    /// where the differential drag is smaller.
    pub fn drag_authority(&self, scales: &[[f64; 2]]) -> f64 {
        self.drag_share
            .iter()
            .zip(scales)
            .take(NX / 2)
            .map(|(share, f)| share * f[1])
            .sum::<f64>()
            .max(0.0)
    }

    /// Forgets the learned bias (new target or new start).
    pub fn forget(&mut self) {
        self.integral = 0.0;
        self.start();
    }

    /// Starts a pattern from rest (hold entry).
    pub fn start(&mut self) {
        self.phase = 0;
        self.amplitude_m_per_s = 0.0;
        self.velocity_m_per_s = 0.0;
        self.displacement_m = 0.0;
        self.rate = f64::NAN;
        self.held_s = 0.0;
    }

    /// Time since the hold was entered, s.
    pub fn held_s(&self) -> f64 {
        self.held_s
    }

    /// The dither's common (displacement m, velocity m/s) now, the
    /// displacement about the pattern's mean position: the centre law
    /// holds the group about this point, so the wobble is centred on the
    /// target.
    pub fn common(&self, dt_s: f64, gap_s: f64) -> (f64, f64) {
        let mean_m = self.amplitude_m_per_s * pattern_mean_position_s(dt_s, gap_s);
        (self.displacement_m - mean_m, self.velocity_m_per_s)
    }

    /// One actuation sample of `dt_s` followed by a zero-gradient gap of
    /// `gap_s`, from the error `e` (relative to the target): the common
    /// acceleration the dither asks for during the sample, m/s^2. A new
    /// pattern's amplitude is at most `speed_room_m_per_s`, the speed the
    /// capsules' other motion leaves free, so that the sum stays inside the
    /// band's speed. Its wobble is not limited by the capsules' distance
    /// to the band's edge: a pattern limited so stopped when the relative
    /// drift had taken them near the edge, and the drift then took them
    /// out (docs/decisions.md).
    pub fn next_acceleration(
        &mut self,
        e: &[f64; NX],
        dt_s: f64,
        gap_s: f64,
        speed_room_m_per_s: f64,
    ) -> f64 {
        self.held_s += dt_s + gap_s;
        let (mut xi, mut xi_rate) = (0.0, 0.0);
        for i in 0..NX / 2 {
            xi += self.direction[i] * e[2 * i];
            xi_rate += self.direction[i] * e[2 * i + 1];
        }
        if self.direction.iter().all(|&d| d == 0.0) {
            return 0.0;
        }
        let period_s = dt_s + gap_s;
        let a = period_s / (STATION_RATE_FILTER_S + period_s);
        self.rate = if self.rate.is_nan() {
            xi_rate
        } else {
            self.rate + a * (xi_rate - self.rate)
        };
        let kappa = pattern_drag_gain(dt_s, gap_s);
        let max_speed = if NX / 2 <= 2 {
            STATION_MAX_SPEED_M_PER_S
        } else {
            STATION_JUDGED_SPEED_M_PER_S
        };
        let limit = kappa * max_speed * max_speed;
        // xi'' = -mean(v|v|) + bias: three poles at -w.
        let w = STATION_BANDWIDTH_RAD_PER_S;
        let pd = 3.0 * w * w * xi + 3.0 * w * self.rate;
        let wanted = pd + w * w * w * self.integral;
        // Integrate unless saturated the same way (anti-windup), and never
        // beyond what the dither can hold.
        if wanted.abs() < limit || wanted.signum() != xi.signum() {
            self.integral += xi * period_s;
        }
        let cap = limit / (w * w * w);
        self.integral = self.integral.clamp(-cap, cap);
        if self.phase == 0 {
            let wanted = pd + w * w * w * self.integral;
            let speed = if kappa > 0.0 {
                libm::sqrt(wanted.abs().min(limit) / kappa)
            } else {
                0.0
            };
            let speed = speed.min(speed_room_m_per_s.max(0.0));
            // Faster than the judged speed only away from the band's edge:
            // the faster pattern's wider wobble would carry a capsule there
            // out.
            let near_edge = (0..NX / 2).any(|i| libm::fabs(e[2 * i]) > STATION_FAST_WITHIN_M);
            let speed = if near_edge {
                speed.min(STATION_JUDGED_SPEED_M_PER_S)
            } else {
                speed
            };
            self.amplitude_m_per_s = speed.copysign(wanted);
        }
        let next = STATION_PATTERN[self.phase] * self.amplitude_m_per_s;
        let accel = (next - self.velocity_m_per_s) / dt_s;
        self.displacement_m += 0.5 * dt_s * (self.velocity_m_per_s + next) + gap_s * next;
        self.velocity_m_per_s = next;
        self.phase = (self.phase + 1) % STATION_PATTERN.len();
        if self.phase == 0 {
            // The pattern returns to its start; drop rounding.
            self.displacement_m = 0.0;
        }
        accel
    }
}

/// Positions of [`STATION_PATTERN`] at unit amplitude at its sample
/// instants (the start of each actuation sample), s (m per m/s).
fn pattern_positions_s(dt_s: f64, gap_s: f64) -> [f64; STATION_PATTERN.len()] {
    let n = STATION_PATTERN.len();
    let mut out = [0.0; STATION_PATTERN.len()];
    let mut x = 0.0;
    for (k, o) in out.iter_mut().enumerate() {
        *o = x;
        let (a, b) = (STATION_PATTERN[(k + n - 1) % n], STATION_PATTERN[k]);
        x += 0.5 * dt_s * (a + b) + gap_s * b;
    }
    out
}

/// Mean position of [`STATION_PATTERN`] at unit amplitude, s (m per m/s).
pub fn pattern_mean_position_s(dt_s: f64, gap_s: f64) -> f64 {
    let p = pattern_positions_s(dt_s, gap_s);
    p.iter().sum::<f64>() / p.len() as f64
}

/// `mean(v|v|) / V^2` of [`STATION_PATTERN`] at unit amplitude: linear
/// ramps over each actuation sample of `dt_s`, constant over each gap of
/// `gap_s`.
pub fn pattern_drag_gain(dt_s: f64, gap_s: f64) -> f64 {
    // Antiderivative of v|v|.
    let h = |v: f64| libm::fabs(v) * v * v / 3.0;
    let n = STATION_PATTERN.len();
    let mut sum = 0.0;
    for k in 0..n {
        let (a, b) = (STATION_PATTERN[(k + n - 1) % n], STATION_PATTERN[k]);
        let ramp = if a == b {
            a * libm::fabs(a)
        } else {
            (h(b) - h(a)) / (b - a)
        };
        sum += dt_s * ramp + gap_s * b * libm::fabs(b);
    }
    let total_s = n as f64 * (dt_s + gap_s);
    if total_s > 0.0 {
        sum / total_s
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pattern returns to its start for any gap, and is fast the way
    /// its amplitude points.
    #[test]
    fn pattern_has_zero_displacement_and_positive_drag_gain() {
        for (dt, gap) in [(0.02, 0.0), (0.02, 0.02), (0.02, 0.05)] {
            let n = STATION_PATTERN.len();
            let mut x = 0.0;
            for k in 0..n {
                let (a, b) = (STATION_PATTERN[(k + n - 1) % n], STATION_PATTERN[k]);
                x += 0.5 * dt * (a + b) + gap * b;
            }
            assert!(x.abs() < 1e-15, "displacement {x}");
            let kappa = pattern_drag_gain(dt, gap);
            assert!(kappa > 0.09 && kappa < 0.172, "kappa {kappa}");
        }
    }

    /// Capsules whose gains differ: the motion one gradient makes (speeds
    /// in the gains' ratio, here the dither's own 3 mm/s) is no relative
    /// motion once the keeper is told the gains, and it is one to the
    /// drag direction alone.
    #[test]
    fn the_relative_coordinate_is_taken_across_the_gains() {
        let (g1, g2) = (173.2 * 1.15, 173.2 * 0.85);
        let mut s = StationKeeper::<4>::new(&[134.7, 16.8]);
        // Both capsules 0.1 mm and 3 mm/s per unit gain along one gradient.
        let along = [
            0.1e-3 * g1 / 173.2,
            3e-3 * g1 / 173.2,
            0.1e-3 * g2 / 173.2,
            3e-3 * g2 / 173.2,
        ];
        assert!(!s.can_stop(&along, 0.02, 0.0, 2.0e-3, 1.0, 0.0));
        s.set_gains(Some(&[g1, g2]));
        assert!(s.along_direction(&[along[0], along[2]]).abs() < 1e-15);
        assert!(s.can_stop(&along, 0.02, 0.0, 2.0e-3, 1.0, 0.0));
        // A relative motion still counts.
        let apart = [0.0, 1.0e-3, 0.0, -1.0e-3];
        assert!(!s.can_stop(&apart, 0.02, 0.0, 2.0e-3, 1.0, 0.0));
        // Equal gains: the drag direction as it was.
        let before = StationKeeper::<4>::new(&[134.7, 16.8]);
        s.set_gains(Some(&[173.2, 173.2]));
        let (now, was) = (
            s.along_direction(&[1e-3, -1e-3]),
            before.along_direction(&[1e-3, -1e-3]),
        );
        assert!((now - was).abs() < 1e-12 * was.abs(), "{now} vs {was}");
        s.set_gains(None);
        assert_eq!(
            s.along_direction(&[1e-3, -1e-3]),
            before.along_direction(&[1e-3, -1e-3])
        );
    }

    /// The learned drag factors scale the dither's authority: 1 on the
    /// model, the differential drag's share off it.
    #[test]
    fn drag_authority_is_the_differential_drag_against_the_model() {
        let drag = [134.7, 16.8];
        let s = StationKeeper::<4>::new(&drag);
        assert!((s.drag_authority(&[[1.0, 1.0], [1.0, 1.0]]) - 1.0).abs() < 1e-12);
        assert!((s.drag_authority(&[[1.0, 0.8], [1.0, 0.8]]) - 0.8).abs() < 1e-12);
        // Only the large drag lower: the difference shrinks by 0.8 x 134.7 / 117.9.
        let scaled = s.drag_authority(&[[1.0, 0.8], [1.0, 1.0]]);
        assert!((scaled - (0.8 * 134.7 - 16.8) / (134.7 - 16.8)).abs() < 1e-12);
        // A weaker authority stops the same relative speed farther out.
        let state = [0.0, 0.25e-3, 0.0, -0.25e-3];
        assert!(s.can_stop(&state, 0.02, 0.0, 2.0e-3, 1.0, 0.0));
        assert!(!s.can_stop(&state, 0.02, 0.0, 2.0e-3, 0.5, 0.0));
    }

    /// The hold's entry test: with the default capsules' drag (a =
    /// kappa * 118 1/m * (3 mm/s)^2, about 1.2e-4 m/s^2 at ideal sampling)
    /// a relative speed stops within w^2 / (2 a): 0.3 mm/s at q = 0 stops
    /// within 2 mm, 1 mm/s does not; the stopping point counts the side
    /// the capsules move to (converging at 1 mm/s from 1.5 mm apart stops
    /// 2.8 mm past zero; diverging at 0.4 mm/s from 1.5 mm, at 2.2 mm);
    /// without differential drag the test never refuses.
    #[test]
    fn can_stop_is_the_stopping_point_of_the_relative_motion() {
        let s = StationKeeper::<4>::new(&[134.7, 16.8]);
        let (dt, gap, spread) = (0.02, 0.0, 2.0e-3);
        let state = |q: f64, w: f64| [0.5 * q, 0.5 * w, -0.5 * q, -0.5 * w];
        assert!(s.can_stop(&state(0.0, 0.3e-3), dt, gap, spread, 1.0, 0.0));
        assert!(s.can_stop(&state(0.0, -0.3e-3), dt, gap, spread, 1.0, 0.0));
        assert!(!s.can_stop(&state(0.0, 1.0e-3), dt, gap, spread, 1.0, 0.0));
        // Each capsule's speed known to 0.4 mm/s: the 1 mm/s relative rate
        // may be 0.3 mm/s or less, which stops; known to 0.01 mm/s it
        // does not.
        let loose = s.rate_std(&[0.4e-3, 0.4e-3]);
        let tight = s.rate_std(&[0.01e-3, 0.01e-3]);
        assert!(s.can_stop(&state(0.0, 1.0e-3), dt, gap, spread, 1.0, loose));
        assert!(!s.can_stop(&state(0.0, 1.0e-3), dt, gap, spread, 1.0, tight));
        let a = pattern_drag_gain(dt, gap)
            * (134.7 - 16.8)
            * STATION_JUDGED_SPEED_M_PER_S
            * STATION_JUDGED_SPEED_M_PER_S;
        let w_max = libm::sqrt(2.0 * a * spread);
        assert!(s.can_stop(&state(0.0, 0.99 * w_max), dt, gap, spread, 1.0, 0.0));
        assert!(!s.can_stop(&state(0.0, 1.01 * w_max), dt, gap, spread, 1.0, 0.0));
        // Converging: from +1.5 mm at -0.6 mm/s the stopping point is
        // 1.5 - 0.36e-6 / (2 a) mm, inside; at -1 mm/s it is beyond -2 mm.
        assert!(s.can_stop(&state(1.5e-3, -0.6e-3), dt, gap, spread, 1.0, 0.0));
        assert!(!s.can_stop(&state(1.5e-3, -1.0e-3), dt, gap, spread, 1.0, 0.0));
        // Diverging: 0.4 mm/s, which converging would stop inside, is
        // refused.
        assert!(s.can_stop(&state(1.5e-3, -0.4e-3), dt, gap, spread, 1.0, 0.0));
        assert!(!s.can_stop(&state(1.5e-3, 0.4e-3), dt, gap, spread, 1.0, 0.0));
        let same = StationKeeper::<4>::new(&[50.0, 50.0]);
        assert!(same.can_stop(&state(1.5e-3, 5.0e-3), dt, gap, spread, 1.0, 0.0));
    }

    /// A relative error the dither cannot hold at its judged speed asks
    /// for more: played while every capsule is well inside the band,
    /// capped at the judged speed once one is near its edge.
    #[test]
    fn plays_faster_than_judged_only_away_from_the_band_edge() {
        let amplitude = |e: [f64; 4]| {
            let mut s = StationKeeper::<4>::new(&[134.7, 16.8]);
            s.next_acceleration(&e, 0.02, 0.02, 1.0);
            s.amplitude_m_per_s.abs()
        };
        let inside = amplitude([0.6e-3, 2.0e-3, -0.6e-3, -2.0e-3]);
        assert!(inside > STATION_JUDGED_SPEED_M_PER_S + 1e-4, "{inside}");
        assert!(inside <= STATION_MAX_SPEED_M_PER_S + 1e-12);
        let edge = amplitude([0.8e-3, 2.0e-3, -0.6e-3, -2.0e-3]);
        assert!(
            (edge - STATION_JUDGED_SPEED_M_PER_S).abs() < 1e-12,
            "{edge}"
        );
        // Three capsules play at the judged speed wherever they are.
        let mut three = StationKeeper::<6>::new(&[134.7, 16.8, 60.0]);
        let e = [0.6e-3, 2.0e-3, -0.6e-3, -2.0e-3, 0.0, 0.0];
        three.next_acceleration(&e, 0.02, 0.02, 1.0);
        assert!(three.amplitude_m_per_s.abs() > 0.0);
        assert!(three.amplitude_m_per_s.abs() <= STATION_JUDGED_SPEED_M_PER_S + 1e-12);
    }

    /// Two capsules, the first with more drag: a relative error with the
    /// first ahead asks for the fast phase forward (more drag on it, so it
    /// falls back), and the dither's displacement returns to zero.
    #[test]
    fn relative_error_sets_the_asymmetry() {
        let mut s = StationKeeper::<4>::new(&[134.7, 16.8]);
        let e = [0.5e-3, 0.0, -0.5e-3, 0.0];
        let mut v_abs_v = 0.0;
        let mut v_max: f64 = 0.0;
        for _ in 0..STATION_PATTERN.len() {
            let v0 = s.common(0.02, 0.02).1;
            s.next_acceleration(&e, 0.02, 0.02, 1.0);
            let v1 = s.common(0.02, 0.02).1;
            v_abs_v += v1 * v1.abs() + v0 * v0.abs();
            v_max = v_max.max(v1.abs());
        }
        assert!(v_abs_v > 0.0);
        assert!(v_max <= STATION_MAX_SPEED_M_PER_S + 1e-12);
        assert!(s.displacement_m.abs() < 1e-15);
        let mut same = StationKeeper::<4>::new(&[16.8, 16.8]);
        assert_eq!(same.next_acceleration(&e, 0.02, 0.02, 1.0), 0.0);
    }
}
