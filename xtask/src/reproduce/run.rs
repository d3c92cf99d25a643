//! One run: train (resuming a model folder left by an interrupted run), evaluate, and record the
//! numbers in a small JSON beside the model folder. A run whose JSON exists is not repeated.

use super::ReproError;
use super::plan::Run;
use candle_core::Device;
use mesh_io::MeshSet;
use meshvae::{ModelConfig, ModelFolder, TrainOptions, TrainRequest, TrainedModel};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a finished run records (`<column>.result.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    pub dataset: String,
    pub protocol: String,
    pub column: String,
    pub seed: u64,
    pub epochs: usize,
    pub model: ModelConfig,
    /// Vertex count of every hierarchy level the network uses (template first).
    pub levels: Vec<usize>,
    pub test_meshes: usize,
    pub train_meshes: usize,
    /// Meshes held out of training to choose the checkpoint.
    #[serde(default)]
    pub val_meshes: usize,
    /// Whether the split was drawn by shape (results from before the option read as false:
    /// they were drawn mesh by mesh).
    #[serde(default)]
    pub split_by_shape: bool,
    /// Which loss chose the evaluated weights: `validation`, `train` or `test`.
    #[serde(default)]
    pub selected_on: String,
    /// Test-set RMS (per coordinate, centroids aligned), in mesh units.
    pub test_rms: f64,
    /// `test_rms` / bounding-box diagonal.
    pub test_rms_rel: f64,
    /// Mean per-vertex distance on the test set (the authors' `show_error.m` measure, without
    /// its rigid alignment).
    pub test_mean_distance: f64,
    pub train_rms: f64,
    /// The trivial predictor (mean training shape) on the test set.
    pub mean_shape_rms: f64,
    pub params: usize,
    pub params_without_biases: usize,
    /// Epoch whose weights were evaluated.
    pub best_epoch: usize,
    /// For comparison, test RMS of the weights the test loss would have chosen (the authors'
    /// protocol on the same run), and their epoch; `None` where they are the evaluated ones.
    #[serde(default)]
    pub test_rms_selected_on_test: Option<f64>,
    #[serde(default)]
    pub best_epoch_on_test: Option<usize>,
    /// Training time summed over the epochs of `log.jsonl` (interrupted sessions included).
    pub train_seconds: f64,
    /// Set-up of this session (features, hierarchy) plus evaluation.
    pub other_seconds: f64,
    /// Threads the run trained on (its session's; `--jobs` shares the cores between runs).
    #[serde(default)]
    pub threads: Option<usize>,
    /// Why training stopped (`converged` or `budget`), its optimizer steps, and the mean
    /// per-vertex distance after rigid alignment (the authors' measure); absent from results
    /// written before runs recorded them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_mean_distance_rigid: Option<f64>,
}

impl RunResult {
    /// Whether this result was produced by `run` (same data set, protocol, column, seed,
    /// epochs, kind of split and network).
    pub fn matches(&self, run: &Run, model: &ModelConfig) -> bool {
        self.dataset == run.dataset.name
            && self.protocol == run.protocol.id
            && self.column == run.column.id
            && self.seed == run.seed
            && self.epochs == run.epochs
            && self.split_by_shape == run.by_shape
            && &self.model == model
    }

    /// Every number finite (a diverged run would not be).
    pub fn is_finite(&self) -> bool {
        [
            self.test_rms,
            self.test_rms_rel,
            self.test_mean_distance,
            self.train_rms,
            self.mean_shape_rms,
        ]
        .iter()
        .all(|x| x.is_finite())
    }
}

/// Reads a finished run's result from `records`, if there is one for this very run.
pub fn finished(run: &Run, records: &Path) -> Result<Option<RunResult>, ReproError> {
    let path = run.result_path(records);
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| ReproError::io(&path, e))?;
    let result: RunResult = serde_json::from_str(&text).map_err(|e| ReproError::Results {
        path: path.clone(),
        message: format!("unreadable run result ({e}); delete it to run again"),
    })?;
    let model = run.column.model().map_err(|e| ReproError::run(run, e))?;
    Ok(result.matches(run, &model).then_some(result))
}

/// Trains and evaluates `run` on `set`, resuming its model folder if one exists, and writes its
/// result under `records` (the same layout as `work`). `on_epoch` sees each epoch as it ends.
pub fn execute(
    run: &Run,
    set: &MeshSet,
    source: Option<PathBuf>,
    work: &Path,
    records: &Path,
    checkpoint_seconds: f64,
    mut on_epoch: impl FnMut(usize),
) -> Result<RunResult, ReproError> {
    let started = Instant::now();
    let out = run.model_dir(work);
    let model = run.column.model().map_err(|e| ReproError::run(run, e))?;
    let folder = ModelFolder::new(&out);
    // A folder with a config is a model (perhaps interrupted): continue it. Anything else there
    // is an interrupted set-up and is replaced.
    let resume = folder.config().is_file();
    let request = TrainRequest {
        set,
        source,
        out: out.clone(),
        model: model.clone(),
        train: run.train_config(),
        features: Default::default(),
        hierarchy: Default::default(),
        split: None,
    };
    let options = TrainOptions {
        resume,
        force: !resume,
        progress: false,
        checkpoint_seconds,
        ..TrainOptions::default()
    };
    let mut session_train = 0.0;
    // A run whose training finished but whose result was lost (or deleted) is only evaluated
    // again: its checkpoint was dropped when the result was first written.
    if !(resume && training_finished(&folder, run.epochs)?) {
        meshvae::train(&request, &options, |record| {
            session_train += record.seconds;
            on_epoch(record.epoch);
        })
        .map_err(|e| ReproError::run(run, e))?;
    }

    let device = Device::Cpu;
    let load = |on_test: bool| {
        TrainedModel::load_selected(&out, &device, on_test).map_err(|e| ReproError::run(run, e))
    };
    let trained = load(run.protocol.select_on_test)?;
    let report = trained
        .evaluate(set, &device)
        .map_err(|e| ReproError::run(run, e))?;
    let (_, best_epoch) = trained
        .epochs_trained()
        .map_err(|e| ReproError::run(run, e))?;
    let (test_rms_selected_on_test, best_epoch_on_test) =
        if run.protocol.select_on_test || trained.split.test.is_empty() {
            (None, None)
        } else {
            // Only the test meshes: reconstructing is most of an evaluation's time.
            let on_test = load(true)?;
            let test = &on_test.split.test;
            let truth: Vec<&[mesh_io::Point]> = test.iter().map(|&i| set.frame(i)).collect();
            let errors = on_test
                .reconstruct(set, test, &device)
                .and_then(|rec| meshvae::error_report(&truth, &rec))
                .map_err(|e| ReproError::run(run, e))?;
            let (_, epoch) = on_test
                .epochs_trained()
                .map_err(|e| ReproError::run(run, e))?;
            (Some(errors.rms), Some(epoch))
        };
    let log = meshvae::read_log(&folder.log()).map_err(|e| ReproError::run(run, e))?;
    let status = meshvae::read_status(&folder).map_err(|e| ReproError::run(run, e))?;
    let train_seconds: f64 = log.iter().map(|r| r.seconds).sum();
    let mut levels = trained.hierarchy.vertex_counts();
    levels.truncate(model.pool_levels() + 1);
    let result = RunResult {
        dataset: run.dataset.name.into(),
        protocol: run.protocol.id.into(),
        column: run.column.id.into(),
        seed: run.seed,
        epochs: run.epochs,
        model,
        levels,
        test_meshes: report.test.meshes,
        train_meshes: report.train.meshes,
        val_meshes: trained.split.val.len(),
        split_by_shape: trained.spec.train.split_by_shape,
        selected_on: trained.selected_on.to_string(),
        test_rms: report.test.rms,
        test_rms_rel: report.test.rms_rel,
        test_mean_distance: report.test.mean_distance,
        train_rms: report.train.rms,
        mean_shape_rms: report.mean_shape.rms,
        params: report.params.with_biases,
        params_without_biases: report.params.without_biases,
        best_epoch,
        test_rms_selected_on_test,
        best_epoch_on_test,
        train_seconds,
        other_seconds: (started.elapsed().as_secs_f64() - session_train).max(0.0),
        threads: Some(rayon::current_num_threads()),
        stop_reason: status.as_ref().map(|s| s.stop_reason.to_string()),
        steps: status.as_ref().map(|s| s.steps),
        test_mean_distance_rigid: Some(report.test.mean_distance_rigid),
    };
    let path = run.result_path(records);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| ReproError::io(parent, e))?;
    }
    let text = serde_json::to_string_pretty(&result).map_err(|e| ReproError::Results {
        path: path.clone(),
        message: e.to_string(),
    })?;
    mesh_io::atomic::write_bytes_atomic(&path, text.as_bytes()).map_err(|e| {
        ReproError::Results {
            path: path.clone(),
            message: e.to_string(),
        }
    })?;
    // The training state (weights plus Adam's two moments) is three times the weights and only
    // serves to resume; a finished run keeps its weights, log and settings, so it can still be
    // evaluated, reconstructed or sampled with `meshvae`.
    let checkpoint = folder.checkpoint();
    if checkpoint.is_file() {
        std::fs::remove_file(&checkpoint).map_err(|e| ReproError::io(&checkpoint, e))?;
    }
    Ok(result)
}

/// Whether the folder's log reaches the last epoch and its selected weights were written.
fn training_finished(folder: &ModelFolder, epochs: usize) -> Result<bool, ReproError> {
    let path = folder.log();
    if !path.is_file() || !folder.weights().is_file() {
        return Ok(false);
    }
    let log = meshvae::read_log(&path).map_err(|e| ReproError::Results {
        path: path.clone(),
        message: e.to_string(),
    })?;
    Ok(log.last().is_some_and(|r| r.epoch == epochs))
}
