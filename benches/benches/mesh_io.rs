//! Loading a mesh set: parsing its OBJ files against reading its `.mvset` cache.
//!
//! `cargo bench -p meshvae-benches --bench mesh_io` (needs ../shared/datasets unpacked).

use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;

fn load_set(c: &mut Criterion) {
    for name in ["horse-gallop", "elephant-gallop"] {
        let Some(dir) = mesh_io::datasets::find_or_skip(name) else {
            continue;
        };
        let set = mesh_io::load_set(&dir).expect("data set loads").value;
        let cache = std::env::temp_dir().join(format!("bench-{name}-{}.mvset", std::process::id()));
        mesh_io::cache::write_cache(&cache, &set).expect("cache written");

        let mut group = c.benchmark_group(format!("load {name}"));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(8));
        group.bench_function("obj folder", |b| {
            b.iter(|| mesh_io::load_set(&dir).expect("loads").value.len())
        });
        group.bench_function("mvset cache", |b| {
            b.iter(|| mesh_io::cache::read_cache(&cache).expect("loads").len())
        });
        group.finish();
        let _ = std::fs::remove_file(&cache);
    }
}

criterion_group!(benches, load_set);
criterion_main!(benches);
