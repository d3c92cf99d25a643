//! `meshvae simplify --method remesh|qem`: the coarse mesh written, one JSON report with the
//! same keys for both methods, and typed errors for bad combinations.

mod common;

use common::{fails_with, meshvae, ok, s, scratch};
use std::path::Path;

/// The keys of `meshvae simplify --json`, for either method.
const KEYS: [&str; 18] = [
    "method",
    "vertices_in",
    "vertices_out",
    "faces_in",
    "faces_out",
    "lambda",
    "edge_cv_in",
    "edge_cv",
    "cluster_cv",
    "cluster_max",
    "cluster_area_cv",
    "manifold",
    "flipped_faces",
    "degenerate_faces",
    "euler_in",
    "euler_out",
    "seconds",
    "geometric_error_rel",
];

/// A subdivided icosahedron (642 vertices) written as OBJ into `dir`.
fn sphere(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("sphere.obj");
    mesh_io::write_mesh(&path, &qem_simplify::shapes::icosphere(3)).unwrap();
    path
}

fn report(args: &[&str]) -> serde_json::Map<String, serde_json::Value> {
    let text = ok(&meshvae(args));
    match serde_json::from_str(&text) {
        Ok(serde_json::Value::Object(map)) => map,
        other => panic!("not a JSON object: {other:?} from {text}"),
    }
}

#[test]
fn simplify_method_remesh_writes_the_coarse_mesh_and_the_same_report_keys() {
    let dir = scratch("simplify-remesh");
    let input = sphere(&dir);
    let out = dir.join("coarse.obj");
    let remesh = report(&[
        "simplify",
        s(&input),
        "--method",
        "remesh",
        "--out",
        s(&out),
        "--json",
    ]);
    let keys: Vec<&str> = remesh.keys().map(String::as_str).collect();
    let mut expected = KEYS.to_vec();
    expected.sort_unstable();
    let mut sorted = keys.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, expected);
    assert_eq!(remesh["method"], "remesh");
    assert!(remesh["lambda"].is_null());
    assert_eq!(remesh["vertices_in"], 642);
    assert_eq!(remesh["vertices_out"], 321);
    assert_eq!(remesh["manifold"], true);
    assert_eq!(remesh["flipped_faces"], 0);
    assert_eq!(remesh["euler_out"], 2);
    let written = mesh_io::read_mesh(&out).unwrap().value;
    assert_eq!(written.vertex_count(), 321);

    // QEM reports the same keys, its method and its λ.
    let qem_out = dir.join("qem.obj");
    let qem = report(&["simplify", s(&input), "--out", s(&qem_out), "--json"]);
    let mut qem_keys: Vec<&str> = qem.keys().map(String::as_str).collect();
    qem_keys.sort_unstable();
    assert_eq!(qem_keys, expected);
    assert_eq!(qem["method"], "qem");
    assert_eq!(qem["lambda"], 0.001);
    // The remeshing's edges are the more even.
    let cv = |r: &serde_json::Map<String, serde_json::Value>| r["edge_cv"].as_f64().unwrap();
    assert!(cv(&remesh) < cv(&qem));
}

#[test]
fn simplify_method_remesh_text_report_and_ratio() {
    let dir = scratch("simplify-remesh-text");
    let input = sphere(&dir);
    let out = dir.join("coarse.ply");
    let text = ok(&meshvae(&[
        "simplify",
        s(&input),
        "--method",
        "remesh",
        "--ratio",
        "0.25",
        "--out",
        s(&out),
    ]));
    assert!(text.contains("method               remesh"), "{text}");
    assert!(text.contains("642 -> 161"), "{text}");
    assert!(text.contains("lambda               -"), "{text}");
    assert_eq!(mesh_io::read_mesh(&out).unwrap().value.vertex_count(), 161);
}

#[test]
fn simplify_rejects_lambda_with_remesh_and_unknown_methods() {
    let dir = scratch("simplify-remesh-bad");
    let input = sphere(&dir);
    let out = dir.join("coarse.obj");
    let with_lambda = meshvae(&[
        "simplify",
        s(&input),
        "--method",
        "remesh",
        "--lambda",
        "0.01",
        "--out",
        s(&out),
    ]);
    fails_with(&with_lambda, 1, "--lambda");
    assert!(!out.exists(), "nothing written on error");
    let unknown = meshvae(&["simplify", s(&input), "--method", "voxel", "--out", s(&out)]);
    fails_with(&unknown, 2, "voxel");
    let bad_ratio = meshvae(&[
        "simplify",
        s(&input),
        "--method",
        "remesh",
        "--ratio",
        "0",
        "--out",
        s(&out),
    ]);
    fails_with(&bad_ratio, 1, "ratio");
    assert!(!out.exists());
}
