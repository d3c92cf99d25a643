//! Helpers shared by the acceptance tests: test meshes, fields, comparisons, references.
#![allow(dead_code)] // each test file uses some of them

use mesh_hierarchy::{DepoolMode, Hierarchy, HierarchyConfig, Pooler};
use mesh_io::TriMesh;
use qem_simplify::shapes::{bumpy_grid, icosphere, torus};

pub fn meshes() -> Vec<TriMesh> {
    vec![icosphere(2), torus(12, 8, 1.0, 0.3), bumpy_grid(12, 10)]
}

pub fn config(pooler: Pooler, levels: usize) -> HierarchyConfig {
    HierarchyConfig {
        pooler,
        levels,
        ..Default::default()
    }
}

/// A deterministic, non-constant field.
pub fn field(n: usize, channels: usize) -> Vec<f64> {
    (0..n * channels)
        .map(|i| ((i * 37 % 101) as f64 - 50.0) / 7.0)
        .collect()
}

pub fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

pub fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("mesh-hierarchy-{}-{name}", std::process::id()))
}

/// Writes `h` as a version-1 file, exactly as `Hierarchy::save` did before version 2 (JSON).
pub fn write_json_v1(h: &Hierarchy, path: &std::path::Path) {
    #[derive(serde::Serialize)]
    struct FileOut<'a> {
        format: &'a str,
        version: u32,
        hierarchy: &'a Hierarchy,
    }
    let out = FileOut {
        format: "meshvae-hierarchy",
        version: 1,
        hierarchy: h,
    };
    std::fs::write(path, serde_json::to_vec(&out).unwrap()).unwrap();
}

/// Dense P (mean) and D (copy or Pᵀ) built from `cluster_of` alone.
pub fn dense_reference(cluster_of: &[u32], m: usize, mode: DepoolMode) -> [Vec<Vec<f64>>; 2] {
    let n = cluster_of.len();
    let mut size = vec![0.0; m];
    for &c in cluster_of {
        size[c as usize] += 1.0;
    }
    let mut p = vec![vec![0.0; n]; m];
    let mut d = vec![vec![0.0; m]; n];
    for (v, &c) in cluster_of.iter().enumerate() {
        let c = c as usize;
        p[c][v] = 1.0 / size[c];
        d[v][c] = match mode {
            DepoolMode::Copy => 1.0,
            DepoolMode::Transpose => 1.0 / size[c],
        };
    }
    [p, d]
}

/// A deterministic field whose values are (almost surely) distinct, so that a max pooling's
/// selection does not change under a small perturbation.
pub fn distinct_field(len: usize) -> Vec<f64> {
    (0..len)
        .map(|i| ((i as f64 * 12.9898 + 0.5).sin() * 43_758.545).fract())
        .collect()
}

/// Central differences (f64, step h) of x ↦ ⟨g, f(x)⟩.
pub fn central_differences(
    f: impl Fn(&[f64]) -> Vec<f64>,
    x: &[f64],
    g: &[f64],
    h: f64,
) -> Vec<f64> {
    let dot = |y: Vec<f64>| y.iter().zip(g).map(|(a, b)| a * b).sum::<f64>();
    let mut x = x.to_vec();
    (0..x.len())
        .map(|i| {
            let keep = x[i];
            x[i] = keep + h;
            let up = dot(f(&x));
            x[i] = keep - h;
            let down = dot(f(&x));
            x[i] = keep;
            (up - down) / (2.0 * h)
        })
        .collect()
}
