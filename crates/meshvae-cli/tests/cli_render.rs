//! `meshvae render`: pictures of the asked size, sheets, error colouring, and clean failures.

mod common;

use common::{meshvae, scratch};
use mesh_io::synth::{self, SynthConfig};
use mesh_io::{MeshSet, TriMesh};
use mesh_render::Image;
use std::path::{Path, PathBuf};
use std::process::Output;

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn assert_ok(out: &Output) {
    assert!(out.status.success(), "stderr: {}", stderr(out));
}

/// A failure (exit code ≥ 1, no panic) whose message contains every one of `parts`.
fn assert_fails_with(out: &Output, parts: &[&str]) {
    let err = stderr(out);
    assert!(!out.status.success(), "expected failure; stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    for p in parts {
        assert!(err.contains(p), "stderr lacks {p:?}: {err}");
    }
}

/// A small synthetic set (6 capsules of 242 vertices) written as OBJ files into `dir/name`.
fn small_set(dir: &Path, name: &str) -> (PathBuf, MeshSet) {
    let config = SynthConfig {
        meshes_per_label: 3,
        rings: 8,
        segments: 12,
        cap_rings: 2,
        ..SynthConfig::default()
    };
    let set = synth::generate(&config).unwrap().set;
    let folder = dir.join(name);
    std::fs::create_dir_all(&folder).unwrap();
    mesh_io::write_folder(&folder, &set).unwrap();
    (folder, set)
}

fn write_obj(path: &Path, positions: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) {
    mesh_io::write_mesh(path, &TriMesh { positions, faces }).unwrap();
}

fn pngs_in(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains(".png"))
        .collect()
}

#[test]
fn one_mesh_gives_one_picture_of_the_asked_size() {
    let dir = scratch("render-one");
    let (_, set) = small_set(&dir, "set");
    let mesh = dir.join("capsule.obj");
    write_obj(&mesh, set.frame(1).to_vec(), set.faces().to_vec());
    let out = dir.join("capsule.png");
    let run = meshvae(&[
        "render",
        mesh.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--view",
        "left",
        "--size",
        "120",
    ]);
    assert_ok(&run);
    let image = Image::load_png(&out).unwrap();
    assert_eq!((image.width, image.height), (120, 120));
    let drawn = image.rgb.chunks_exact(3).filter(|p| p != &[255; 3]).count();
    assert!(drawn > 120 * 120 / 20, "{drawn} pixels drawn");
    assert_eq!(image.pixel(0, 0), Some([255; 3]));
}

#[test]
fn a_folder_gives_a_captioned_sheet_and_errors_add_a_colour_bar() {
    let dir = scratch("render-sheet");
    let (folder, set) = small_set(&dir, "set");
    let out = dir.join("sheet.png");
    let run = meshvae(&[
        "render",
        folder.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "64",
        "--columns",
        "4",
    ]);
    assert_ok(&run);
    let sheet = Image::load_png(&out).unwrap();
    // Tiles shaped like the set's shared frame, seen from the side its rest mesh picks.
    let frames: Vec<&[[f32; 3]]> = set.frames().collect();
    let view = mesh_render::View::Auto.for_set(set.frame(0));
    let (tile_w, tile_h) = mesh_render::Bounds::of(&frames).unwrap().fit(view, 64);
    assert!(tile_w <= 64 && tile_h <= 64 && tile_w.max(tile_h) == 64);
    let cell_h = tile_h + mesh_render::caption_height(tile_w);
    assert_eq!((sheet.width, sheet.height), (4 * tile_w, 2 * cell_h));

    // The same set moved by 0.1 along x: every vertex is 0.1 from its ground truth.
    let moved: Vec<TriMesh> = (0..set.len())
        .map(|i| TriMesh {
            positions: set
                .frame(i)
                .iter()
                .map(|p| [p[0] + 0.1, p[1], p[2]])
                .collect(),
            faces: set.faces().to_vec(),
        })
        .collect();
    let moved = MeshSet::from_meshes(moved, set.names().to_vec()).unwrap();
    let moved_dir = dir.join("moved");
    std::fs::create_dir_all(&moved_dir).unwrap();
    mesh_io::write_folder(&moved_dir, &moved).unwrap();
    let out = dir.join("errors.png");
    let run = meshvae(&[
        "render",
        moved_dir.to_str().unwrap(),
        "--errors-against",
        folder.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "64",
        "--columns",
        "3",
        "--max-error",
        "0.1",
    ]);
    assert_ok(&run);
    assert!(String::from_utf8_lossy(&run.stdout).contains("largest error 0.100"));
    let image = Image::load_png(&out).unwrap();
    assert!(
        image.height > 2 * cell_h + 30 && image.width >= 3 * tile_w,
        "a colour bar heads the sheet: {}x{}",
        image.width,
        image.height
    );
    // The band on top holds the bar's hottest colour; the sheet below starts after it.
    let hot = mesh_render::error_color(1.0);
    let top = image.height - 2 * cell_h;
    assert!(
        (0..top).any(|y| (0..image.width).any(|x| image
            .pixel(x, y)
            .is_some_and(|c| (0..3).all(|k| c[k].abs_diff(hot[k]) <= 6)))),
        "no colour bar in the top {top} rows"
    );
    // Every error is at the top of the scale: the meshes are dark red, not grey.
    let red = image
        .rgb
        .chunks_exact(3)
        .filter(|p| u16::from(p[0]) > 2 * u16::from(p[1].max(p[2]).max(8)))
        .count();
    assert!(red > 6 * 64 * 64 / 30, "{red} red pixels");
}

