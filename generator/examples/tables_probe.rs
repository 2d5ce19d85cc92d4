use capsule_mpc_generator::{config::Config, tables::*};
fn main() {
    let mut cfg = Config::embedded_default();
    cfg.controller.q = vec![0.02, 0.0001, 0.02, 0.0001];
    cfg.controller.p = vec![1000.0, 10.0, 1000.0, 10.0];
    cfg.grid.position_step_m = std::env::args().nth(1).unwrap().parse().unwrap();
    cfg.grid.starts = 12;
    cfg.grid.sqp_iterations = 40;
    let t = std::time::Instant::now();
    let tables = build_tables(&cfg, &Silent);
    println!(
        "time {:?} plans {} reached {} index {} bytes {}",
        t.elapsed(),
        tables.plans.len(),
        tables.reached_count(),
        tables.index.len(),
        tables.to_bytes().len()
    );
    for p in &tables.plans {
        print!("{}", if p.reached { '#' } else { '.' });
        if (p.e0[2] - tables.plan_axis.value(tables.plan_axis.count - 1)).abs() < 1e-9 {
            println!();
        }
    }
}
