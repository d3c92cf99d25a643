//! GLB/glTF round trips (bit-exact), hand-written glTF files, and the reader's error cases.

mod common;
use common::base64;

use mesh_io::glb::{
    FRAMES_PER_SECOND, parse_gltf_mesh, parse_gltf_set, read_gltf_mesh, read_gltf_set,
    write_glb_mesh, write_glb_set, write_glb_set_to,
};
use mesh_io::{MeshIoError, MeshSet, Point, TriMesh};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mesh-io-glb-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A wavy 7 × 5 grid; frames are large rotations and translations of it (computed in f64, so
/// most frame − base differences are not exactly representable), plus a frame with signed
/// zeros and coordinates near 0 that no f32 displacement can reach exactly.
fn generated_set() -> MeshSet {
    let (nx, ny) = (7u32, 5u32);
    let mut base: Vec<[f64; 3]> = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let (x, y) = (i as f64 * 0.37 + 0.11, j as f64 * 0.29 - 0.53);
            base.push([x, y, 0.2 * (3.0 * x).sin() * (2.0 * y).cos() + 0.731]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let a = j * nx + i;
            faces.push([a, a + 1, a + nx + 1]);
            faces.push([a, a + nx + 1, a + nx]);
        }
    }
    let axis = {
        let a = [1.0f64, 2.0, 3.0];
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|c| c / n)
    };
    let rotate = |p: [f64; 3], angle: f64, shift: f64| -> Point {
        // Rodrigues' rotation formula.
        let (s, c) = angle.sin_cos();
        let k = axis;
        let cross = [
            k[1] * p[2] - k[2] * p[1],
            k[2] * p[0] - k[0] * p[2],
            k[0] * p[1] - k[1] * p[0],
        ];
        let dot = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
        std::array::from_fn(|a| {
            (p[a] * c + cross[a] * s + k[a] * dot * (1.0 - c) + shift * (a as f64 - 1.0)) as f32
        })
    };
    let angles = [0.0, 0.3, 2.0, 3.1, -2.7, 1.5];
    let mut positions: Vec<Point> = Vec::new();
    for (f, &angle) in angles.iter().enumerate() {
        positions.extend(base.iter().map(|&p| rotate(p, angle, 0.25 * f as f64)));
    }
    let v = base.len();
    let mut special: Vec<Point> = positions[..v].to_vec();
    special[0] = [-0.0, 0.0, -0.0];
    special[1][0] = 1e-30;
    special[2][1] = -3.7e-9;
    special[3] = [-special[3][0], -special[3][1], 1e7];
    positions.extend(special);
    let count = angles.len() + 1;
    let names = (0..count).map(|k| format!("pose {k} é")).collect();
    let labels = (0..count)
        .map(|k| ["walk", "run"][k % 2].to_string())
        .collect();
    MeshSet::from_flat(faces, v, positions, names)
        .unwrap()
        .with_labels(labels)
        .unwrap()
}

fn assert_bit_exact(a: &MeshSet, b: &MeshSet) {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.faces(), b.faces());
    assert_eq!(a.vertex_count(), b.vertex_count());
    assert_eq!(a.names(), b.names());
    assert_eq!(a.labels(), b.labels());
    for (k, (fa, fb)) in a.frames().zip(b.frames()).enumerate() {
        for (v, (pa, pb)) in fa.iter().zip(fb).enumerate() {
            assert_eq!(
                pa.map(f32::to_bits),
                pb.map(f32::to_bits),
                "frame {k} vertex {v}: {pa:?} vs {pb:?}"
            );
        }
    }
}

/// The JSON chunk of a GLB, checking the container's layout on the way.
fn glb_json(bytes: &[u8]) -> Value {
    assert_eq!(&bytes[..4], b"glTF");
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(word(4), 2);
    assert_eq!(word(8), bytes.len());
    let json_len = word(12);
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let bin_at = 20 + json_len;
    assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
    assert_eq!(word(bin_at) % 4, 0);
    assert_eq!(bin_at + 8 + word(bin_at), bytes.len());
    serde_json::from_slice(&bytes[20..bin_at]).unwrap()
}

