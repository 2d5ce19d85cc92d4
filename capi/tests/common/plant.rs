//! The host's own plant for the C ABI tests: the two Table I capsules
//! (g_i and b_i as in NOTES.md), integrated with 1 ms RK4 steps, written
//! independently of the library's model.

/// Magnetic acceleration per gradient, (m/s^2)/(T/m).
pub const G: [f64; 2] = [173.25, 173.25];
/// Quadratic drag coefficients, 1/m.
pub const B: [f64; 2] = [134.7, 16.84];
/// Integration step, s.
pub const STEP_S: f64 = 1e-3;

fn deriv(s: &[f64; 4], u: f64) -> [f64; 4] {
    let mut d = [0.0; 4];
    for i in 0..2 {
        let v = s[2 * i + 1];
        d[2 * i] = v;
        d[2 * i + 1] = -B[i] * v * v.abs() + G[i] * u;
    }
    d
}

/// One RK4 step of `h` seconds at gradient `u`.
pub fn rk4(s: &mut [f64; 4], u: f64, h: f64) {
    let add =
        |a: &[f64; 4], k: &[f64; 4], c: f64| std::array::from_fn::<f64, 4, _>(|j| a[j] + c * k[j]);
    let k1 = deriv(s, u);
    let k2 = deriv(&add(s, &k1, h / 2.0), u);
    let k3 = deriv(&add(s, &k2, h / 2.0), u);
    let k4 = deriv(&add(s, &k3, h), u);
    for j in 0..4 {
        s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
}

/// Holds `u` for `duration_s` in `STEP_S` RK4 steps.
pub fn hold_for(s: &mut [f64; 4], u: f64, duration_s: f64) {
    let steps = (duration_s / STEP_S).round() as usize;
    for _ in 0..steps {
        rk4(s, u, STEP_S);
    }
}
