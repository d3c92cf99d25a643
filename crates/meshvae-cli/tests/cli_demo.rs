//! `meshvae demo` end to end, tiny (146-vertex capsules) so that it runs in seconds: the model
//! trains until it has converged, every file it announces exists, pictures decode, meshes and
//! the animation load, and a non-empty folder is refused unless --force, which leaves other
//! files alone.

mod common;

use common::{fails_with, meshvae, ok, s, scratch};
use std::path::Path;

/// Decodes a PNG; fails the test when it does not decode or is one flat colour.
fn assert_picture(path: &Path) {
    let image = mesh_render::Image::load_png(path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        image.rgb.chunks(3).any(|p| p != &image.rgb[..3]),
        "{} is blank",
        path.display()
    );
}

fn count(dir: &Path, ext: &str) -> usize {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(ext)
        })
        .count()
}

#[test]
fn the_demo_writes_every_picture_mesh_and_report_it_announces() {
    let dir = scratch("demo");
    let out = dir.join("demo");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "not the demo's").unwrap();
    let args = ["demo", "--out", s(&out), "--tiny"];

    // A non-empty folder is refused, nothing written.
    fails_with(&meshvae(&args), 1, "--force");
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1);
    fails_with(
        &meshvae(&["demo", "--out", s(&out), "--epochs", "0", "--force"]),
        1,
        "--epochs",
    );

    let stdout = ok(&meshvae(&[&args[..], &["--force"]].concat()));
    for part in [
        "$ meshvae train",
        "until it has converged",
        "stopped: converged",
        "test RMS",
        "mean shape",
        "Done in",
        "set.png",
    ] {
        assert!(stdout.contains(part), "stdout lacks {part:?}: {stdout}");
    }
    assert_eq!(
        std::fs::read_to_string(out.join("keep.txt")).unwrap(),
        "not the demo's"
    );

    assert_eq!(count(&out.join("set"), ".obj"), 8);
    let template = mesh_io::read_mesh(&out.join("model/template.obj"))
        .unwrap()
        .value;
    assert_eq!(template.positions.len(), 146);
    for picture in [
        "set.png",
        "generated/sheet.png",
        "interpolation/strip.png",
        "embedding/embedding.png",
        "reconstruction/sheet.png",
    ] {
        assert_picture(&out.join(picture));
    }
    assert_eq!(count(&out.join("generated"), ".obj"), 12);
    assert_eq!(count(&out.join("interpolation"), ".obj"), 8);
    assert_eq!(count(&out.join("reconstruction"), ".obj"), 4);
    for mesh in ["generated/sample_011.obj", "interpolation/step_07.obj"] {
        let mesh = mesh_io::read_mesh(&out.join(mesh)).unwrap().value;
        assert_eq!(mesh.faces, template.faces);
    }
    let animation = mesh_io::load_set(&out.join("interpolation/interpolation.glb"))
        .unwrap()
        .value;
    assert_eq!(
        (animation.len(), animation.faces()),
        (8, template.faces.as_slice())
    );
    // Interpolated from a bent to a twisted capsule.
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("interpolation/interpolation.json")).unwrap(),
    )
    .unwrap();
    let labels = std::fs::read_to_string(out.join("set/labels.csv")).unwrap();
    for (end, label) in [("from", "bend"), ("to", "twist")] {
        let name = json[end].as_str().unwrap();
        assert!(
            labels.lines().any(|l| l == format!("{name}.obj,{label}")),
            "{end} {name} is not a {label}: {labels}"
        );
    }
    // The embedding's CSV carries the set's labels.
    let csv = std::fs::read_to_string(out.join("embedding/embedding.csv")).unwrap();
    let label_column: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(label_column.len(), 8);
    assert!(
        label_column.iter().all(|l| *l == "bend" || *l == "twist"),
        "{csv}"
    );
    assert!(csv.starts_with("name,frame,") && csv.lines().next().unwrap().ends_with(",label"));
}

#[test]
fn synth_writes_capsules_of_the_resolution_it_is_given() {
    let dir = scratch("synth-resolution");
    let out = dir.join("set");
    let resolution = ["--rings", "16", "--segments", "24", "--cap-rings", "3"];
    let args = [
        &["synth", "--out", s(&out), "--per-label", "1"][..],
        &resolution,
    ]
    .concat();
    ok(&meshvae(&args));
    let info: serde_json::Value =
        serde_json::from_str(&ok(&meshvae(&["info", s(&out), "--json"]))).unwrap();
    // 2 + segments × (rings + 2 × cap rings) vertices: the demo's capsule.
    assert_eq!(
        (info["meshes"].as_u64(), info["vertices"].as_u64()),
        (Some(2), Some(530)),
        "{info}"
    );
    let bad = dir.join("bad");
    fails_with(
        &meshvae(&["synth", "--out", s(&bad), "--rings", "1"]),
        1,
        "rings",
    );
    assert!(!bad.join("0000.obj").exists());
}
