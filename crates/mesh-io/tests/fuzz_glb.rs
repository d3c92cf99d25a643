//! Deterministic fuzzing of the glTF reader: thousands of mutations of a valid small GLB (and of
//! the same file as `.gltf` with a data: URI). Every read must return `Ok` with a valid set or
//! an `Err`; never panic, never over-read.

mod common;
use common::{Rng, base64};

use mesh_io::glb::{parse_gltf_mesh, parse_gltf_set, write_glb_set_to};
use mesh_io::{MeshSet, Point};
use serde_json::Value;
use std::path::Path;

/// Three frames of a 2 × 3 grid; frame 2 needs corrections (values near 0), and the set is
/// labelled, so every part of the format is present.
fn small_set() -> MeshSet {
    let base: Vec<Point> = (0..6)
        .map(|i| [(i % 3) as f32 * 0.7 + 0.3, (i / 3) as f32 * 0.9 - 0.2, 0.5])
        .collect();
    let faces = vec![[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]];
    let mut positions = base.clone();
    positions.extend(base.iter().map(|p| [p[1], -p[0], p[2] * 1.5]));
    positions.extend(base.iter().map(|p| [p[0] * 1e-6, -0.0, p[2] + 1.0]));
    let names = vec!["a".into(), "b".into(), "c".into()];
    let labels = vec!["x".into(), "y".into(), "x".into()];
    MeshSet::from_flat(faces, 6, positions, names)
        .unwrap()
        .with_labels(labels)
        .unwrap()
}

fn split(glb: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    let json_len = word(12);
    let bin_at = 20 + json_len;
    (
        glb[20..bin_at].to_vec(),
        glb[bin_at + 8..bin_at + 8 + word(bin_at)].to_vec(),
    )
}

