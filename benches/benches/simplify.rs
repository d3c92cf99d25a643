//! Simplifying elephant-gallop's template (42,321 vertices) to half its vertices: qem-simplify
//! (λ = 0.001 and classical λ = 0) side by side with meshoptimizer's simplifier at the same
//! target, and isotropic remeshing (`qem_simplify::remesh`, the paper's "uniform remeshing"
//! ablation) to the same 21,161 vertices, plus each result's edge-length CV (and, for ours, the
//! geometric error), printed before the timings.
//!
//! `cargo bench -p meshvae-benches --bench simplify` (skips, saying so, without the data set).
//! qem-simplify's set-up (edge table, initial costs) runs on rayon's threads, its contraction
//! loop on one; the remesher's relaxation, projection and flip checks run on rayon's threads,
//! its splits, collapses and flips on one; meshopt is single-threaded. `RAYON_NUM_THREADS=1` gives the one-thread figure.

// glibc returns each large buffer to the kernel when it is freed, so every call pays ~3,000
// page faults for fresh memory; the benches use mimalloc, as the `meshvae` binary does.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use criterion::{Criterion, criterion_group, criterion_main};
use mesh_io::TriMesh;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use qem_simplify::{
    RemeshConfig, SimplifyConfig, Target, edge_length_cv, geometric_error_rel, remesh, simplify,
};
use std::hint::black_box;

/// meshopt's result as an index buffer into the fine vertices.
fn meshopt_simplify(mesh: &TriMesh, target_vertices: usize, options: SimplifyOptions) -> Vec<u32> {
    let indices: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
    let bytes: Vec<u8> = mesh
        .positions
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let adapter = VertexDataAdapter::new(&bytes, 12, 0).expect("12-byte vertices");
    // A closed mesh loses two faces per vertex: the same target expressed in indices.
    let removed = mesh.vertex_count() - target_vertices;
    let target_faces = mesh.face_count().saturating_sub(2 * removed);
    // Error bound 1 (the whole extent): only the count stops it.
    meshopt::simplify(&indices, &adapter, 3 * target_faces, 1.0, options, None)
}

/// The thread count rayon's global pool will use (its documented environment variable, else
/// the available parallelism); printed only.
fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|&n| n > 0)
        .or_else(|| std::thread::available_parallelism().ok().map(|n| n.get()))
        .unwrap_or(1)
}

fn faces_of(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

fn used_vertices(indices: &[u32]) -> usize {
    let mut v = indices.to_vec();
    v.sort_unstable();
    v.dedup();
    v.len()
}

fn bench_simplify(c: &mut Criterion) {
    let Some(dir) = mesh_io::datasets::find_or_skip("elephant-gallop") else {
        return;
    };
    let fine = match mesh_io::load_set(&dir) {
        Ok(loaded) => loaded.value.template(),
        Err(e) => {
            eprintln!("SKIPPED: {e}");
            return;
        }
    };
    let target = fine.vertex_count().div_ceil(2);
    let config = |lambda| SimplifyConfig {
        target: Target::Ratio(0.5),
        lambda,
    };

    println!(
        "elephant-gallop template: {} vertices, {} faces -> {target} vertices; {} rayon threads",
        fine.vertex_count(),
        fine.face_count(),
        rayon_threads()
    );
    println!(
        "input edge_cv {:.4}",
        edge_length_cv(&fine.positions, &fine.faces)
    );
    for lambda in [0.001, 0.0] {
        let s = simplify(&fine, &config(lambda)).expect("simplifies");
        println!(
            "qem-simplify lambda={lambda}: {} vertices, {} faces, edge_cv {:.4}, \
             geometric_error_rel {:.2e}",
            s.coarse.vertex_count(),
            s.coarse.face_count(),
            edge_length_cv(&s.coarse.positions, &s.coarse.faces),
            geometric_error_rel(&fine, &s.coarse)
        );
    }
    let r = remesh(&fine, &RemeshConfig::default()).expect("remeshes");
    println!(
        "remesh: {} vertices, {} faces, edge_cv {:.4}, geometric_error_rel {:.2e}",
        r.coarse.vertex_count(),
        r.coarse.face_count(),
        edge_length_cv(&r.coarse.positions, &r.coarse.faces),
        geometric_error_rel(&fine, &r.coarse)
    );
    for (name, options) in [
        ("meshopt", SimplifyOptions::None),
        ("meshopt Regularize", SimplifyOptions::Regularize),
    ] {
        let indices = meshopt_simplify(&fine, target, options);
        println!(
            "{name}: {} vertices, {} faces, edge_cv {:.4}",
            used_vertices(&indices),
            indices.len() / 3,
            edge_length_cv(&fine.positions, &faces_of(&indices))
        );
    }

    let mut group = c.benchmark_group("simplify elephant-gallop to half");
    group.sample_size(10);
    group.bench_function("qem-simplify lambda=0.001", |b| {
        b.iter(|| simplify(black_box(&fine), &config(0.001)).expect("simplifies"))
    });
    group.bench_function("qem-simplify lambda=0", |b| {
        b.iter(|| simplify(black_box(&fine), &config(0.0)).expect("simplifies"))
    });
    group.bench_function("remesh", |b| {
        b.iter(|| remesh(black_box(&fine), &RemeshConfig::default()).expect("remeshes"))
    });
    group.bench_function("meshopt", |b| {
        b.iter(|| meshopt_simplify(black_box(&fine), target, SimplifyOptions::None))
    });
    group.bench_function("meshopt Regularize", |b| {
        b.iter(|| meshopt_simplify(black_box(&fine), target, SimplifyOptions::Regularize))
    });
    group.finish();
}

criterion_group!(benches, bench_simplify);
criterion_main!(benches);