#[test]
fn generated_set_round_trips_bit_exactly() {
    let set = generated_set();
    let dir = temp_dir("generated");
    let path = dir.join("set.glb");
    write_glb_set(&path, &set).unwrap();
    let loaded = read_gltf_set(&path).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_bit_exact(&set, &loaded.value);

    // The file is valid as far as the `gltf` crate's own validation can tell.
    let bytes = std::fs::read(&path).unwrap();
    gltf::Gltf::from_slice(&bytes).expect("the gltf crate accepts the file");

    let doc = glb_json(&bytes);
    let mesh = &doc["meshes"][0];
    let n = set.len();
    assert_eq!(
        mesh["primitives"][0]["targets"].as_array().unwrap().len(),
        n - 1
    );
    assert_eq!(
        mesh["extras"]["targetNames"].as_array().unwrap().len(),
        n - 1
    );
    assert_eq!(mesh["extras"]["meshvae_labels"][1], "run");
    // The special frame needs corrections; the rotations mostly do not.
    let corrections = mesh["extras"]["meshvae_corrections"]["count"]
        .as_u64()
        .unwrap();
    assert!(corrections >= 4, "{corrections}");
    for view in doc["bufferViews"].as_array().unwrap() {
        assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0);
    }
    // POSITION min/max are the base's bounds.
    let accessors = doc["accessors"].as_array().unwrap();
    let position = &accessors[mesh["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap() as usize];
    let (lo, hi) = mesh_io::bbox(set.frame(0)).unwrap();
    let floats = |v: &Value| -> Vec<f32> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect()
    };
    assert_eq!(floats(&position["min"]), lo);
    assert_eq!(floats(&position["max"]), hi);

    // The animation: STEP, keyframe k at k / 24 s, one-hot weights.
    let animation = &doc["animations"][0];
    assert_eq!(animation["samplers"][0]["interpolation"], "STEP");
    assert_eq!(animation["channels"][0]["target"]["path"], "weights");
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_deref().unwrap();
    let read_floats = |accessor: gltf::Accessor| -> Vec<f32> {
        let view = accessor.view().unwrap();
        let start = view.offset() + accessor.offset();
        blob[start..start + 4 * accessor.count()]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    let sampler = gltf.animations().next().unwrap().samplers().next().unwrap();
    let times = read_floats(sampler.input());
    assert_eq!(times.len(), n);
    for (k, t) in times.iter().enumerate() {
        assert!((t * FRAMES_PER_SECOND - k as f32).abs() < 1e-4);
    }
    let weights = read_floats(sampler.output());
    assert_eq!(weights.len(), n * (n - 1));
    for k in 0..n {
        let row = &weights[k * (n - 1)..(k + 1) * (n - 1)];
        let expected: Vec<f32> = (0..n - 1).map(|t| f32::from(k == t + 1)).collect();
        assert_eq!(row, expected, "keyframe {k}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn horse_gallop_round_trips_bit_exactly() {
    let Some(dir) = mesh_io::datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let set = mesh_io::load_set(&dir).unwrap().value;
    let mut bytes = Vec::new();
    write_glb_set_to(&mut bytes, &set).unwrap();
    let doc = glb_json(&bytes);
    let corrections = &doc["meshes"][0]["extras"]["meshvae_corrections"]["count"];
    eprintln!(
        "horse-gallop: {} frames, {} bytes, {corrections} corrections",
        set.len(),
        bytes.len()
    );
    let back = parse_gltf_set(&bytes, Path::new("horse.glb"))
        .unwrap()
        .value;
    assert_bit_exact(&set, &back);
}

#[test]
fn single_mesh_round_trips_and_is_not_a_set() {
    let set = generated_set();
    let mesh = set.mesh(2);
    let dir = temp_dir("single");
    let path = dir.join("one.glb");
    write_glb_mesh(&path, &mesh).unwrap();
    let back = read_gltf_mesh(&path).unwrap().value;
    assert_eq!(back.faces, mesh.faces);
    let bits = |m: &TriMesh| -> Vec<[u32; 3]> {
        m.positions.iter().map(|p| p.map(f32::to_bits)).collect()
    };
    assert_eq!(bits(&back), bits(&mesh));
    // No morph targets: not a set.
    let err = read_gltf_set(&path).unwrap_err();
    assert!(
        matches!(err, MeshIoError::TooFewMeshes { count: 1, .. }),
        "{err}"
    );
    // The whole-set file read as a mesh gives the base.
    let set_path = dir.join("set.glb");
    write_glb_set(&set_path, &set).unwrap();
    assert_eq!(read_gltf_mesh(&set_path).unwrap().value, set.template());
    // An invalid mesh is refused before anything is written.
    let bad = TriMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, f32::NAN], [0.0, 1.0, 0.0]],
        faces: vec![[0, 1, 2]],
    };
    let bad_path = dir.join("bad.glb");
    assert!(matches!(
        write_glb_mesh(&bad_path, &bad),
        Err(MeshIoError::NonFinite { .. })
    ));
    assert!(!bad_path.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

const QUAD: [Point; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];
const LIFT: [Point; 4] = [
    [0.0, 0.0, 0.5],
    [0.0, 0.0, 0.25],
    [0.0, 0.0, 0.0],
    [0.1, 0.0, 0.0],
];
const POKE: Point = [0.0, 0.0, -2.0];

/// A hand-written glTF: a quad with interleaved (16-byte stride) positions, u16 indices, a
/// dense morph target and a sparse one moving vertex 2 only; `uri` names the buffer.
fn quad_gltf(uri: &str) -> (Value, Vec<u8>) {
    let mut bin = Vec::new();
    for p in QUAD {
        bin.extend(p.iter().flat_map(|x| x.to_le_bytes()));
        bin.extend(7.5f32.to_le_bytes()); // an interleaved attribute the reader must skip
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend(i.to_le_bytes());
    }
    bin.extend(LIFT.iter().flatten().flat_map(|x| x.to_le_bytes()));
    bin.extend([2u8, 0, 0, 0]);
    bin.extend(POKE.iter().flat_map(|x| x.to_le_bytes()));
    let gltf = json!({
        "asset": { "version": "2.0" },
        "meshes": [{
            "name": "quad",
            "primitives": [{
                "attributes": { "POSITION": 0 },
                "indices": 1,
                "targets": [{ "POSITION": 2 }, { "POSITION": 3 }],
            }],
            "extras": { "targetNames": ["lift", "poke"] },
        }],
        "buffers": [{ "byteLength": bin.len(), "uri": uri }],
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": 64, "byteStride": 16 },
            { "buffer": 0, "byteOffset": 64, "byteLength": 12 },
            { "buffer": 0, "byteOffset": 76, "byteLength": 48 },
            { "buffer": 0, "byteOffset": 124, "byteLength": 4 },
            { "buffer": 0, "byteOffset": 128, "byteLength": 12 },
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
              "min": [0, 0, 0], "max": [1, 1, 0] },
            { "bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR" },
            { "bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3" },
            { "componentType": 5126, "count": 4, "type": "VEC3",
              "sparse": { "count": 1,
                          "indices": { "bufferView": 3, "componentType": 5121 },
                          "values": { "bufferView": 4 } } },
        ],
    });
    (gltf, bin)
}

