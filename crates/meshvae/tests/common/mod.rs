//! What the training tests share: a small synthetic set, a scratch folder, a short request.
// Each test binary compiles this module and uses only some of it.
#![allow(dead_code)]

use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::MeshSet;
use mesh_io::synth::{SynthConfig, generate};
use meshvae::{ModelConfig, TrainConfig, TrainOptions, TrainRequest};
use std::path::{Path, PathBuf};

pub fn small_set(seed: u64, rings: usize) -> MeshSet {
    generate(&SynthConfig {
        seed,
        meshes_per_label: 6,
        rings,
        segments: 10,
        cap_rings: 2,
        ..SynthConfig::default()
    })
    .expect("synthetic set")
    .set
}

pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("meshvae-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

pub fn request<'a>(set: &'a MeshSet, out: &Path, epochs: usize) -> TrainRequest<'a> {
    TrainRequest {
        set,
        source: None,
        out: out.to_path_buf(),
        model: ModelConfig {
            latent: 16,
            ..ModelConfig::default()
        },
        train: TrainConfig {
            epochs,
            batch: 4,
            seed: 11,
            ..TrainConfig::default()
        },
        features: FeatureOptions::default(),
        hierarchy: HierarchyConfig::default(),
        split: None,
    }
}

pub fn options(resume: bool, force: bool) -> TrainOptions {
    TrainOptions {
        resume,
        force,
        ..TrainOptions::default()
    }
}
