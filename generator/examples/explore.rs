use capsule_mpc_generator::{config::Config, model::Model, ocp::Ocp};
use rand::{Rng, SeedableRng};
fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().unwrap())
        .collect();
    let mut cfg = Config::embedded_default();
    let k = args[2] as usize;
    cfg.controller.q = vec![args[3], args[4], args[3], args[4]];
    cfg.controller.p = vec![args[5], args[6], args[5], args[6]];
    let model = Model::from_config(&cfg);
    let ocp = Ocp::from_config(&model, &cfg, k);
    let e0 = vec![-args[0], 0.0, -args[1], 0.0];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let t = std::time::Instant::now();
    let mut best: Option<capsule_mpc_generator::ocp::Plan> = None;
    for s in 0..args[7] as usize {
        let mut u = vec![0.0; k];
        let mut i = 0;
        while i < k {
            let len = rng.gen_range(2..12);
            let lvl = rng.gen_range(-1.0..1.0) * 0.04;
            for j in i..(i + len).min(k) {
                u[j] = lvl;
            }
            i += len;
        }
        let p = ocp.solve(&e0, &u, 60);
        println!(
            "start {s}: cost {:.5} final err {:.2} mm it {}",
            p.cost,
            p.final_position_error_m() * 1e3,
            p.iterations
        );
        if best.as_ref().map_or(true, |b| p.cost < b.cost) {
            best = Some(p);
        }
    }
    let b = best.unwrap();
    println!(
        "time {:?}; best cost {:.5} final {:?}",
        t.elapsed(),
        b.cost,
        b.states.last()
    );
    for (k, (u, s)) in b.u.iter().zip(&b.states).enumerate() {
        if k % 5 == 0 {
            println!(
                "{k:3} u={:+.4} e={:?}",
                u,
                s.iter()
                    .map(|v| (v * 1000.0).round() / 1000.0 * 100.0)
                    .collect::<Vec<_>>()
            );
        }
    }
}
