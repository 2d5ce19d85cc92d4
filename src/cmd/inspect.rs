//! `capsule-mpc inspect`: the constants the model derives from a config, so a
//! user can check a config before spending minutes generating tables.

use crate::cli::{load_config, InspectArgs};
use anyhow::Result;
use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::model::Model;
use capsule_mpc_sim::report::B_REFERENCE_SPEED_M_PER_S;
use serde::Serialize;
use std::fmt::Write as _;
use std::io::Write;

/// Derived constants of one capsule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CapsuleSummary {
    pub name: String,
    /// Magnetic acceleration per gradient, m/s^2 per T/m.
    pub g: f64,
    /// Quadratic drag coefficient, 1/m (effective at 0.1 m/s for the
    /// sphere-correlation law).
    pub b: f64,
    pub mass_kg: f64,
    /// Terminal speed under the full gradient u_max, m/s.
    pub terminal_speed_m_per_s: f64,
    pub reynolds_at_terminal_speed: f64,
}

/// Everything `inspect` prints (the `--json` object).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InspectReport {
    pub capsules: Vec<CapsuleSummary>,
    pub g: Vec<f64>,
    pub b: Vec<f64>,
    /// L_f of the switching rule on |v| <= controller.speed_bound_m_per_s.
    pub lipschitz_f: f64,
    pub config: Config,
}

impl InspectReport {
    pub fn from_config(config: &Config) -> InspectReport {
        let model = Model::from_config(config);
        let u_max = model.u_max_t_per_m;
        let capsules: Vec<CapsuleSummary> = model
            .capsules
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let name = config
                    .capsule
                    .get(i)
                    .map(|cc| cc.name.clone())
                    .filter(|n| !n.is_empty())
                    .unwrap_or_else(|| format!("capsule{}", i + 1));
                let terminal = model.terminal_speed_m_per_s(i, u_max);
                CapsuleSummary {
                    name,
                    g: c.g,
                    b: c.drag.effective_b_per_m(B_REFERENCE_SPEED_M_PER_S),
                    mass_kg: c.mass_kg,
                    terminal_speed_m_per_s: terminal,
                    reynolds_at_terminal_speed: model.reynolds(i, terminal),
                }
            })
            .collect();
        InspectReport {
            g: capsules.iter().map(|c| c.g).collect(),
            b: capsules.iter().map(|c| c.b).collect(),
            lipschitz_f: model.lipschitz_f(config.controller.speed_bound_m_per_s),
            capsules,
            config: config.clone(),
        }
    }

    /// A human-readable table.
    pub fn render_text(&self) -> String {
        let mut s = String::new();
        let c = &self.config;
        let _ = writeln!(
            s,
            "drag law {:?}, u_max {} T/m, sample {} s, tracking {} s",
            c.drag.law,
            c.scanner.max_gradient_t_per_m,
            c.controller.sample_time_s,
            c.scanner.tracking_time_s
        );
        let _ = writeln!(
            s,
            "{:<12} {:>12} {:>10} {:>12} {:>16} {:>12}",
            "capsule", "g (m/s2/T/m)", "b (1/m)", "mass (kg)", "v_term (m/s)", "Re at v_term"
        );
        for k in &self.capsules {
            let _ = writeln!(
                s,
                "{:<12} {:>12.3} {:>10.3} {:>12.4e} {:>16.4} {:>12.0}",
                k.name, k.g, k.b, k.mass_kg, k.terminal_speed_m_per_s, k.reynolds_at_terminal_speed
            );
        }
        let _ = writeln!(
            s,
            "L_f = {:.3} (on |v| <= {} m/s)",
            self.lipschitz_f, c.controller.speed_bound_m_per_s
        );
        match toml::to_string(&self.config) {
            Ok(text) => {
                let _ = write!(s, "\nconfig as understood:\n{text}");
            }
            Err(e) => {
                let _ = writeln!(s, "\n(config could not be shown as TOML: {e})");
            }
        }
        s
    }
}

/// Runs `inspect`, printing to `out`.
pub fn run(args: &InspectArgs, out: &mut dyn Write) -> Result<()> {
    let config = load_config(args.config.as_deref())?;
    let report = InspectReport::from_config(&config);
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &report)?;
        writeln!(out)?;
    } else {
        write!(out, "{}", report.render_text())?;
    }
    out.flush()?;
    Ok(())
}