/// A GLB with consistent header and chunk lengths around any JSON and BIN bytes.
fn wrap(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_vec();
    json.resize(json.len().next_multiple_of(4), b' ');
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[derive(Default)]
struct Tally {
    ok: usize,
    err: usize,
}

impl Tally {
    /// Reads `bytes` as a set and as a mesh; checks what an `Ok` holds.
    fn check(&mut self, bytes: &[u8], name: &str, case: &str) {
        let path = Path::new(name);
        let result = std::panic::catch_unwind(|| {
            (parse_gltf_set(bytes, path), parse_gltf_mesh(bytes, path))
        });
        let Ok((set, mesh)) = result else {
            panic!("reading panicked on case {case}");
        };
        match set {
            Ok(loaded) => {
                let set = loaded.value;
                assert!(set.len() >= 2, "case {case}");
                for i in 0..set.len() {
                    set.mesh(i).validate(path).unwrap();
                }
                assert_eq!(set.names().len(), set.len());
                self.ok += 1;
            }
            Err(_) => self.err += 1,
        }
        if let Ok(mesh) = mesh {
            mesh.value.validate(path).unwrap();
        }
    }
}

/// The byte ranges of every number in a JSON text.
fn numbers(json: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < json.len() {
        if json[i].is_ascii_digit()
            || (json[i] == b'-' && json.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            let start = i;
            i += 1;
            while i < json.len() && (json[i].is_ascii_digit() || b".eE+-".contains(&json[i])) {
                i += 1;
            }
            out.push((start, i));
        } else {
            i += 1;
        }
    }
    out
}

#[test]
fn mutated_glb_never_panics() {
    let set = small_set();
    let mut glb = Vec::new();
    write_glb_set_to(&mut glb, &set).unwrap();
    let (json, bin) = split(&glb);
    let mut tally = Tally::default();
    tally.check(&glb, "f.glb", "original");
    assert_eq!(tally.ok, 1, "the unmutated file must read");
    let back = parse_gltf_set(&glb, Path::new("f.glb")).unwrap().value;
    assert_eq!(back, set);

    // Truncation at every length.
    for len in 0..glb.len() {
        tally.check(&glb[..len], "f.glb", &format!("truncate {len}"));
    }
    // Header length fields that lie (below 12 included).
    for length in (0..24).chain([glb.len() as u32 - 1, glb.len() as u32 + 1, u32::MAX]) {
        let mut bytes = glb.clone();
        bytes[8..12].copy_from_slice(&length.to_le_bytes());
        tally.check(&bytes, "f.glb", &format!("header length {length}"));
    }
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    // Byte flips anywhere, 1 to 4 at a time.
    for case in 0..3000 {
        let mut bytes = glb.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(bytes.len());
            bytes[at] ^= 1 + rng.below(255) as u8;
        }
        tally.check(&bytes, "f.glb", &format!("flip {case}"));
    }
    // Inserted and deleted bytes.
    for case in 0..1000 {
        let mut bytes = glb.clone();
        let at = rng.below(bytes.len());
        if case % 2 == 0 {
            let extra: Vec<u8> = (0..1 + rng.below(8)).map(|_| rng.next() as u8).collect();
            bytes.splice(at..at, extra);
        } else {
            let end = (at + 1 + rng.below(8)).min(bytes.len());
            bytes.drain(at..end);
        }
        tally.check(&bytes, "f.glb", &format!("insert/delete {case}"));
    }
    // Every JSON number replaced by awkward values, container kept consistent.
    let replacements = [
        "0",
        "1",
        "2",
        "3",
        "5",
        "12",
        "255",
        "65535",
        "4294967295",
        "4294967296",
        "18446744073709551615",
        "99999999999999999999",
        "-1",
        "1e30",
        "0.5",
    ];
    for (start, end) in numbers(&json) {
        for replacement in replacements {
            let mut edited = json[..start].to_vec();
            edited.extend(replacement.as_bytes());
            edited.extend(&json[end..]);
            tally.check(
                &wrap(&edited, &bin),
                "f.glb",
                &format!("json number at {start} = {replacement}"),
            );
        }
    }
    // JSON bytes deleted or flipped, container kept consistent.
    for case in 0..1000 {
        let mut edited = json.clone();
        let at = rng.below(edited.len());
        if case % 2 == 0 {
            edited.remove(at);
        } else {
            let pool = b"{}[]\":,0123456789-e. a";
            edited[at] = pool[rng.below(pool.len())];
        }
        tally.check(&wrap(&edited, &bin), "f.glb", &format!("json edit {case}"));
    }
    eprintln!("GLB mutations: {} read, {} refused", tally.ok, tally.err);
    // Plenty of both outcomes: the mutations reach past the container checks.
    assert!(tally.ok > 500, "{} ok", tally.ok);
    assert!(tally.err > 2000, "{} err", tally.err);
}

#[test]
fn mutated_gltf_with_data_uri_never_panics() {
    let mut glb = Vec::new();
    write_glb_set_to(&mut glb, &small_set()).unwrap();
    let (json, bin) = split(&glb);
    let mut doc: Value = serde_json::from_slice(&json).unwrap();
    doc["buffers"][0]["uri"] =
        format!("data:application/octet-stream;base64,{}", base64(&bin)).into();
    let text = serde_json::to_vec(&doc).unwrap();
    let mut tally = Tally::default();
    tally.check(&text, "f.gltf", "original");
    assert_eq!(tally.ok, 1);

    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for len in (0..text.len()).step_by(3) {
        tally.check(&text[..len], "f.gltf", &format!("truncate {len}"));
    }
    // The base64 payload is the last string: flip its characters, shorten it.
    let payload = text.windows(7).position(|w| w == b"base64,").unwrap() + 7;
    for case in 0..1500 {
        let mut bytes = text.clone();
        if case % 3 == 0 {
            let at = payload + rng.below(bytes.len() - payload);
            let pool = b"AZaz09+/=-_!\" ";
            bytes[at] = pool[rng.below(pool.len())];
        } else if case % 3 == 1 {
            let at = payload + rng.below(bytes.len() - payload);
            bytes.remove(at);
        } else {
            let at = rng.below(bytes.len());
            bytes[at] ^= 1 + rng.below(255) as u8;
        }
        tally.check(&bytes, "f.gltf", &format!("gltf edit {case}"));
    }
    eprintln!("glTF mutations: {} read, {} refused", tally.ok, tally.err);
    assert!(
        tally.ok > 50 && tally.err > 500,
        "{} ok, {} err",
        tally.ok,
        tally.err
    );
}
