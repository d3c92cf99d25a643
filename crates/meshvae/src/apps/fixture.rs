//! A small model trained once on a small synthetic set, shared by the applications' tests.

use crate::{ModelConfig, TrainConfig, TrainOptions, TrainRequest, TrainedModel, train};
use mesh_io::MeshSet;
use mesh_io::synth::{SynthConfig, generate};
use std::sync::OnceLock;

/// The model (2 epochs, latent 16) and its set (8 meshes of 122 vertices).
pub fn trained() -> &'static (TrainedModel, MeshSet) {
    static FIXTURE: OnceLock<(TrainedModel, MeshSet)> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let config = SynthConfig {
            meshes_per_label: 4,
            rings: 8,
            segments: 10,
            cap_rings: 2,
            ..SynthConfig::default()
        };
        let set = generate(&config).unwrap().set;
        let out = std::env::temp_dir().join(format!("meshvae-apps-{}", std::process::id()));
        let request = TrainRequest {
            set: &set,
            source: None,
            out: out.clone(),
            model: ModelConfig {
                latent: 16,
                ..ModelConfig::default()
            },
            train: TrainConfig {
                epochs: 2,
                batch: 4,
                ..TrainConfig::default()
            },
            features: Default::default(),
            hierarchy: Default::default(),
            split: None,
        };
        let options = TrainOptions {
            force: true,
            progress: false,
            ..TrainOptions::default()
        };
        train(&request, &options, |_| {}).unwrap();
        let model = TrainedModel::load(&out, &candle_core::Device::Cpu).unwrap();
        let _ = std::fs::remove_dir_all(&out);
        (model, set)
    })
}
