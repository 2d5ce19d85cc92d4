//! The committed `generated/` crate is exactly what the generator emits
//! (like prost-build's committed output), and regenerating for new capsule
//! parameters gives a controller that works.

use capsule_mpc_generator::config::Config;
use capsule_mpc_generator::generate::{
    differences, emit_module_files, generate, write_atomically, ControllerModule,
};
use capsule_mpc_generator::table_file;
use capsule_mpc_generator::tables::{Silent, TableError};
use std::path::Path;
use std::process::Command;

/// Copies `entries` (files or folders, recursively) of `from` into `to`.
fn copy_tree(from: &Path, to: &Path, entries: &[&str]) {
    std::fs::create_dir_all(to).unwrap();
    for name in entries {
        let (src, dst) = (from.join(name), to.join(name));
        if src.is_dir() {
            let children: Vec<String> = std::fs::read_dir(&src)
                .unwrap()
                .map(|e| e.unwrap().file_name().into_string().unwrap())
                .collect();
            let refs: Vec<&str> = children.iter().map(String::as_str).collect();
            copy_tree(&src, &dst, &refs);
        } else {
            std::fs::copy(&src, &dst).unwrap();
        }
    }
}

/// The full regenerate-and-compare (`capsule-mpc generate --check`, both
/// modules) solves every table again and takes minutes: it is its own
/// `.ci/run` step. Here, in seconds: the committed crate is what the
/// emitter writes from the committed tables (bindings, summaries, the
/// explicit tier rebuilt from the plans, the table files byte for byte),
/// and the committed QP iteration map is the one the compiled solver
/// measures on them.
#[test]
fn committed_generated_crate_re_emits_from_its_own_tables() {
    for module in ControllerModule::ALL {
        let config = module.default_config();
        let tables =
            table_file::read(&Path::new("generated").join(module.tables_path()), &config).unwrap();
        let mut files = emit_module_files(module, &config, tables).unwrap();
        if module == ControllerModule::Controller {
            let measured = capsule_mpc_sim::qp_map::fill_if_compiled(&mut files).unwrap();
            assert!(measured, "the compiled controller is not the committed one");
        }
        let diff = differences(Path::new("generated"), &files);
        assert!(
            diff.is_empty(),
            "run `capsule-mpc generate --module {} --reuse-tables`: {diff:?} differ",
            module.cli_name()
        );
    }
}

#[test]
fn committed_tables_refuse_another_config() {
    let mut other = Config::embedded_default();
    other.capsule[0].sphere_radius_m = 0.001;
    let err = table_file::read(Path::new("generated/controller.tables.bin"), &other).unwrap_err();
    assert!(err.to_string().contains("different config"), "{err}");
    let bytes = std::fs::read("generated/controller.tables.bin").unwrap();
    let err =
        table_file::decode(&bytes[..bytes.len() / 2], &Config::embedded_default()).unwrap_err();
    assert!(err.to_string().contains("truncated or corrupted"), "{err}");
    // One flipped bit in the middle of the payload (inside the stored
    // plans) still decodes; the SHA-256 trailer refuses it.
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x10;
    let err = table_file::decode(&flipped, &Config::embedded_default()).unwrap_err();
    assert!(matches!(err, TableError::Checksum { .. }), "{err}");
    assert!(err.to_string().contains("truncated or corrupted"), "{err}");
}

