//! Deformation features and reconstruction on the real data sets (skipped when absent):
//! features of all 48 elephant-gallop frames and of all horse-gallop frames (extractor built
//! beforehand), the one-off setup per rest mesh, and one elephant reconstruction solve after
//! factorisation. Run: `cargo bench -p meshvae-benches --bench features`.

use criterion::{Criterion, criterion_group, criterion_main};
use deform_features::{FeatureExtractor, FeatureOptions, Reconstructor, RestMesh};
use std::hint::black_box;
use std::time::Duration;

fn load(name: &str) -> Option<mesh_io::MeshSet> {
    let dir = mesh_io::datasets::find_or_skip(name)?;
    Some(mesh_io::load_set(&dir).ok()?.value)
}

fn features(c: &mut Criterion) {
    let mut group = c.benchmark_group("features");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(15));
    for name in ["horse-gallop", "elephant-gallop"] {
        let Some(set) = load(name) else { continue };
        for (label, integrable) in [("exact", true), ("plain", false)] {
            let options = FeatureOptions {
                integrable,
                ..Default::default()
            };
            let ex = FeatureExtractor::for_set(&set, options).expect("extractor");
            group.bench_function(format!("{name}/all {} frames/{label}", set.len()), |b| {
                b.iter(|| black_box(ex.extract(&set).expect("features")))
            });
            group.bench_function(format!("{name}/setup/{label}"), |b| {
                b.iter(|| {
                    let rest = RestMesh::new(set.frame(0), set.faces()).expect("rest");
                    black_box(FeatureExtractor::new(rest, options).expect("extractor"))
                })
            });
        }
    }
    group.finish();
}

fn reconstruct(c: &mut Criterion) {
    let mut group = c.benchmark_group("reconstruct");
    group.sample_size(20);
    let Some(set) = load("elephant-gallop") else {
        return;
    };
    let ex = FeatureExtractor::for_set(&set, FeatureOptions::default()).expect("extractor");
    let (f, _) = ex.frame_features(set.frame(20)).expect("features");
    let flat: Vec<f32> = f.iter().flatten().map(|&x| x as f32).collect();
    group.bench_function("elephant-gallop/factorize Laplacian", |b| {
        b.iter(|| black_box(Reconstructor::new(ex.rest()).expect("factorize")))
    });
    let rec = Reconstructor::new(ex.rest()).expect("factorize");
    group.bench_function(
        "elephant-gallop/one frame (exp, rhs, 3-column solve)",
        |b| b.iter(|| black_box(rec.reconstruct(&flat).expect("solve"))),
    );
    group.finish();
}

criterion_group!(benches, features, reconstruct);
criterion_main!(benches);
