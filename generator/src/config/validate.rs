//! The range check of every config value: [`Config::validate`] names the
//! offending field and its allowed range, so a typo in a capsule radius or
//! a weight count is refused before any table is built.

use super::*;

impl Config {
    /// Checks every value; the error names the field and its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let m = self.capsule.len();
        if m == 0 || m > MAX_CAPSULES {
            return Err(invalid(
                "capsule",
                format!("{m} capsules given; between 1 and {MAX_CAPSULES} are allowed"),
            ));
        }
        for (i, c) in self.capsule.iter().enumerate() {
            let f = |name: &str| format!("capsule[{i}].{name}");
            check_range(&f("sphere_radius_m"), c.sphere_radius_m, 0.0, true, 0.05)?;
            check_range(&f("capsule_radius_m"), c.capsule_radius_m, 0.0, true, 0.05)?;
            if c.capsule_radius_m < c.sphere_radius_m {
                return Err(invalid(
                    f("capsule_radius_m"),
                    format!(
                        "{} m is smaller than the sphere it holds (sphere_radius_m = {} m)",
                        c.capsule_radius_m, c.sphere_radius_m
                    ),
                ));
            }
            check_range(
                &f("sphere_density_kg_per_m3"),
                c.sphere_density_kg_per_m3,
                0.0,
                true,
                1e5,
            )?;
            check_range(
                &f("saturation_magnetization_a_per_m"),
                c.saturation_magnetization_a_per_m,
                0.0,
                true,
                1e7,
            )?;
            check_range(&f("shell_mass_kg"), c.shell_mass_kg, 0.0, false, 1.0)?;
            if let Some(g) = c.gain_m_per_s2_per_t_per_m {
                check_range(&f("gain_m_per_s2_per_t_per_m"), g, 0.0, true, 1e5)?;
            }
            if let Some(b) = c.drag_per_m {
                check_range(&f("drag_per_m"), b, 0.0, true, 1e5)?;
            }
        }
        check_range(
            "fluid.density_kg_per_m3",
            self.fluid.density_kg_per_m3,
            0.0,
            true,
            1e5,
        )?;
        check_range(
            "fluid.dynamic_viscosity_pa_s",
            self.fluid.dynamic_viscosity_pa_s,
            0.0,
            true,
            1e3,
        )?;
        check_range(
            "drag.drag_coefficient",
            self.drag.drag_coefficient,
            0.0,
            true,
            100.0,
        )?;

        let s = &self.scanner;
        check_range(
            "scanner.max_gradient_t_per_m",
            s.max_gradient_t_per_m,
            0.0,
            true,
            1.0,
        )?;
        check_range("scanner.tracking_time_s", s.tracking_time_s, 0.0, true, 1.0)?;
        check_range("scanner.extra_delay_s", s.extra_delay_s, 0.0, false, 1.0)?;
        if let Some(slew) = s.slew_rate_t_per_m_per_s {
            check_range("scanner.slew_rate_t_per_m_per_s", slew, 0.0, true, 1e6)?;
        }
        if let Some(raster) = s.gradient_raster_s {
            check_range("scanner.gradient_raster_s", raster, 0.0, true, 1e-3)?;
        }
        if let Some(rf) = s.tracking_rf_duration_s {
            check_range("scanner.tracking_rf_duration_s", rf, 0.0, true, 0.1)?;
        }
        if let Some(adc) = s.tracking_adc_duration_s {
            check_range("scanner.tracking_adc_duration_s", adc, 0.0, true, 0.1)?;
        }
        if s.tracking_rf_duration_s.is_some() || s.tracking_adc_duration_s.is_some() {
            // The placeholder tracking event (RF, then ADC) must fit in the
            // tracking phase; the Pulseq writer also checks its fixed gaps.
            let (rf, adc) = (
                s.tracking_rf_duration_or_default_s(),
                s.tracking_adc_duration_or_default_s(),
            );
            if rf + adc >= s.tracking_time_s {
                let field = if s.tracking_adc_duration_s.is_some() {
                    "scanner.tracking_adc_duration_s"
                } else {
                    "scanner.tracking_rf_duration_s"
                };
                return Err(invalid(
                    field,
                    format!(
                        "the placeholder tracking RF ({rf} s) and ADC ({adc} s) together must be shorter than scanner.tracking_time_s ({} s)",
                        s.tracking_time_s
                    ),
                ));
            }
        }