#[test]
fn bad_arguments_fail_clearly_and_write_nothing() {
    let dir = scratch("render-errors");
    let (folder, set) = small_set(&dir, "set");
    let mesh = dir.join("a.obj");
    write_obj(&mesh, set.frame(0).to_vec(), set.faces().to_vec());
    // A ground truth with a different vertex count (one vertex dropped, faces kept in range).
    let other = dir.join("other.obj");
    let n = set.vertex_count() as u32 - 1;
    let faces: Vec<[u32; 3]> = set
        .faces()
        .iter()
        .filter(|f| f.iter().all(|&i| i < n))
        .copied()
        .collect();
    write_obj(&other, set.frame(0)[..n as usize].to_vec(), faces);
    let png = dir.join("out.png");
    let no_dir = dir.join("no-dir/x.png");
    let (mesh_s, png_s) = (mesh.to_str().unwrap(), png.to_str().unwrap());
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec![mesh_s, "--out", "picture.jpg"],
            vec!["--out", "picture.jpg", ".png"],
        ),
        (
            vec!["no-such-mesh.obj", "--out", png_s],
            vec!["no-such-mesh.obj"],
        ),
        (
            vec![
                mesh_s,
                "--out",
                png_s,
                "--errors-against",
                other.to_str().unwrap(),
            ],
            vec!["--errors-against", "other.obj", "vertices"],
        ),
        (vec![mesh_s, "--out", png_s, "--size", "0"], vec!["--size"]),
        (
            vec![folder.to_str().unwrap(), "--out", png_s, "--columns", "0"],
            vec!["--columns"],
        ),
        (
            vec![
                mesh_s,
                "--out",
                png_s,
                "--errors-against",
                mesh_s,
                "--max-error=-1",
            ],
            vec!["--max-error"],
        ),
        (
            vec![mesh_s, "--out", png_s, "--max-error", "1"],
            vec!["--errors-against"],
        ),
        (
            vec![mesh_s, "--out", png_s, "--view", "sideways"],
            vec!["sideways"],
        ),
        (
            vec![mesh_s, "--out", png_s, "--size", "100000"],
            vec!["100000"],
        ),
        (
            vec![mesh_s, "--out", no_dir.to_str().unwrap()],
            vec!["no-dir"],
        ),
    ];
    for (args, parts) in cases {
        let mut all = vec!["render"];
        all.extend(&args);
        let out = meshvae(&all);
        assert_fails_with(&out, &parts);
        assert!(pngs_in(&dir).is_empty(), "{args:?} left a PNG");
    }
}
