//! The applications on real data: horse-gallop's 48 frames are one gallop cycle, so their
//! embeddings in frame order must trace a closed loop (see `meshvae::LoopMeasure` for the
//! measure and its thresholds).

use candle_core::Device;
use mesh_io::datasets;
use meshvae::{
    EmbedOptions, GenerateOptions, ModelConfig, Schedule, TrainConfig, TrainOptions, TrainRequest,
    TrainedModel, loop_measure,
};

/// Epochs of the brief training: the encoder means already follow the gait (latent measure at
/// 5 epochs: all steps shorter than the median pair, closing 0.35 median steps; at 20: 0.15),
/// and the test takes about 35 s in the debug build on 2 shared cores.
const EPOCHS: usize = 5;

#[test]
fn horse_gallop_embeddings_are_closed_loops() {
    let Some(dir) = datasets::find_or_skip("horse-gallop") else {
        return;
    };
    let set = mesh_io::load_set(&dir).unwrap().value;
    assert_eq!(set.len(), 48);
    let out = std::env::temp_dir().join(format!("e2e-apps-horse-{}", std::process::id()));
    let request = TrainRequest {
        set: &set,
        source: Some(dir.clone()),
        out: out.clone(),
        model: ModelConfig {
            latent: 32,
            ..ModelConfig::default()
        },
        train: TrainConfig {
            epochs: EPOCHS,
            batch: 24,
            // The rate, constant schedule and min–max feature ranges the thresholds were
            // measured with.
            lr: 1e-3,
            schedule: Schedule::constant(),
            normalize_quantile: 0.0,
            ..TrainConfig::default()
        },
        features: Default::default(),
        hierarchy: Default::default(),
        split: None,
    };
    let options = TrainOptions {
        force: true,
        // One checkpoint, after the last epoch.
        checkpoint_seconds: 1e9,
        ..TrainOptions::default()
    };
    meshvae::train(&request, &options, |_| {}).unwrap();
    let model = TrainedModel::load(&out, &Device::Cpu).unwrap();

    let embedding = meshvae::embed(
        &model,
        &set,
        &EmbedOptions {
            iterations: 500,
            ..EmbedOptions::default()
        },
    )
    .unwrap();
    let latent = loop_measure(&embedding.latent_2d).unwrap();
    let pca = loop_measure(&embedding.pca_2d).unwrap();
    eprintln!("latent {latent:?}, PCA {pca:?}");
    assert!(latent.is_loop(), "latent embedding: {latent:?}");
    assert!(pca.is_loop(), "PCA embedding: {pca:?}");

    // The frames scrambled are no loop: the measure sees the order, not only the shape.
    let mut order: Vec<usize> = (0..48).collect();
    meshvae::Rng::new(5).shuffle(&mut order);
    let scrambled: Vec<[f64; 2]> = order.iter().map(|&i| embedding.pca_2d[i]).collect();
    assert!(!loop_measure(&scrambled).unwrap().is_loop());

    // Generation on the real set: finite meshes, nearest training meshes from the split.
    let g = meshvae::generate(&model, &set, &GenerateOptions { count: 3, seed: 2 }).unwrap();
    for (p, nb) in g.positions.iter().zip(&g.nearest) {
        assert_eq!(p.len(), set.vertex_count());
        assert!(p.iter().flatten().all(|x| x.is_finite()));
        assert!(model.split.train.contains(&nb.index));
    }
    let _ = std::fs::remove_dir_all(&out);
}
