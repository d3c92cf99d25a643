//! `meshvae generate`, `interpolate`, `embed` end to end on a small synthetic set.

mod common;

use common::{fails_with, meshvae, ok, s, synth_case};
use std::path::Path;

/// Decodes a PNG and returns its size; fails the test when it does not decode.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let image = mesh_render::Image::decode_png(&bytes).unwrap();
    assert!(image.width > 0 && image.height > 0);
    // Not a blank picture: some pixel differs from the first.
    assert!(
        image.rgb.chunks(3).any(|p| p != &image.rgb[..3]),
        "{}",
        path.display()
    );
    (image.width, image.height)
}

fn files(dir: &Path, ext: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(ext))
        .collect();
    names.sort();
    names
}

#[test]
fn generate_interpolate_embed_on_a_synthetic_set() {
    let (dir, set, model) = synth_case("apps", 4);
    ok(&meshvae(&[
        "train",
        s(&set),
        "--out",
        s(&model),
        "--epochs",
        "2",
        "--batch",
        "4",
        "--latent",
        "16",
        "--quiet",
    ]));

    // generate
    let gen_dir = dir.join("gen");
    let out = ok(&meshvae(&[
        "generate",
        s(&model),
        "-n",
        "3",
        "--out",
        s(&gen_dir),
        "--seed",
        "7",
        "--sheet",
    ]));
    assert!(out.contains("wrote 3 generated meshes"), "{out}");
    assert_eq!(
        files(&gen_dir, ".obj"),
        ["sample_000.obj", "sample_001.obj", "sample_002.obj"]
    );
    let sample = mesh_io::read_mesh(&gen_dir.join("sample_001.obj"))
        .unwrap()
        .value;
    let template = mesh_io::read_mesh(&model.join("template.obj"))
        .unwrap()
        .value;
    assert_eq!(sample.faces, template.faces);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(gen_dir.join("report.json")).unwrap())
            .unwrap();
    let samples = report["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 3);
    let split: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("split.json")).unwrap()).unwrap();
    for sample in samples {
        assert!(sample["distance"].as_f64().unwrap() > 0.0);
        assert!(
            split["train"]
                .as_array()
                .unwrap()
                .contains(&sample["nearest_index"])
        );
    }
    let csv = std::fs::read_to_string(gen_dir.join("report.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let (w, h) = png_size(&gen_dir.join("sheet.png"));
    assert!(w > h, "two pairs side by side: {w} × {h}");
    // The same seed gives the same meshes (up to the float rounding of another batch size).
    let again = dir.join("gen2");
    ok(&meshvae(&[
        "generate",
        s(&model),
        "-n",
        "1",
        "--out",
        s(&again),
        "--seed",
        "7",
    ]));
    let one = mesh_io::read_mesh(&again.join("sample_000.obj"))
        .unwrap()
        .value;
    let first = mesh_io::read_mesh(&gen_dir.join("sample_000.obj"))
        .unwrap()
        .value;
    let diagonal = first.bbox_diagonal() as f32;
    let worst = one
        .positions
        .iter()
        .zip(&first.positions)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0f32, f32::max);
    assert!(worst < 1e-4 * diagonal, "{worst} of {diagonal}");

    // interpolate: by name and by index.
    let names: Vec<String> = files(&set, ".obj");
    let first = names[0].trim_end_matches(".obj");
    let int_dir = dir.join("int");
    let out = ok(&meshvae(&[
        "interpolate",
        s(&model),
        "--from",
        first,
        "--to",
        "5",
        "--steps",
        "4",
        "--out",
        s(&int_dir),
    ]));
    assert!(out.contains("wrote 4 meshes"), "{out}");
    assert_eq!(
        files(&int_dir, ".obj"),
        ["step_00.obj", "step_01.obj", "step_02.obj", "step_03.obj"]
    );
    let glb = mesh_io::load_set(&int_dir.join("interpolation.glb"))
        .unwrap()
        .value;
    assert_eq!(glb.len(), 4);
    assert_eq!(glb.faces(), template.faces.as_slice());
    let (w, h) = png_size(&int_dir.join("strip.png"));
    assert!(w > 3 * h, "one row of four: {w} × {h}");

    // embed
    let emb_dir = dir.join("emb");
    let out = ok(&meshvae(&["embed", s(&model), "--out", s(&emb_dir)]));
    assert!(out.contains("wrote embedding.csv"), "{out}");
    let csv = std::fs::read_to_string(emb_dir.join("embedding.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "name,frame,latent_x,latent_y,pca_x,pca_y,tsne_x,tsne_y,label"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 8);
    for (i, row) in rows.iter().enumerate() {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells.len(), 9, "{row}");
        assert_eq!(cells[1], i.to_string());
        assert!(
            cells[2..8]
                .iter()
                .all(|c| c.parse::<f64>().unwrap().is_finite())
        );
        assert_eq!(cells[8], ["bend", "twist"][i % 2], "{row}");
    }
    let (w, h) = png_size(&emb_dir.join("embedding.png"));
    assert!(w > 2 * h, "three plots side by side: {w} × {h}");

    // Bad arguments: non-zero exit naming the argument, nothing written.
    let bad = dir.join("bad");
    fails_with(
        &meshvae(&["generate", s(&model), "-n", "0", "--out", s(&bad)]),
        1,
        "--count",
    );
    fails_with(
        &meshvae(&[
            "interpolate",
            s(&model),
            "--from",
            "nope",
            "--to",
            "0",
            "--out",
            s(&bad),
        ]),
        1,
        "--from",
    );
    fails_with(
        &meshvae(&[
            "interpolate",
            s(&model),
            "--from",
            "0",
            "--to",
            "99",
            "--out",
            s(&bad),
        ]),
        1,
        "--to",
    );
    fails_with(
        &meshvae(&[
            "interpolate",
            s(&model),
            "--from",
            "0",
            "--to",
            "1",
            "--steps",
            "1",
            "--out",
            s(&bad),
        ]),
        1,
        "--steps",
    );
    fails_with(
        &meshvae(&["embed", s(&model), "--out", s(&bad), "--perplexity", "0.5"]),
        1,
        "--perplexity",
    );
    fails_with(&meshvae(&["embed", s(&model)]), 2, "--out");
    fails_with(
        &meshvae(&["generate", s(&dir), "--out", s(&bad)]),
        1,
        "not a model folder",
    );
    assert!(!bad.exists(), "a failed command wrote {}", bad.display());
}
