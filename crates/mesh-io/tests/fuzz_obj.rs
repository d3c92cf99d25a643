//! Thousands of mutated and truncated OBJ files: each parse returns a valid mesh or an error,
//! never a panic.

mod common;
use common::Rng;

use mesh_io::TriMesh;
use mesh_io::obj::{parse_obj, write_obj_to};
use std::path::Path;

fn grid_obj() -> Vec<u8> {
    let n = 7;
    let positions = (0..n * n)
        .map(|i| {
            [
                (i % n) as f32 * 0.37,
                (i / n) as f32 * 1.1,
                ((i * 7) % 5) as f32 / 3.0,
            ]
        })
        .collect();
    let mut faces = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let i = (y * n + x) as u32;
            let n = n as u32;
            faces.push([i, i + 1, i + n + 1]);
            faces.push([i, i + n + 1, i + n]);
        }
    }
    let mut text = Vec::new();
    write_obj_to(&mut text, &TriMesh { positions, faces }).unwrap();
    // Exercise the other index forms and a quad too.
    text.extend_from_slice(b"vt 0 0\nvn 0 0 1\nf 1/1/1 2//1 9/1\nf -1 -2 -3 -4\n");
    text
}

const TOKENS: &[&[u8]] = &[
    b"v ",
    b"f ",
    b"nan",
    b"inf",
    b"-",
    b"/",
    b"//",
    b"0",
    b"4294967296",
    b"-99999999999",
    b"\n",
    b" ",
    b"1e39",
    b"\xff\xfe",
    b"#",
    b"vt",
    b"f 1 2 3 4 5 6\n",
    b"\r\n",
];

fn check(bytes: &[u8]) {
    let path = Path::new("fuzz.obj");
    if let Ok(loaded) = parse_obj(bytes, path) {
        loaded.value.validate(path).expect("a parsed mesh is valid");
    }
}

#[test]
fn mutated_obj_files_never_panic() {
    let base = grid_obj();
    check(&base);
    assert!(parse_obj(&base, Path::new("base.obj")).is_ok());
    // Every truncation of the first part of the file.
    for cut in 0..base.len().min(600) {
        check(&base[..cut]);
    }
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for _ in 0..4000 {
        let mut bytes = base.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(bytes.len());
            match rng.below(5) {
                0 => bytes[at] = rng.next() as u8,
                1 => {
                    bytes.remove(at);
                }
                2 => {
                    let t = TOKENS[rng.below(TOKENS.len())];
                    bytes.splice(at..at, t.iter().copied());
                }
                3 => bytes.truncate(at),
                _ => {
                    if bytes[at].is_ascii_digit() {
                        bytes[at] = b'0' + rng.below(10) as u8;
                    }
                }
            }
            if bytes.is_empty() {
                break;
            }
        }
        check(&bytes);
    }
}
