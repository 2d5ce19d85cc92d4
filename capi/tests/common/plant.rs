//! The host's own plant for the C ABI tests: capsules under quadratic drag
//! and one gradient (x'' = -b v|v| + g u), integrated with 1 ms RK4 steps,
//! written independently of the library's model. The two Table I capsules
//! (g_i and b_i as in NOTES.md) unless a test gives its own.

/// Magnetic acceleration per gradient, (m/s^2)/(T/m).
pub const G: [f64; 2] = [173.25, 173.25];
/// Quadratic drag coefficients, 1/m.
pub const B: [f64; 2] = [134.7, 16.84];
/// Integration step, s.
pub const STEP_S: f64 = 1e-3;

fn deriv<const NX: usize>(s: &[f64; NX], u: f64, g: &[f64], b: &[f64]) -> [f64; NX] {
    let mut d = [0.0; NX];
    for i in 0..NX / 2 {
        let v = s[2 * i + 1];
        d[2 * i] = v;
        d[2 * i + 1] = -b[i] * v * v.abs() + g[i] * u;
    }
    d
}

/// One RK4 step of `h` seconds at gradient `u` for capsules with gains
/// `g` and drags `b`.
fn rk4_of<const NX: usize>(s: &mut [f64; NX], u: f64, h: f64, g: &[f64], b: &[f64]) {
    let add = |a: &[f64; NX], k: &[f64; NX], c: f64| {
        std::array::from_fn::<f64, NX, _>(|j| a[j] + c * k[j])
    };
    let k1 = deriv(s, u, g, b);
    let k2 = deriv(&add(s, &k1, h / 2.0), u, g, b);
    let k3 = deriv(&add(s, &k2, h / 2.0), u, g, b);
    let k4 = deriv(&add(s, &k3, h), u, g, b);
    for j in 0..NX {
        s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
}

/// Holds `u` for `duration_s` in `STEP_S` RK4 steps, capsules `g`, `b`.
pub fn hold_capsules_for<const NX: usize>(
    s: &mut [f64; NX],
    u: f64,
    duration_s: f64,
    g: &[f64],
    b: &[f64],
) {
    let steps = (duration_s / STEP_S).round() as usize;
    for _ in 0..steps {
        rk4_of(s, u, STEP_S, g, b);
    }
}

/// Holds `u` for `duration_s` on the two Table I capsules.
pub fn hold_for(s: &mut [f64; 4], u: f64, duration_s: f64) {
    hold_capsules_for(s, u, duration_s, &G, &B);
}
