//! Training on a small synthetic set: the model folder, resumption that reproduces an
//! uninterrupted run bit for bit, refusal to overwrite, evaluation and a foreign set.

use candle_core::Device;
use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::MeshSet;
use mesh_io::synth::{SynthConfig, generate};
use meshvae::{
    ModelConfig, ModelFolder, TrainConfig, TrainOptions, TrainRequest, TrainedModel, VaeError,
    read_log, train,
};
use std::path::{Path, PathBuf};

fn small_set(seed: u64, rings: usize) -> MeshSet {
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

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("meshvae-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn request<'a>(set: &'a MeshSet, out: &Path, epochs: usize) -> TrainRequest<'a> {
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

fn options(resume: bool, force: bool) -> TrainOptions {
    TrainOptions {
        resume,
        force,
        ..TrainOptions::default()
    }
}

#[test]
fn resumed_training_ends_with_the_weights_of_an_uninterrupted_run() {
    resumption_is_exact(&TrainOptions::default().best_in_memory_params, "mem");
    // Best weights written as soon as they improve (what large models do).
    resumption_is_exact(&0, "disk");
}

fn resumption_is_exact(best_in_memory_params: &usize, tag: &str) {
    let options = |resume: bool, force: bool| TrainOptions {
        best_in_memory_params: *best_in_memory_params,
        ..options(resume, force)
    };
    let set = small_set(3, 8);
    let whole = scratch(&format!("whole-{tag}"));
    let parts = scratch(&format!("parts-{tag}"));

    let summary = train(&request(&set, &whole, 4), &options(false, false), |_| {}).unwrap();
    assert_eq!(summary.epochs_run, 4);

    // "Interrupted" after two epochs, then resumed to four. A killed run may have logged an
    // epoch after its last checkpoint: resumption replays it.
    train(&request(&set, &parts, 2), &options(false, false), |_| {}).unwrap();
    let log = ModelFolder::new(&parts).log();
    let mut text = std::fs::read_to_string(&log).unwrap();
    text.push_str(
        &text
            .lines()
            .last()
            .unwrap()
            .replace("\"epoch\":2", "\"epoch\":3"),
    );
    text.push('\n');
    std::fs::write(&log, text).unwrap();
    let resumed = train(&request(&set, &parts, 4), &options(true, false), |_| {}).unwrap();
    assert_eq!(resumed.epochs_run, 2);

    let a = std::fs::read(ModelFolder::new(&whole).checkpoint()).unwrap();
    let b = std::fs::read(ModelFolder::new(&parts).checkpoint()).unwrap();
    assert!(a == b, "checkpoints differ after resumption");
    let a = std::fs::read(ModelFolder::new(&whole).weights()).unwrap();
    let b = std::fs::read(ModelFolder::new(&parts).weights()).unwrap();
    assert!(a == b, "best weights differ after resumption");
    let log_a = read_log(&ModelFolder::new(&whole).log()).unwrap();
    let log_b = read_log(&ModelFolder::new(&parts).log()).unwrap();
    assert_eq!(log_a.len(), 4);
    for (x, y) in log_a.iter().zip(&log_b) {
        assert_eq!(
            (x.epoch, x.train_loss, x.test_loss),
            (y.epoch, y.train_loss, y.test_loss)
        );
    }
    // Loss goes down on this easy set.
    assert!(log_a[3].train_loss < log_a[0].train_loss, "{log_a:?}");

    // A resumed run that is already complete does nothing.
    let again = train(&request(&set, &parts, 4), &options(true, false), |_| {}).unwrap();
    assert_eq!(again.epochs_run, 0);

    // Resuming with other settings is refused, naming what differs.
    let mut other = request(&set, &parts, 5);
    other.train.lr = 0.01;
    let err = train(&other, &options(true, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("training settings"), "{err}");

    let _ = std::fs::remove_dir_all(&whole);
    let _ = std::fs::remove_dir_all(&parts);
}

#[test]
fn model_folder_is_complete_refuses_overwrite_and_evaluates() {
    let set = small_set(5, 8);
    let out = scratch("folder");
    train(&request(&set, &out, 2), &options(false, false), |_| {}).unwrap();
    let folder = ModelFolder::new(&out);
    for path in [
        folder.config(),
        folder.hierarchy(),
        folder.normalization(),
        folder.split(),
        folder.template(),
        folder.weights(),
        folder.checkpoint(),
        folder.log(),
    ] {
        assert!(path.is_file(), "missing {}", path.display());
    }

    let err = train(&request(&set, &out, 2), &options(false, false), |_| {}).unwrap_err();
    assert!(matches!(err, VaeError::Model { .. }), "{err}");
    assert!(err.to_string().contains("already holds a model"), "{err}");
    train(&request(&set, &out, 1), &options(false, true), |_| {}).unwrap();

    let trained = TrainedModel::load(&out, &Device::Cpu).unwrap();
    let report = trained.evaluate(&set, &Device::Cpu).unwrap();
    assert_eq!(report.test.meshes + report.train.meshes, set.len());
    assert!(report.test.rms.is_finite() && report.test.rms > 0.0);
    assert!((report.test.rms_x1000 - 1000.0 * report.test.rms).abs() < 1e-9);
    assert_eq!(report.params, trained.model.param_count());

    // Another connectivity is a clear error.
    let foreign = small_set(5, 9);
    let err = trained.evaluate(&foreign, &Device::Cpu).unwrap_err();
    assert!(err.to_string().contains("vertices"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn not_a_model_folder_and_bad_settings_are_typed_errors() {
    let missing = scratch("missing");
    let err = TrainedModel::load(&missing, &Device::Cpu).unwrap_err();
    assert!(err.to_string().contains("not a model folder"), "{err}");

    let set = small_set(3, 8);
    let out = scratch("bad");
    let mut bad = request(&set, &out, 1);
    bad.train.batch = 0;
    assert!(train(&bad, &options(false, false), |_| {}).is_err());
    let mut bad = request(&set, &out, 1);
    bad.train.lr = f64::NAN;
    let err = train(&bad, &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("lr"), "{err}");
    let err = train(&request(&set, &out, 0), &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("epochs"), "{err}");
    // A bad model setting is refused before anything is written.
    let mut bad = request(&set, &out, 1);
    bad.model.latent = 0;
    let err = train(&bad, &options(false, false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("latent"), "{err}");
    assert!(
        !ModelFolder::new(&out).has_model(),
        "a refused run left a config.json"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_non_finite_loss_stops_training_with_a_message() {
    let set = small_set(3, 8);
    let out = scratch("nan");
    let mut req = request(&set, &out, 3);
    // The weighted reconstruction term overflows f32: the loss is infinite at the first step.
    req.train.loss.rec = 1e38;
    let err = train(&req, &options(false, false), |_| {}).unwrap_err();
    assert!(matches!(err, VaeError::Diverged(_)), "{err}");
    let text = err.to_string();
    assert!(text.contains("epoch 1") && text.contains("inf"), "{text}");
    assert!(!ModelFolder::new(&out).weights().exists());
    let _ = std::fs::remove_dir_all(&out);
}
