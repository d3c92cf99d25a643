//! meshvae: one training step (forward, loss, backward, Adam) of the paper's network (CCPC,
//! spectral, mean pooling, K = 3, 9 channels, latent 128) at batch 32, f32, on the horse-gallop
//! (8,431 vertices) and elephant-gallop (42,321 vertices) templates, with random features in
//! (−0.95, 0.95): the step's cost does not depend on the values.
//!
//! Two functions: the step `meshvae::train` runs (the hand-written `Engine`), and candle's
//! autograd path (the reference, and the fallback for models the engine declines).
//!
//! `cargo bench -p meshvae-benches --bench train` (needs ../shared/datasets unpacked).

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use candle_core::{Device, Tensor};
use criterion::{Criterion, criterion_group, criterion_main};
use mesh_hierarchy::Hierarchy;
use meshvae::{Adam, EngineExecutor, LossWeights, MeshVae, ModelConfig, Rng};
use std::time::Duration;

const BATCH: usize = 32;

fn step(c: &mut Criterion) {
    for name in ["horse-gallop", "elephant-gallop"] {
        let Some(dir) = mesh_io::datasets::find_or_skip(name) else {
            continue;
        };
        let set = mesh_io::load_set(&dir).expect("set loads").value;
        let config = ModelConfig::default();
        let hierarchy =
            Hierarchy::build(&set.template(), &config.hierarchy_config()).expect("hierarchy");
        let device = Device::Cpu;
        let model = MeshVae::new(&config, &hierarchy, &device, 1).expect("model");
        let mut adam = Adam::new(model.trainable_vars(), 1e-3).expect("adam");
        let mut rng = Rng::new(7);
        let v = set.vertex_count();
        let data: Vec<f32> = (0..BATCH * v * 9)
            .map(|_| (rng.uniform() * 1.9 - 0.95) as f32)
            .collect();
        let x = Tensor::from_vec(data, (BATCH, v, 9), &device).expect("batch");
        let weights = LossWeights::default();

        let mut group = c.benchmark_group(format!("train step {name} ({v} vertices)"));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(10));
        let mut engine =
            EngineExecutor::new(&model, BATCH).expect("the engine covers the paper's network");
        group.bench_function("batch 32, f32: engine (what train() runs)", |b| {
            b.iter(|| {
                let eps = rng
                    .normal_tensor((BATCH, config.latent), &device)
                    .expect("eps");
                engine
                    .forward_backward(&model, &x, None, &eps, &weights)
                    .expect("step");
                engine.apply_adam(&mut adam, weights.l2).expect("adam");
            })
        });
        drop(engine);
        group.bench_function("batch 32, f32: candle autograd", |b| {
            b.iter(|| {
                let eps = rng
                    .normal_tensor((BATCH, config.latent), &device)
                    .expect("eps");
                // As `meshvae::train` does without the engine: Adam applies the L2 gradient.
                let loss = model.training_loss(&x, None, &eps, &weights).expect("loss");
                let grads = model.backward(&loss.total).expect("backward");
                adam.step_with_l2(&grads, weights.l2).expect("adam");
            })
        });
        group.finish();
    }
}

criterion_group!(benches, step);
criterion_main!(benches);
