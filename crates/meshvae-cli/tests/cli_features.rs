//! `meshvae features` and `meshvae roundtrip` on a small synthetic set: what they write and
//! print, and their messages for bad arguments.

mod common;

use common::{fails_with, meshvae, ok, s, synth_case};
use deform_features::load_features;

#[test]
fn features_writes_normalised_or_raw_features_of_every_frame() {
    let (dir, set, _) = synth_case("features", 2);
    let frames = std::fs::read_dir(&set)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "obj")
        })
        .count();
    let out = dir.join("f.safetensors");
    let printed = ok(&meshvae(&["features", s(&set), "--out", s(&out)]));
    assert!(printed.contains(&format!("{frames} frames")), "{printed}");
    assert!(printed.contains("stored normalised"), "{printed}");
    let file = load_features(&out).unwrap();
    assert!(file.normalized);
    assert_eq!(file.features.frames(), frames);
    assert_eq!(file.names.len(), frames);
    assert_eq!(file.extra["rest_frame"], file.names[0]);
    let values = file.features.as_slice();
    assert!(values.iter().all(|v| v.abs() <= 0.95 + 1e-6));
    // The stored normalisation maps them back to the raw features `--raw` stores.
    let raw_out = dir.join("raw.safetensors");
    let printed = ok(&meshvae(&[
        "features",
        s(&set),
        "--out",
        s(&raw_out),
        "--raw",
        "--rest",
        "1",
    ]));
    assert!(printed.contains("stored raw"), "{printed}");
    let raw = load_features(&raw_out).unwrap();
    assert!(!raw.normalized);
    assert_eq!(raw.extra["rest_frame"], raw.names[1]);
    assert!(raw.features.as_slice().iter().any(|v| v.abs() > 0.95));
}

#[test]
fn roundtrip_reconstructs_every_frame_to_float_rounding() {
    let (_dir, set, _) = synth_case("roundtrip", 2);
    let printed = ok(&meshvae(&["roundtrip", s(&set), "--json"]));
    let report: serde_json::Value = serde_json::from_str(&printed).unwrap();
    assert_eq!(
        report["frames"], 4,
        "two meshes per label, two labels: {report}"
    );
    let (rms, max) = (
        report["rms_rel"].as_f64().unwrap(),
        report["max_rel"].as_f64().unwrap(),
    );
    // Integrable features lose only their f32 rounding on the way (measured: 4e-9 of the
    // diagonal), and the worst vertex is no better than the mean.
    assert!(rms > 0.0 && rms < 1e-6, "{report}");
    assert!(max >= rms, "{report}");
    assert!(report["worst_vertex"]["error_rel"].as_f64().unwrap() <= max);
    assert!(report.get("worst_vertices").is_none(), "only with --worst");

    // --worst N: the N vertices by largest error, in the JSON and on stdout in text mode.
    let printed = ok(&meshvae(&["roundtrip", s(&set), "--json", "--worst", "3"]));
    let report: serde_json::Value = serde_json::from_str(&printed).unwrap();
    let worst = report["worst_vertices"].as_array().unwrap();
    assert_eq!(worst.len(), 3);
    let errors: Vec<f64> = worst
        .iter()
        .map(|w| w["max_rel"].as_f64().unwrap())
        .collect();
    assert!(errors.windows(2).all(|p| p[0] >= p[1]), "{errors:?}");
    assert_eq!(errors[0], max);
    assert_eq!(worst[0]["vertex"], report["worst_vertex"]["vertex"]);
    assert_eq!(worst[0]["rest_position"].as_array().unwrap().len(), 3);
    let text = ok(&meshvae(&["roundtrip", s(&set), "--worst", "2"]));
    let table = text
        .find("vertex  max_rel")
        .expect("the table is on stdout");
    assert_eq!(text[table..].lines().count(), 3, "{text}");
}

#[test]
fn bad_arguments_name_what_is_wrong() {
    let (dir, set, _) = synth_case("features-bad", 2);
    let out = dir.join("f.safetensors");
    fails_with(
        &meshvae(&[
            "features",
            s(&set),
            "--out",
            s(&out),
            "--rest",
            "no-such-frame",
        ]),
        1,
        "--rest",
    );
    assert!(!out.exists(), "nothing is written on an error");
    fails_with(
        &meshvae(&["roundtrip", s(&dir.join("missing")), "--json"]),
        1,
        "missing",
    );
    let into_missing = dir.join("no-folder").join("f.safetensors");
    fails_with(
        &meshvae(&["features", s(&set), "--out", s(&into_missing)]),
        1,
        "no-folder",
    );
}
