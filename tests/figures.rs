//! `all_figures` runs the real closed loop and writes every figure as SVG and
//! PNG; checks that the files are well-formed and hold the plotted series.

use capsule_mpc::figures::all_figures;
use std::collections::HashSet;
use std::path::Path;

/// Decodes a PNG; returns (width, height, number of distinct colours).
fn png_stats(path: &Path) -> (u32, u32, usize) {
    let file = std::fs::File::open(path).unwrap();
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let channels = info.color_type.samples();
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    let colours: HashSet<&[u8]> = buf[..info.buffer_size()].chunks_exact(channels).collect();
    (info.width, info.height, colours.len())
}

#[test]
fn all_figures_writes_every_figure_as_svg_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("figures");
    let figures = all_figures(&out, 0.6).unwrap();

    let names: Vec<&str> = figures.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["fig3", "fig4", "fig5", "fig6", "fig7", "fig8"]);

    for f in &figures {
        assert!(!f.caption.is_empty(), "{}", f.name);
        assert!(!f.runs.is_empty(), "{}", f.name);
        for r in &f.runs {
            assert!((0.0..=1.0).contains(&r.duty_cycle), "{}: {r:?}", f.name);
            assert!(r.final_position_error_m.is_finite(), "{}: {r:?}", f.name);
        }
        let svg = out.join(format!("{}.svg", f.name));
        let png = out.join(format!("{}.png", f.name));
        assert_eq!(f.files, vec![svg.clone(), png.clone()]);

        let text = std::fs::read_to_string(&svg).unwrap();
        let head = text.trim_start();
        assert!(
            head.starts_with("<svg") || head.starts_with("<?xml"),
            "{}",
            svg.display()
        );
        assert!(text.trim_end().ends_with("</svg>"), "{}", svg.display());
        let paths = text.matches("<polyline").count() + text.matches("<path").count();
        assert!(paths >= 2, "{}: {paths} polylines", svg.display());
        assert!(text.contains("time (s)"), "{}: no time axis", svg.display());
        assert!(text.contains("<text"), "{}: no text", svg.display());

        let (w, h, colours) = png_stats(&png);
        assert!(w > 100 && h > 100, "{}: {w}x{h}", png.display());
        assert!(colours > 1, "{}: one colour", png.display());
    }

    // Units on the axes.
    let fig3 = std::fs::read_to_string(out.join("fig3.svg")).unwrap();
    for unit in ["position (mm)", "velocity (mm/s)", "gradient (mT/m)"] {
        assert!(fig3.contains(unit), "fig3 lacks {unit}");
    }
    let fig5 = std::fs::read_to_string(out.join("fig5.svg")).unwrap();
    assert!(
        fig5.contains("gradient (mT/m)"),
        "fig5 lacks the gradient axis"
    );

    // Two sampled runs in fig 7 with their tracking instants.
    let fig7 = figures.iter().find(|f| f.name == "fig7").unwrap();
    assert_eq!(fig7.runs.len(), 2);

    // The index lists every figure with its numbers.
    let index = std::fs::read_to_string(out.join("index.md")).unwrap();
    for f in &figures {
        assert!(
            index.contains(&format!("[{}]", f.name)),
            "index.md: {index}"
        );
    }
    assert!(index.contains("duty"), "{index}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("figures.json")).unwrap()).unwrap();
    assert_eq!(json["figures"].as_array().unwrap().len(), figures.len());
}

#[test]
fn all_figures_rejects_a_non_positive_duration() {
    let dir = tempfile::tempdir().unwrap();
    assert!(all_figures(dir.path(), 0.0).is_err());
    assert!(all_figures(dir.path(), f64::NAN).is_err());
}

/// docs/results.md shows the committed figures in `docs/figures/`: their numbers
/// must be what the current code produces (regenerate with
/// `capsule-mpc figures --out docs/figures` when the controller changes).
#[test]
fn committed_figures_match_the_current_code() {
    let committed: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/figures/figures.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let duration_s = committed["duration_s"].as_f64().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let fresh = all_figures(&dir.path().join("figures"), duration_s).unwrap();
    let figures = committed["figures"].as_array().unwrap();
    assert_eq!(figures.len(), fresh.len());
    for (old, new) in figures.iter().zip(&fresh) {
        assert_eq!(old["name"], new.name.as_str());
        assert_eq!(old["caption"], new.caption.as_str(), "{}", new.name);
        let runs = old["runs"].as_array().unwrap();
        assert_eq!(runs.len(), new.runs.len(), "{}", new.name);
        for (o, n) in runs.iter().zip(&new.runs) {
            let stale = format!(
                "{}: committed figure is stale; run `capsule-mpc figures --out docs/figures`",
                new.name
            );
            assert_eq!(o["settle_time_s"].as_f64(), n.settle_time_s, "{stale}");
            assert_eq!(o["duty_cycle"].as_f64(), Some(n.duty_cycle), "{stale}");
            let err = o["final_position_error_m"].as_f64().unwrap();
            assert!((err - n.final_position_error_m).abs() <= 1e-9, "{stale}");
        }
    }
}
