//! Acceptance tests of the hierarchy file: exact round trips of the safetensors layout,
//! version-1 JSON files still loading, and damaged, truncated, foreign, newer or inconsistent
//! files refused with an error naming them.

mod common;

use common::*;
use mesh_hierarchy::{
    DepoolMode, FORMAT, Hierarchy, HierarchyConfig, HierarchyError, LambdaMax, Pooler, VERSION,
};
use mesh_io::stamped::{Dtype, Entry, Stamp, format_of, read_stamped, write_stamped};
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};
use serde_json::Value;
use std::path::Path;

/// Hierarchies that between them use every field and option: clusters present and absent
/// (sampling, no pooling), graph pooling, Pᵀ de-pooling, power-iteration λmax.
fn samples() -> Vec<Hierarchy> {
    let sampling = HierarchyConfig {
        lambda_max: LambdaMax::PowerIteration(30),
        ..config(Pooler::Sampling, 2)
    };
    let transpose = HierarchyConfig {
        depool: DepoolMode::Transpose,
        ..config(Pooler::Remesh, 1)
    };
    vec![
        Hierarchy::build(&torus(12, 8, 1.0, 0.3), &config(Pooler::Max, 2)).unwrap(),
        Hierarchy::build(&icosphere(2), &config(Pooler::Graph, 2)).unwrap(),
        Hierarchy::build(&bumpy_grid(12, 10), &sampling).unwrap(),
        Hierarchy::build(&bumpy_grid(12, 10), &transpose).unwrap(),
        Hierarchy::build(&icosphere(1), &config(Pooler::None, 1)).unwrap(),
        Hierarchy::build(&icosphere(1), &config(Pooler::Mean, 0)).unwrap(),
    ]
}

/// The bits of every float of `h` (`==` does not tell 0.0 from -0.0).
fn float_bits(h: &Hierarchy) -> Vec<u64> {
    let positions = h.levels.iter().flat_map(|l| l.positions.iter().flatten());
    let matrices = h
        .levels
        .iter()
        .map(|l| &l.laplacian)
        .chain(h.pooling.iter().flat_map(|p| [&p.pool, &p.depool]));
    positions
        .map(|x| u64::from(x.to_bits()))
        .chain(matrices.flat_map(|m| m.values().iter().map(|v| v.to_bits())))
        .collect()
}

fn load_error(path: &Path) -> String {
    match Hierarchy::load(path) {
        Err(e @ HierarchyError::File { .. }) => e.to_string(),
        other => panic!("{}: expected a file error, got {other:?}", path.display()),
    }
}

/// The header length of a safetensors file.
fn header_len(bytes: &[u8]) -> usize {
    u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize
}

#[test]
fn binary_round_trip_is_exact() {
    let path = temp_path("exact.hierarchy");
    for h in samples() {
        h.save(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(format_of(&bytes).as_deref(), Some(FORMAT));
        let back = Hierarchy::load(&path).unwrap();
        assert_eq!(back, h, "{}", h.config.pooler);
        assert_eq!(float_bits(&back), float_bits(&h));
    }
    assert_eq!(VERSION, 2);
    let _ = std::fs::remove_file(&path);
}

#[test]
fn wider_integer_arrays_read_the_same() {
    // Files of meshes with 65,536 vertices or more hold U32 (or U64) indices: widen every U16
    // array of a small hierarchy's file, alternately to U32 and U64.
    let h = Hierarchy::build(&icosphere(2), &config(Pooler::Graph, 2)).unwrap();
    let path = temp_path("wide.hierarchy");
    h.save(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let stamp = Stamp {
        format: FORMAT,
        version: VERSION,
    };
    let file = read_stamped(&bytes, &path, stamp).unwrap();
    let mut names = file.tensors.names();
    names.sort();
    let mut widened = 0;
    let entries = names
        .into_iter()
        .map(|name| {
            let t = file.tensors.tensor(name).unwrap();
            if t.dtype() != Dtype::U16 {
                return Entry::new(name, t.dtype(), t.shape().to_vec(), t.data());
            }
            let values = t
                .data()
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]));
            widened += 1;
            let (dtype, data): (_, Vec<u8>) = match widened % 2 {
                0 => (
                    Dtype::U32,
                    values.flat_map(|v| u32::from(v).to_le_bytes()).collect(),
                ),
                _ => (
                    Dtype::U64,
                    values.flat_map(|v| u64::from(v).to_le_bytes()).collect(),
                ),
            };
            Entry::new(name, dtype, t.shape().to_vec(), data)
        })
        .collect();
    let metadata = [("hierarchy".into(), file.metadata["hierarchy"].clone())].into();
    write_stamped(&path, stamp, metadata, entries).unwrap();
    assert!(widened > 10, "{widened}");
    assert_eq!(Hierarchy::load(&path).unwrap(), h);
    let _ = std::fs::remove_file(&path);
}

