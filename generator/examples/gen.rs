use capsule_mpc_generator::{config::Config, generate::*, tables::Silent};
fn main() {
    let cfg = Config::embedded_default();
    let t = std::time::Instant::now();
    let files = generate(&cfg, &Silent).unwrap();
    eprintln!(
        "generated in {:?}; reached {}/{}",
        t.elapsed(),
        files.tables.reached_count(),
        files.tables.plans.len()
    );
    write_atomically(std::path::Path::new("generated"), &files).unwrap();
}
