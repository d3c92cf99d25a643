//! The `meshvae` binary on good and bad mesh sets: counts, messages, exit codes.

mod common;

use common::{meshvae, scratch};
use mesh_io::datasets;
use std::path::Path;
use std::process::Output;

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts a failure with a message on stderr that contains every one of `parts`, and no panic.
fn assert_fails_with(out: &Output, parts: &[&str]) {
    let err = stderr(out);
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr: {err}"
    );
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    for p in parts {
        assert!(err.contains(p), "stderr lacks {p:?}: {err}");
    }
}

const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n";

fn write(dir: &Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

#[test]
fn info_json_counts_on_the_real_sets() {
    for &(name, meshes, vertices, faces, boundary) in datasets::KNOWN {
        let Some(dir) = datasets::find_or_skip(name) else {
            continue;
        };
        let out = meshvae(&["info", dir.to_str().unwrap(), "--json"]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(json["meshes"], meshes, "{name}");
        assert_eq!(json["vertices"], vertices, "{name}");
        assert_eq!(json["faces"], faces, "{name}");
        assert_eq!(json["boundary_edges"], boundary, "{name}");
        assert_eq!(json["nonmanifold_edges"], 0, "{name}");
        assert_eq!(json["labels"], serde_json::Value::Null, "{name}");
        assert!(json["bbox_diagonal"].as_f64().unwrap() > 1.0, "{name}");
    }
}

#[test]
fn mixed_connectivity_names_the_first_mismatching_file() {
    let (Some(horse), Some(samba)) = (
        datasets::find_or_skip("horse-gallop"),
        datasets::find_or_skip("samba"),
    ) else {
        return;
    };
    let dir = scratch("mixed");
    for src in [&horse, &samba] {
        for entry in std::fs::read_dir(src).unwrap() {
            let path = entry.unwrap().path();
            std::os::unix::fs::symlink(&path, dir.join(path.file_name().unwrap())).unwrap();
        }
    }
    // Natural order puts 0001.obj … 0048.obj (horse) before mesh_0000.obj (samba).
    let out = meshvae(&["info", dir.to_str().unwrap()]);
    assert_fails_with(
        &out,
        &["mesh_0000.obj", "9971 vertices", "0001.obj has 8431"],
    );
}

#[test]
fn broken_files_give_clear_messages() {
    let cases: [(&str, &str, &[&str]); 5] = [
        (
            "truncated",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3",
            &["b.obj:6:", "2 vertices"],
        ),
        (
            "nan",
            "v 0 0 0\nv nan 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n",
            &["b.obj:2:", "non-finite"],
        ),
        (
            "index",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 9\n",
            &["b.obj:6:", "index 9", "4 vertices"],
        ),
        (
            "faces",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 3\n",
            &["b.obj", "face 1", "a.obj"],
        ),
        ("garbage", "v 0 0 zero\n", &["b.obj:1:", "bad coordinate"]),
    ];
    for (name, text, parts) in cases {
        let dir = scratch(name);
        write(&dir, "a.obj", TRI);
        write(&dir, "b.obj", text);
        let out = meshvae(&["info", dir.to_str().unwrap()]);
        assert_fails_with(&out, parts);
    }
}

#[test]
fn empty_and_missing_sets() {
    let dir = scratch("empty");
    assert_fails_with(
        &meshvae(&["info", dir.to_str().unwrap()]),
        &["no mesh files"],
    );
    write(&dir, "a.obj", TRI);
    assert_fails_with(
        &meshvae(&["info", dir.to_str().unwrap()]),
        &["at least two meshes"],
    );
    let missing = dir.join("nowhere");
    assert_fails_with(&meshvae(&["info", missing.to_str().unwrap()]), &["nowhere"]);
}

#[test]
fn pack_then_info_reads_the_cache() {
    let dir = scratch("pack");
    write(&dir, "1.obj", TRI);
    write(&dir, "2.obj", &TRI.replace("v 0 0 1", "v 0 0 2"));
    write(&dir, "labels.csv", "file,label\n1.obj,rest\n2.obj,up\n");
    let cache = dir.join("set.mvset");
    let out = meshvae(&[
        "pack",
        dir.to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = meshvae(&["info", cache.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["meshes"], 2);
    assert_eq!(json["vertices"], 4);
    assert_eq!(json["boundary_edges"], 4);
    assert_eq!(json["labels"], serde_json::json!(["rest", "up"]));
    // The same set as one GLB (frames as morph targets) reads back with the same report.
    let glb = dir.join("set.glb");
    let out = meshvae(&[
        "pack",
        cache.to_str().unwrap(),
        "--out",
        glb.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = meshvae(&["info", glb.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let again: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(again, json);
    let bad = dir.join("set.txt");
    assert_fails_with(
        &meshvae(&[
            "pack",
            cache.to_str().unwrap(),
            "--out",
            bad.to_str().unwrap(),
        ]),
        &["--out", "set.txt", ".mvset or .glb"],
    );
    assert!(!bad.exists());
    // One flipped bit in the positions (a coordinate that stays finite) is caught by the
    // checksum, naming the file; so is garbage.
    let mut bytes = std::fs::read(&cache).unwrap();
    let header = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    bytes[8 + header + 2] ^= 0x01;
    std::fs::write(&cache, &bytes).unwrap();
    assert_fails_with(
        &meshvae(&["info", cache.to_str().unwrap()]),
        &["set.mvset", "checksum"],
    );
    std::fs::write(&cache, b"garbage").unwrap();
    assert_fails_with(&meshvae(&["info", cache.to_str().unwrap()]), &["set.mvset"]);
}

#[test]
fn a_full_disk_on_standard_output_is_an_error_not_a_panic() {
    let full = Path::new("/dev/full");
    if !full.exists() {
        eprintln!("skipped: this system has no /dev/full");
        return;
    }
    let dir = scratch("devfull");
    write(&dir, "a.obj", TRI);
    write(&dir, "b.obj", TRI);
    for json in [false, true] {
        let mut args = vec!["info", dir.to_str().unwrap()];
        if json {
            args.push("--json");
        }
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_meshvae"))
            .args(&args)
            .stdout(std::fs::File::create(full).unwrap())
            .output()
            .unwrap();
        assert_fails_with(&out, &["cannot write to standard output"]);
    }
}