#[test]
fn version_1_json_files_still_load() {
    let path = temp_path("v1.json");
    let written = temp_path("v1-written.json");
    for h in samples() {
        write_json_v1(&h, &path);
        let back = Hierarchy::load(&path).unwrap();
        assert_eq!(back, h, "{}", h.config.pooler);
        assert_eq!(float_bits(&back), float_bits(&h));
        // save_json writes exactly that layout.
        h.save_json(&written).unwrap();
        assert_eq!(
            std::fs::read(&written).unwrap(),
            std::fs::read(&path).unwrap()
        );
    }
    // Leading whitespace is still JSON.
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, format!("\n  {text}")).unwrap();
    assert!(Hierarchy::load(&path).is_ok());
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&written);
}

#[test]
fn the_binary_file_is_less_than_half_the_json() {
    let h = Hierarchy::build(&icosphere(4), &config(Pooler::Mean, 2)).unwrap();
    let (binary, json) = (temp_path("size.hierarchy"), temp_path("size.json"));
    h.save(&binary).unwrap();
    write_json_v1(&h, &json);
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    let (b, j) = (size(&binary), size(&json));
    eprintln!(
        "{:?} vertices: binary {b} bytes, JSON {j} bytes",
        h.vertex_counts()
    );
    assert!(b < j / 2, "binary {b} bytes, JSON {j} bytes");
    let _ = std::fs::remove_file(&binary);
    let _ = std::fs::remove_file(&json);
}

#[test]
fn a_flipped_data_byte_is_refused_naming_the_file() {
    let h = Hierarchy::build(&torus(12, 8, 1.0, 0.3), &config(Pooler::Mean, 2)).unwrap();
    let path = temp_path("flipped.hierarchy");
    h.save(&path).unwrap();
    let good = std::fs::read(&path).unwrap();
    let data = 8 + header_len(&good);
    for at in [data, (data + good.len()) / 2, good.len() - 1] {
        let mut bytes = good.clone();
        bytes[at] ^= 0x04;
        std::fs::write(&path, &bytes).unwrap();
        let err = load_error(&path);
        assert!(
            err.contains("flipped.hierarchy") && err.contains("checksum"),
            "{err}"
        );
    }
    let _ = std::fs::remove_file(&path);
}

#[test]
fn a_truncated_file_is_refused_naming_the_file() {
    let h = Hierarchy::build(&torus(12, 8, 1.0, 0.3), &config(Pooler::Graph, 1)).unwrap();
    let path = temp_path("truncated.hierarchy");
    h.save(&path).unwrap();
    let good = std::fs::read(&path).unwrap();
    let data = 8 + header_len(&good);
    let cuts = [
        0,
        1,
        7,
        8,
        9,
        data / 2,
        data - 1,
        data,
        data + 1,
        good.len() - 1,
    ];
    for cut in cuts.into_iter().chain((data..good.len()).step_by(97)) {
        std::fs::write(&path, &good[..cut]).unwrap();
        let err = load_error(&path);
        assert!(err.contains("truncated.hierarchy"), "cut at {cut}: {err}");
    }
    let _ = std::fs::remove_file(&path);
}

#[test]
fn foreign_newer_and_unlabelled_files_are_refused() {
    let path = temp_path("foreign.hierarchy");
    let write = |format: &'static str, version: u32, meta: &[(&str, &str)]| {
        let meta = meta
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let one = Entry::new("x", Dtype::U32, vec![1], vec![1, 0, 0, 0]);
        write_stamped(&path, Stamp { format, version }, meta, vec![one]).unwrap();
    };
    write("meshvae-features", 2, &[]);
    let err = load_error(&path);
    assert!(err.contains("not a meshvae-hierarchy file"), "{err}");
    write(FORMAT, 3, &[("hierarchy", "{}")]);
    let err = load_error(&path);
    assert!(err.contains("version 3") && err.contains("update"), "{err}");
    write(FORMAT, 1, &[]);
    assert!(load_error(&path).contains("version 1"));
    write(FORMAT, 2, &[]);
    assert!(load_error(&path).contains("no \"hierarchy\" entry"));
    write(FORMAT, 2, &[("hierarchy", "{\"levels\": 3}")]);
    assert!(load_error(&path).contains("metadata \"hierarchy\""));
    // JSON that claims a later version.
    let h = Hierarchy::build(&icosphere(1), &config(Pooler::Mean, 1)).unwrap();
    write_json_v1(&h, &path);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replace("\"version\":1", "\"version\":2")).unwrap();
    assert!(load_error(&path).contains("only version 1 is JSON"));
    // Neither layout.
    std::fs::write(&path, b"hello").unwrap();
    assert!(load_error(&path).contains("foreign.hierarchy"));
    let _ = std::fs::remove_file(&path);
}

