//! The conditional VAE from the command line: `pack` of several sets into one labelled set,
//! `train --labels` / `--conditional`, `generate --label`, and their errors.

mod common;

use common::{fails_with, meshvae, ok, s, scratch};
use std::path::Path;

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn pack_joins_sets_of_one_connectivity_into_a_labelled_set() {
    let dir = scratch("cvae-pack");
    let (a, b) = (dir.join("bendy"), dir.join("twisty"));
    ok(&meshvae(&["synth", "--out", s(&a), "--per-label", "2"]));
    ok(&meshvae(&[
        "synth",
        "--out",
        s(&b),
        "--per-label",
        "1",
        "--seed",
        "5",
    ]));
    // Labels from the folder names, into a folder (OBJ files + labels.csv).
    let joined = dir.join("joined");
    ok(&meshvae(&["pack", s(&a), s(&b), "--out", s(&joined)]));
    let info = ok(&meshvae(&["info", s(&joined), "--json"]));
    let info: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(info["meshes"], 6);
    assert_eq!(info["labels"], serde_json::json!(["bendy", "twisty"]));
    let labels = std::fs::read_to_string(joined.join("labels.csv")).unwrap();
    assert_eq!(labels.lines().filter(|l| l.ends_with(",twisty")).count(), 2);
    assert!(labels.contains("bendy_"), "{labels}");
    // Given names, into a cache.
    let cache = dir.join("joined.mvset");
    let out = meshvae(&[
        "pack",
        s(&a),
        s(&b),
        "--out",
        s(&cache),
        "--label-names",
        "x,y",
    ]);
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("labelled x, y"));
    let info = ok(&meshvae(&["info", s(&cache), "--json"]));
    let info: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(info["labels"], serde_json::json!(["x", "y"]));

    // Errors: another connectivity names the set; a label count that does not fit; a
    // non-empty output folder.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).unwrap();
    let tetra = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
    for name in ["a.obj", "b.obj"] {
        std::fs::write(other.join(name), tetra).unwrap();
    }
    let bad = dir.join("bad.mvset");
    fails_with(
        &meshvae(&["pack", s(&a), s(&other), "--out", s(&bad)]),
        1,
        "other",
    );
    assert!(!bad.exists());
    fails_with(
        &meshvae(&["pack", s(&a), s(&b), "--out", s(&bad), "--label-names", "x"]),
        1,
        "1 labels for 2 sets",
    );
    fails_with(
        &meshvae(&["pack", s(&a), s(&b), "--out", s(&joined)]),
        1,
        "not an empty folder",
    );
}

#[test]
fn train_with_labels_then_generate_by_label() {
    let dir = scratch("cvae-train");
    let set = dir.join("set");
    ok(&meshvae(&["synth", "--out", s(&set), "--per-label", "3"]));
    // A labels file of its own: the set's labels.csv renamed, so --labels is what counts.
    let labels = dir.join("kinds.csv");
    std::fs::rename(set.join("labels.csv"), &labels).unwrap();
    let train = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            s(&set),
            "--out",
            s(out),
            "--epochs",
            "2",
            "--batch",
            "3",
            "--latent",
            "8",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        meshvae(&args)
    };
    // --conditional needs labels the set does not have any more.
    let model = dir.join("model");
    fails_with(&train(&model, &["--conditional"]), 1, "has no labels");
    let out = ok(&train(&model, &["--labels", s(&labels)]));
    assert!(
        out.contains("conditional on the labels bend, twist"),
        "{out}"
    );
    let config = json(&model.join("config.json"));
    assert_eq!(
        config["model"]["labels"],
        serde_json::json!(["bend", "twist"])
    );
    assert_eq!(config["labels"].as_array().unwrap().len(), 6);

    let gen_dir = dir.join("gen");
    let out = ok(&meshvae(&[
        "generate",
        s(&model),
        "-n",
        "4",
        "--label",
        "twist",
        "--out",
        s(&gen_dir),
    ]));
    assert!(
        out.contains("label twist:") && out.contains("of 4 samples"),
        "{out}"
    );
    let report = json(&gen_dir.join("report.json"));
    assert_eq!(report["label"], "twist");
    let share = report["label_share"].as_f64().unwrap();
    let samples = report["samples"].as_array().unwrap();
    let hits = samples
        .iter()
        .filter(|x| x["nearest_label"] == "twist")
        .count();
    assert_eq!(share, hits as f64 / 4.0);
    assert!(samples.iter().all(|x| x["label"] == "twist"));
    let csv = std::fs::read_to_string(gen_dir.join("report.csv")).unwrap();
    assert!(csv.starts_with("sample,file,label,nearest,nearest_index,nearest_label,"));
    assert!(csv.lines().nth(1).unwrap().contains(",twist,"), "{csv}");

    // An unknown label names itself and the known ones; a conditional model needs a label.
    let none = dir.join("none");
    let out = meshvae(&[
        "generate",
        s(&model),
        "--label",
        "canter",
        "--out",
        s(&none),
    ]);
    fails_with(&out, 1, "\"canter\"");
    fails_with(&out, 1, "bend, twist");
    fails_with(
        &meshvae(&["generate", s(&model), "--out", s(&none)]),
        1,
        "give one of its labels (bend, twist)",
    );
    assert!(!none.exists());

    // The other applications take each mesh's own label.
    let json_eval = ok(&meshvae(&["eval", s(&model), "--json"]));
    let eval: serde_json::Value = serde_json::from_str(&json_eval).unwrap();
    assert!(eval["test_rms"].as_f64().unwrap().is_finite());
    let int_dir = dir.join("int");
    ok(&meshvae(&[
        "interpolate",
        s(&model),
        "--from",
        "0",
        "--to",
        "5",
        "--steps",
        "3",
        "--out",
        s(&int_dir),
    ]));
    assert!(int_dir.join("interpolation.glb").is_file());

    // --label on an unconditional model.
    let plain = dir.join("plain");
    ok(&train(&plain, &[]));
    assert!(
        !json(&plain.join("config.json"))
            .to_string()
            .contains("labels")
    );
    fails_with(
        &meshvae(&["generate", s(&plain), "--label", "bend", "--out", s(&none)]),
        1,
        "not conditional",
    );
}