fn check_quad(set: &MeshSet) {
    assert_eq!(set.names(), ["quad", "lift", "poke"]);
    assert_eq!(set.faces(), [[0, 1, 2], [0, 2, 3]]);
    assert_eq!(set.frame(0), QUAD);
    let lifted: Vec<Point> = QUAD
        .iter()
        .zip(LIFT)
        .map(|(b, d)| [b[0] + d[0], b[1] + d[1], b[2] + d[2]])
        .collect();
    assert_eq!(set.frame(1), lifted);
    let mut poked = QUAD;
    poked[2][2] += POKE[2];
    assert_eq!(set.frame(2), poked);
    assert!(set.labels().is_none());
}

#[test]
fn hand_written_gltf_with_data_uri() {
    let (_, bin) = quad_gltf("");
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let (gltf, _) = quad_gltf(&uri);
    let text = serde_json::to_vec_pretty(&gltf).unwrap();
    let loaded = parse_gltf_set(&text, Path::new("quad.gltf")).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    check_quad(&loaded.value);
    let mesh = parse_gltf_mesh(&text, Path::new("quad.gltf"))
        .unwrap()
        .value;
    assert_eq!(mesh.positions, QUAD);
}

#[test]
fn hand_written_gltf_with_external_bin() {
    let dir = temp_dir("external");
    let (gltf, bin) = quad_gltf("quad%20data.bin");
    std::fs::write(dir.join("quad data.bin"), &bin).unwrap();
    let path = dir.join("quad.gltf");
    std::fs::write(&path, serde_json::to_vec(&gltf).unwrap()).unwrap();
    check_quad(&read_gltf_set(&path).unwrap().value);
    // Through the format-independent entry points too.
    assert_eq!(mesh_io::read_mesh(&path).unwrap().value.positions, QUAD);
    check_quad(&mesh_io::load_set(&path).unwrap().value);

    std::fs::remove_file(dir.join("quad data.bin")).unwrap();
    let err = read_gltf_set(&path).unwrap_err();
    assert!(
        matches!(&err, MeshIoError::Io { path, .. } if path.ends_with("quad data.bin")),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Parses the quad after `edit` changed its JSON; the error's message.
fn quad_error(edit: impl FnOnce(&mut Value)) -> MeshIoError {
    let (_, bin) = quad_gltf("");
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let (mut gltf, _) = quad_gltf(&uri);
    edit(&mut gltf);
    let text = serde_json::to_vec(&gltf).unwrap();
    parse_gltf_set(&text, Path::new("quad.gltf")).unwrap_err()
}

fn assert_gltf_error(err: MeshIoError, needle: &str) {
    match &err {
        MeshIoError::Gltf { path, message } => {
            assert_eq!(path, Path::new("quad.gltf"));
            assert!(message.contains(needle), "{message:?} lacks {needle:?}");
        }
        other => panic!("expected a glTF error containing {needle:?}, got {other:?}"),
    }
}

#[test]
fn error_cases() {
    let err = quad_error(|g| g["meshes"][0]["primitives"][0]["mode"] = json!(1));
    assert_gltf_error(err, "LINES");
    let err = quad_error(|g| g["accessors"][2]["byteOffset"] = json!(4));
    assert_gltf_error(err, "morph target 0 POSITION");
    let err = quad_error(|g| g["accessors"][0]["byteOffset"] = json!(8));
    assert_gltf_error(err, "need 68 bytes but bufferView 0 has 64");
    let err = quad_error(|g| g["bufferViews"][2]["byteOffset"] = json!(1u64 << 62));
    assert_gltf_error(err, "overruns buffer 0");
    let err = quad_error(|g| g["accessors"][0]["count"] = json!(u64::MAX));
    assert_gltf_error(err, "POSITION");
    let err = quad_error(|g| g["bufferViews"][0]["byteStride"] = json!(8));
    assert_gltf_error(err, "byteStride 8");
    let err = quad_error(|g| g["accessors"][0]["componentType"] = json!(5123));
    assert_gltf_error(err, "expected VEC3 of FLOAT");
    let err = quad_error(|g| g["accessors"][2]["count"] = json!(3));
    assert_gltf_error(err, "expected 4");
    let err = quad_error(|g| g["accessors"][3]["sparse"]["count"] = json!(5));
    assert_gltf_error(err, "5 sparse values");
    let err = quad_error(|g| g["meshes"][0]["primitives"][0]["indices"] = json!(9));
    assert_gltf_error(err, "accessor 9 does not exist");
    let err = quad_error(|g| g["buffers"][0]["uri"] = json!("https://example.com/q.bin"));
    assert_gltf_error(err, "unsupported URI");
    let err = quad_error(|g| g["buffers"][0]["uri"] = json!("data:text/plain,abc"));
    assert_gltf_error(err, "base64");
    let err = quad_error(|g| g["buffers"][0]["byteLength"] = json!(1000));
    assert_gltf_error(err, "declares 1000 bytes");
    let err = quad_error(|g| g["asset"]["version"] = json!("1.0"));
    assert_gltf_error(err, "version");
    // An index past the vertices, and a non-finite position: the crate's typed errors.
    let err = quad_error(|g| {
        // Start the indices 2 bytes early: the first is the top half of 7.5f32 (0x40f0_0000).
        g["accessors"][1]["count"] = json!(3);
        g["bufferViews"][1]["byteOffset"] = json!(62);
    });
    assert!(
        matches!(
            err,
            MeshIoError::IndexOutOfRange {
                index: 16624,
                vertices: 4,
                ..
            }
        ),
        "{err}"
    );
    let err = quad_error(|g| g["meshes"][0]["primitives"][0]["targets"] = json!([]));
    assert!(matches!(err, MeshIoError::TooFewMeshes { .. }), "{err}");
}

#[test]
fn non_finite_frame_is_refused() {
    // A displacement that overflows f32 when added to the base.
    let (_, mut bin) = quad_gltf("");
    bin[76 + 8..76 + 12].copy_from_slice(&f32::MAX.to_le_bytes());
    bin[8..12].copy_from_slice(&f32::MAX.to_le_bytes());
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let (gltf, _) = quad_gltf(&uri);
    let text = serde_json::to_vec(&gltf).unwrap();
    let err = parse_gltf_set(&text, Path::new("quad.gltf")).unwrap_err();
    assert!(
        matches!(err, MeshIoError::NonFinite { vertex: 0, value, .. } if value == f32::INFINITY),
        "{err}"
    );
}

#[test]
fn names_fall_back_when_extras_are_absent_or_wrong() {
    let (_, bin) = quad_gltf("");
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let (mut gltf, _) = quad_gltf(&uri);
    gltf["meshes"][0]["extras"] = json!({ "targetNames": ["only one"] });
    let text = serde_json::to_vec(&gltf).unwrap();
    let loaded = parse_gltf_set(&text, Path::new("quad.gltf")).unwrap();
    assert_eq!(
        loaded.value.names(),
        ["frame_0000", "frame_0001", "frame_0002"]
    );
    assert_eq!(loaded.warnings.len(), 1);
    assert!(loaded.warnings[0].message.contains("targetNames"));

    gltf["meshes"][0]["extras"] = json!({
        "meshvae_frame_names": ["a", "b", "c"],
        "meshvae_labels": ["x", "y", "x"],
    });
    let text = serde_json::to_vec(&gltf).unwrap();
    let set = parse_gltf_set(&text, Path::new("quad.gltf")).unwrap().value;
    assert_eq!(set.names(), ["a", "b", "c"]);
    assert_eq!(set.labels().unwrap(), ["x", "y", "x"]);
}
