//! What the training tests share: a small synthetic set, a scratch folder, a short request.
// Each test binary compiles this module and uses only some of it.
#![allow(dead_code)]

use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::MeshSet;
use mesh_io::synth::{SynthConfig, generate};
use meshvae::{
    EpochRecord, ModelConfig, ModelFolder, TrainConfig, TrainOptions, TrainRequest, read_log,
    read_status,
};
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

/// [`request`] looking at the validation loss only every fourth step, with a short warm-up and
/// decay, and clipping (a running mean in the optimiser's state): what a resumed run must
/// restore beyond the weights.
pub fn looking_request<'a>(set: &'a MeshSet, out: &Path, epochs: usize) -> TrainRequest<'a> {
    let mut r = request(set, out, epochs);
    r.train.schedule.validate_every_steps = 4;
    r.train.schedule.warmup_steps = 4;
    r.train.schedule.decay_steps = 20;
    r.train.grad_clip = 1.0;
    r
}

/// The two model folders hold the same weights, log losses and run record, bit for bit.
pub fn assert_same_run(a: &Path, b: &Path, tag: &str) {
    let (fa, fb) = (ModelFolder::new(a), ModelFolder::new(b));
    let read = |p: PathBuf| std::fs::read(p).unwrap();
    assert!(
        read(fa.weights()) == read(fb.weights()),
        "{tag}: weights differ"
    );
    let losses = |f: &ModelFolder| {
        (read_log(&f.log()).unwrap().iter())
            .map(|r: &EpochRecord| (r.epoch, r.train_loss, r.val_loss, r.test_loss))
            .collect::<Vec<_>>()
    };
    assert_eq!(losses(&fa), losses(&fb), "{tag}: logs differ");
    let (sa, sb) = (
        read_status(&fa).unwrap().unwrap(),
        read_status(&fb).unwrap().unwrap(),
    );
    assert_eq!(
        (sa.epochs, sa.steps, sa.best_epoch, sa.stop_reason),
        (sb.epochs, sb.steps, sb.best_epoch, sb.stop_reason),
        "{tag}: run records differ"
    );
}