/// A user changes the spheres to 1.0 mm and 2.5 mm, regenerates (small grid
/// here), rebuilds, and the closed loop reaches a covered target.
#[test]
fn regenerated_solver_for_new_capsules_closes_the_loop() {
    let mut config = Config::embedded_default();
    config.capsule[0].sphere_radius_m = 0.0010;
    config.capsule[1].sphere_radius_m = 0.0025;
    config.grid.position_range_m = 0.02;
    config.grid.position_step_m = 0.01;
    config.grid.starts = 8;
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let files = generate(&config, &Silent).unwrap();
    write_atomically(&root.join("generated"), &files).unwrap();
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    // Only the `controller` module is regenerated; the shipped three-capsule
    // module (which lib.rs declares) stays as committed, as in a checkout.
    for rel in [
        "src/three_capsules.rs",
        "three_capsules.tables.bin",
        "three_capsules.tables.txt",
    ] {
        std::fs::copy(
            here.join("generated").join(rel),
            root.join("generated").join(rel),
        )
        .unwrap();
    }
    // The solver and the runtime as shipped, pointed at the new generated crate.
    for krate in ["solver", "runtime"] {
        copy_tree(&here.join(krate), &root.join(krate), &["Cargo.toml", "src"]);
    }
    std::fs::create_dir_all(root.join("probe/src")).unwrap();
    std::fs::write(
        root.join("Cargo.toml"),
        "[workspace]\nmembers = [\"solver\", \"generated\", \"runtime\", \"probe\"]\nresolver = \"2\"\n\
         [workspace.package]\nversion = \"0.1.0\"\nedition = \"2021\"\nlicense = \"MIT\"\n",
    )
    .unwrap();
    std::fs::write(
        root.join("probe/Cargo.toml"),
        "[package]\nname = \"probe\"\nversion = \"0.1.0\"\nedition = \"2021\"\n\
         [dependencies]\ncapsule-mpc-runtime = { path = \"../runtime\" }\n",
    )
    .unwrap();
    // A plain RK4 plant with the new capsules' constants, 1 ms steps.
    let model = capsule_mpc_generator::model::Model::from_config(&config);
    let b: Vec<f64> = model
        .capsules
        .iter()
        .map(|c| c.drag.effective_b_per_m(0.1))
        .collect();
    let g: Vec<f64> = model.capsules.iter().map(|c| c.g).collect();
    std::fs::write(
        root.join("probe/src/main.rs"),
        format!(
            r#"use capsule_mpc_runtime::DefaultController;
fn f(x: &[f64; 4], u: f64) -> [f64; 4] {{
    let (b, g) = ([{b0:?}, {b1:?}], [{g0:?}, {g1:?}]);
    [x[1], -b[0] * x[1] * x[1].abs() + g[0] * u, x[3], -b[1] * x[3] * x[3].abs() + g[1] * u]
}}
fn main() {{
    let mut settings = DefaultController::default_settings();
    settings.sampling = capsule_mpc_runtime::controller::Sampling::Ideal;
    let mut c = DefaultController::new(settings, &[0.0, 0.0]).unwrap();
    let target = [0.01, 0.0, -0.01, 0.0];
    c.set_target(&target).unwrap();
    let mut x = [0.0f64; 4];
    for _ in 0..150 {{
        let out = c.cycle_full_state(&x).unwrap();
        let u = out.gradients_t_per_m[0];
        for _ in 0..20 {{
            let h = 1e-3;
            let k1 = f(&x, u);
            let a = |k: &[f64; 4], s: f64| [x[0] + s * k[0], x[1] + s * k[1], x[2] + s * k[2], x[3] + s * k[3]];
            let k2 = f(&a(&k1, h / 2.0), u);
            let k3 = f(&a(&k2, h / 2.0), u);
            let k4 = f(&a(&k3, h), u);
            for j in 0..4 {{ x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]); }}
        }}
    }}
    let err = (x[0] - target[0]).abs().max((x[2] - target[2]).abs());
    println!("final error {{err}}");
    assert!(err < 1e-3, "did not reach the target: error {{err}} m");
}}
"#,
            b0 = b[0],
            b1 = b[1],
            g0 = g[0],
            g1 = g[1]
        ),
    )
    .unwrap();
    let target_dir = here.join("target/regenerate-test");
    let out = Command::new(env!("CARGO"))
        .args(["run", "--release", "--quiet", "-p", "probe"])
        .current_dir(root)
        .env("CARGO_TARGET_DIR", &target_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