/// `bytes` with the header's JSON edited by `edit`, padded back to its length so that the
/// data (and its checksum) stay valid: the header is not covered by the checksum.
fn edit_header(bytes: &[u8], edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let n = header_len(bytes);
    let mut header: Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    edit(&mut header);
    let mut text = serde_json::to_vec(&header).unwrap();
    assert!(text.len() <= n, "the edit must not lengthen the header");
    text.resize(n, b' ');
    [&bytes[..8], &text, &bytes[8 + n..]].concat()
}

/// Edits the metadata's `hierarchy` JSON.
fn edit_outline(header: &mut Value, edit: impl FnOnce(&mut Value)) {
    let entry = &mut header["__metadata__"]["hierarchy"];
    let mut outline: Value = serde_json::from_str(entry.as_str().unwrap()).unwrap();
    edit(&mut outline);
    *entry = Value::String(outline.to_string());
}

#[test]
fn inconsistent_binary_files_are_refused_by_the_same_checks() {
    let h = Hierarchy::build(&icosphere(2), &config(Pooler::Graph, 2)).unwrap();
    let path = temp_path("inconsistent.hierarchy");
    h.save(&path).unwrap();
    let good = std::fs::read(&path).unwrap();
    let refused = |bytes: Vec<u8>, expected: &str| {
        std::fs::write(&path, bytes).unwrap();
        let err = load_error(&path);
        assert!(
            err.contains("inconsistent.hierarchy") && err.contains(expected),
            "{err}"
        );
    };
    // A missing tensor.
    let renamed = edit_header(&good, |h| {
        let map = h.as_object_mut().unwrap();
        let faces = map.remove("level.1.faces").unwrap();
        map.insert("level.1.fuces".into(), faces);
    });
    refused(renamed, "tensor level.1.faces is missing");
    // A tensor of the wrong type, and one of the wrong shape.
    let retyped = edit_header(&good, |h| h["level.0.positions"]["dtype"] = "U32".into());
    refused(retyped, "tensor level.0.positions is U32");
    let reshaped = edit_header(&good, |h| {
        let shape = &mut h["level.0.positions"]["shape"];
        let len = shape[0].as_u64().unwrap() * 3;
        *shape = serde_json::json!([len]);
    });
    refused(reshaped, "expected F32 [k, 3]");
    // A level whose vertex count disagrees with its arrays (check_shapes).
    let recounted = edit_header(&good, |h| {
        edit_outline(h, |o| o["levels"][1]["vertex_count"] = 7.into())
    });
    refused(recounted, "positions for 7 vertices");
    // A Laplacian whose columns overrun its declared width (the sparse matrix checks).
    let narrowed = edit_header(&good, |h| {
        edit_outline(h, |o| o["levels"][0]["laplacian"]["cols"] = 3.into())
    });
    refused(narrowed, "column beyond 3");
    // A missing cluster array.
    let unclustered = edit_header(&good, |h| {
        let map = h.as_object_mut().unwrap();
        let members = map.remove("pooling.0.clusters.members").unwrap();
        map.insert("pooling.0.clusters.membrs".into(), members);
    });
    refused(unclustered, "pooling.0.clusters.members is missing");
    let _ = std::fs::remove_file(&path);
}

#[test]
fn version_1_json_corruption_is_a_typed_error() {
    let h = Hierarchy::build(&torus(12, 8, 1.0, 0.3), &config(Pooler::Max, 2)).unwrap();
    let path = temp_path("corrupt.json");
    write_json_v1(&h, &path);
    let text = std::fs::read_to_string(&path).unwrap();
    // Truncated file.
    std::fs::write(&path, &text[..text.len() / 2]).unwrap();
    let err = Hierarchy::load(&path).unwrap_err();
    assert!(
        matches!(&err, HierarchyError::File { path: p, .. } if *p == path),
        "{err}"
    );
    // Valid JSON whose level sizes disagree with the operators.
    let mut value: Value = serde_json::from_str(&text).unwrap();
    value["hierarchy"]["levels"][1]["vertex_count"] = serde_json::json!(7);
    std::fs::write(&path, value.to_string()).unwrap();
    assert!(load_error(&path).contains("corrupt.json"));
    // A sparse matrix with a broken index pointer.
    let mut value: Value = serde_json::from_str(&text).unwrap();
    value["hierarchy"]["pooling"][0]["pool"]["indptr"][1] = serde_json::json!(1_000_000);
    std::fs::write(&path, value.to_string()).unwrap();
    assert!(load_error(&path).contains("indptr"));
    // Another format.
    std::fs::write(&path, text.replace(FORMAT, "meshvae-other")).unwrap();
    assert!(load_error(&path).contains("meshvae-other"));
    // Missing file.
    let _ = std::fs::remove_file(&path);
    load_error(&path);
}
