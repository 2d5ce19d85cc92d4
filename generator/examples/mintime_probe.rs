use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::mintime::*;
use capsule_mpc_generator::model::Model;
use capsule_mpc_generator::ocp::Ocp;
use capsule_mpc_generator::tables::{Axis, Silent};
use std::time::Instant;

fn main() {
    let config = Config::embedded_default();
    let model = Model::from_config(&config);
    let steps: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(75);
    let range: f64 = std::env::args()
        .nth(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.04);
    let coast: f64 = std::env::args()
        .nth(3)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.0);
    let mut ocp = Ocp::from_config(&model, &config, steps);
    ocp.coast_s = coast;
    let axis = Axis::symmetric(range, 0.005);
    let t = Instant::now();
    let plans = grid_min_time_plans(&ocp, &axis, steps, 12, 40, &Silent);
    println!(
        "{} points in {:.1}s",
        plans.len(),
        t.elapsed().as_secs_f64()
    );
    let n = axis.count;
    for i in 0..n {
        let mut line = String::new();
        for j in 0..n {
            let p = &plans[i * n + j];
            line += &match p {
                Some(p) => format!("{:4}", p.samples),
                None => "   -".into(),
            };
        }
        println!("{line}");
    }
}