        let c = &self.controller;
        check_range("controller.sample_time_s", c.sample_time_s, 0.0, true, 1.0)?;
        if !(1..=64).contains(&c.horizon_steps) {
            return Err(invalid(
                "controller.horizon_steps",
                format!("{} is outside the allowed range [1, 64]", c.horizon_steps),
            ));
        }
        if c.plan_steps < c.horizon_steps || c.plan_steps > 400 {
            return Err(invalid(
                "controller.plan_steps",
                format!(
                    "{} must be in [horizon_steps = {}, 400]",
                    c.plan_steps, c.horizon_steps
                ),
            ));
        }
        if !(1..=100).contains(&c.rk4_substeps) {
            return Err(invalid(
                "controller.rk4_substeps",
                format!("{} is outside the allowed range [1, 100]", c.rk4_substeps),
            ));
        }
        if !(1..=50).contains(&c.sqp_iterations) {
            return Err(invalid(
                "controller.sqp_iterations",
                format!("{} is outside the allowed range [1, 50]", c.sqp_iterations),
            ));
        }
        for (name, weights) in [("controller.q", &c.q), ("controller.p", &c.p)] {
            if weights.len() != 2 * m {
                return Err(invalid(
                    name,
                    format!(
                        "has {} entries; 2 x capsules = {} are needed",
                        weights.len(),
                        2 * m
                    ),
                ));
            }
            for (k, w) in weights.iter().enumerate() {
                check_range(&format!("{name}[{k}]"), *w, 0.0, false, 1e12)?;
            }
        }
        check_range("controller.r", c.r, 0.0, true, 1e12)?;
        check_range(
            "controller.position_bound_m",
            c.position_bound_m,
            0.0,
            true,
            10.0,
        )?;
        check_range(
            "controller.speed_bound_m_per_s",
            c.speed_bound_m_per_s,
            0.0,
            true,
            100.0,
        )?;
        check_range(
            "controller.switching_sigma",
            c.switching_sigma,
            0.0,
            true,
            1.0,
        )?;
        if c.switching_sigma >= 1.0 {
            return Err(invalid(
                "controller.switching_sigma",
                "must be < 1 (condition 18)",
            ));
        }

        let g = &self.grid;
        check_range(
            "grid.position_range_m",
            g.position_range_m,
            0.0,
            true,
            c.position_bound_m,
        )?;
        check_range(
            "grid.position_step_m",
            g.position_step_m,
            0.0,
            true,
            g.position_range_m,
        )?;
        if 2.0 * g.position_range_m / g.position_step_m > 200.0 {
            return Err(invalid(
                "grid.position_step_m",
                "gives more than 201 points per axis; use a larger step",
            ));
        }
        check_range(
            "grid.fine_range_m",
            g.fine_range_m(),
            0.0,
            true,
            g.position_range_m,
        )?;
        check_range(
            "grid.fine_step_m",
            g.fine_step_m(),
            0.0,
            true,
            g.fine_range_m(),
        )?;
        if 2.0 * g.fine_range_m() / g.fine_step_m() > 40.0 {
            return Err(invalid(
                "grid.fine_step_m",
                "gives more than 41 fine points per axis; use a larger step",
            ));
        }
        if !(1..=256).contains(&g.starts) {
            return Err(invalid(
                "grid.starts",
                format!("{} is outside [1, 256]", g.starts),
            ));
        }
        if !(1..=500).contains(&g.sqp_iterations) {
            return Err(invalid(
                "grid.sqp_iterations",
                format!("{} is outside [1, 500]", g.sqp_iterations),
            ));
        }

        let w = &self.workspace;
        check_range(
            "workspace.position_min_m",
            w.position_min_m,
            -0.5,
            false,
            0.5,
        )?;
        check_range(
            "workspace.position_max_m",
            w.position_max_m,
            -0.5,
            false,
            0.5,
        )?;
        if w.position_max_m <= w.position_min_m {
            return Err(invalid(
                "workspace.position_max_m",
                format!(
                    "{} must exceed workspace.position_min_m = {}",
                    w.position_max_m, w.position_min_m
                ),
            ));
        }
        if w.span_m() / g.position_step_m > 400.0 {
            return Err(invalid(
                "workspace.position_max_m",
                "the workspace spans more than 400 grid steps; use a larger grid.position_step_m",
            ));
        }

        check_range("disturbance.bound", self.disturbance.bound, 0.0, false, 1e3)?;
        check_range(
            "measurement.position_noise_m",
            self.measurement.position_noise_m,
            0.0,
            false,
            0.1,
        )?;
        Ok(())
    }
}

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        field: field.into(),
        reason: reason.into(),
    }
}

/// `value` must be finite and in `[lo, hi]` (with `lo_open` making it `(lo, hi]`).
fn check_range(
    field: &str,
    value: f64,
    lo: f64,
    lo_open: bool,
    hi: f64,
) -> Result<(), ConfigError> {
    let lower_ok = if lo_open { value > lo } else { value >= lo };
    if !value.is_finite() || !lower_ok || value > hi {
        let open = if lo_open { "(" } else { "[" };
        return Err(invalid(
            field,
            format!("{value} is outside the allowed range {open}{lo:e}, {hi:e}]"),
        ));
    }
    Ok(())
}
