//! The model folder: everything needed to use a trained model without the training run.
//!
//! ```text
//! MODEL/
//!   config.json          ModelSpec: model, training and feature settings, set description
//!   hierarchy.safetensors  mesh levels, Laplacians, pooling operators (mesh-hierarchy's
//!                        format; models trained before it have hierarchy.json)
//!   normalization.json   feature ranges fitted on the training split
//!   split.json           training and test indices (and names)
//!   template.obj         the rest mesh features are relative to
//!   weights.safetensors  the best weights (lowest validation loss); metadata `epoch` says which
//!   checkpoint.safetensors  the rest of that epoch's training state: optimiser moments, random
//!                        state, schedule (a resumed run trains the later epochs again)
//!   log.jsonl            one line of losses per epoch (with the step count and learning rate)
//!   run.json             why training stopped: converged, budget or interrupted (RunStatus),
//!                        and the epoch with the lowest test loss
//!   loss.png             the loss curves (written by `meshvae train`)
//!   weights-selected-on-test.safetensors  only with `--keep-selected-on-test`
//! ```
//!
//! One copy of the weights: the checkpoint does not repeat them (horse-gallop's folder went
//! from 191 MB to about 120 MB). Every file is written atomically (temporary file, then
//! rename).

use crate::config::ModelConfig;
use crate::error::{Result, VaeError};
use crate::loss::LossWeights;
use crate::model::MeshVae;
use crate::schedule::Schedule;
use crate::split::{Selection, Split};
use candle_core::Device;
use deform_features::{FeatureOptions, Normalization};
use mesh_hierarchy::{Hierarchy, HierarchyConfig};
use mesh_io::{MeshSet, ShapeGroups, TriMesh};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Tag of `config.json`.
pub const FORMAT: &str = "meshvae-model";
/// Version of the folder layout.
pub const VERSION: u32 = 1;

/// Training settings (saved with the model).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Epoch budget (used when `steps` is `None`); a resumed run may change it.
    pub epochs: usize,
    /// Budget in optimizer steps (rounded up to whole epochs), so that small and large sets get
    /// the same number of updates; overrides `epochs`. Models saved before it read as `None`.
    #[serde(default)]
    pub steps: Option<usize>,
    /// Meshes per step (the authors: 50); the last batch of an epoch may be smaller.
    pub batch: usize,
    /// Adam's initial learning rate (1e-2; the authors' 1e-3 took more than 8,000 steps to
    /// reach what 1e-2 reaches in 1,500, see docs/benchmarks.md "Convergence"; 3e-2 diverges).
    pub lr: f64,
    /// Seeds the split, the initial weights, the shuffles and the sampling noise.
    pub seed: u64,
    pub loss: LossWeights,
    /// Fraction of the set held out for testing when no lists are given (0.5).
    pub test_fraction: f64,
    /// Fraction of the training meshes moved to the validation set that chooses the best
    /// checkpoint (0.1; at least one mesh, two from ten on). 0 chooses on the training loss. Models saved before
    /// validation sets existed read as 0.
    #[serde(default)]
    pub val_fraction: f64,
    /// Draw the random test set by shape, not by mesh: meshes with the same vertex positions (a
    /// cycle stored twice, as horse-gallop's 48 meshes are) always land on the same side, so
    /// no test shape has a copy among the training meshes. A set without repeats splits
    /// exactly as by mesh. Models saved before this option read as false. (The validation set
    /// is drawn by shape either way, so that its loss measures poses the network has not seen.)
    #[serde(default)]
    pub split_by_shape: bool,
    /// Learning-rate schedule and early stop. Models saved before schedules existed read as
    /// [`Schedule::constant`] (a constant rate for the whole budget).
    #[serde(default = "Schedule::constant")]
    pub schedule: Schedule,
    /// Fit the feature normalisation on every mesh, test meshes included (the authors' code),
    /// instead of the training meshes only. For comparisons: it lets the test meshes shape the
    /// model's inputs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub normalize_on_all: bool,
    /// Fit each feature group's range between the quantiles q and 1 − q and clamp the
    /// outliers (0: between min and max, as the authors). Models saved before the option read
    /// as 0; new ones default to [`DEFAULT_NORMALIZE_QUANTILE`].
    #[serde(default, skip_serializing_if = "is_zero")]
    pub normalize_quantile: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The default [`TrainConfig::normalize_quantile`]: a handful of vertices around nearly
/// collapsed edges hold stretch features 10–20× the rest, and a min–max range fitted to them
/// squeezes 99 % of the entries into 7 % of the network's output range. Fitting between the
/// 0.1 % and 99.9 % quantiles (and clamping the 0.2 % beyond) converged horse-gallop to a lower
/// error in fewer steps (docs/benchmarks.md, "Convergence").
pub const DEFAULT_NORMALIZE_QUANTILE: f64 = 0.001;

/// The step budget of a run given no budget: long enough for every set measured to converge
/// first (horse-gallop, samba and the synthetic set stop on their own in fewer steps), so it
/// only ends a run that keeps improving.
pub const DEFAULT_MAX_STEPS: usize = 20_000;

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 100,
            steps: None,
            batch: 50,
            lr: 1e-2,
            seed: 1,
            loss: LossWeights::default(),
            test_fraction: 0.5,
            val_fraction: 0.1,
            split_by_shape: true,
            schedule: Schedule::default(),
            normalize_on_all: false,
            normalize_quantile: DEFAULT_NORMALIZE_QUANTILE,
        }
    }
}

impl TrainConfig {
    /// The run's length in epochs when an epoch takes `steps_per_epoch` steps.
    pub fn epoch_budget(&self, steps_per_epoch: usize) -> usize {
        match self.steps {
            Some(steps) => steps.div_ceil(steps_per_epoch.max(1)),
            None => self.epochs,
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.epochs == 0 {
            return Err(VaeError::argument("epochs", "must be at least 1"));
        }
        if self.steps == Some(0) {
            return Err(VaeError::argument("steps", "must be at least 1"));
        }
        self.schedule.validate()?;
        if !(0.0..0.5).contains(&self.normalize_quantile) {
            return Err(VaeError::argument(
                "normalize_quantile",
                format!("{} is not in [0, 0.5)", self.normalize_quantile),
            ));
        }
        if self.batch == 0 {
            return Err(VaeError::argument("batch", "must be at least 1"));
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err(VaeError::argument(
                "lr",
                format!("{} is not positive", self.lr),
            ));
        }
        if !(0.0..1.0).contains(&self.val_fraction) {
            return Err(VaeError::argument(
                "val_fraction",
                format!("{} is not in [0, 1)", self.val_fraction),
            ));
        }
        let w = self.loss;
        if ![w.rec, w.kl, w.l2]
            .iter()
            .all(|x| x.is_finite() && *x >= 0.0)
        {
            return Err(VaeError::argument(
                "loss weights",
                "must be finite and non-negative",
            ));
        }
        Ok(())
    }
}

/// `config.json`: what the model is and what it was trained on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSpec {
    pub format: String,
    pub version: u32,
    pub model: ModelConfig,
    pub train: TrainConfig,
    pub features: FeatureOptions,
    pub hierarchy: HierarchyConfig,
    /// Connectivity of the training set, checked whenever the model meets a mesh set.
    pub vertices: usize,
    pub faces: usize,
    /// The set's mesh names, in order (the split's indices refer to them).
    pub names: Vec<String>,
    /// Where the set was loaded from, if from disk (used by `eval` when no set is given).
    pub source: Option<PathBuf>,
    /// A conditional model's label of each mesh, in `names` order (what the encoder and the
    /// decoder are given for that mesh). Absent for unconditional models.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<Vec<String>>,
}

impl ModelSpec {
    /// A conditional model has one known label per mesh; an unconditional one has none.
    pub fn check_labels(&self, dir: &Path) -> Result<()> {
        let classes = &self.model.labels;
        match &self.labels {
            None if classes.is_empty() => Ok(()),
            None => Err(VaeError::model(
                dir,
                "a conditional model without its meshes' labels in config.json",
            )),
            Some(_) if classes.is_empty() => Err(VaeError::model(
                dir,
                "mesh labels in config.json, but the model is not conditional",
            )),
            Some(labels) => {
                if labels.len() != self.names.len() {
                    return Err(VaeError::model(
                        dir,
                        format!(
                            "{} mesh labels for {} meshes in config.json",
                            labels.len(),
                            self.names.len()
                        ),
                    ));
                }
                match labels.iter().position(|l| !classes.contains(l)) {
                    Some(i) => Err(VaeError::model(
                        dir,
                        format!(
                            "mesh {:?} has label {:?}, not one of the model's ({})",
                            self.names[i],
                            labels[i],
                            classes.join(", ")
                        ),
                    )),
                    None => Ok(()),
                }
            }
        }
    }

    /// Checks that `set` has this model's connectivity.
    pub fn check_set(&self, set: &MeshSet, template: &TriMesh, dir: &Path) -> Result<()> {
        if set.vertex_count() != self.vertices || set.faces().len() != self.faces {
            return Err(VaeError::model(
                dir,
                format!(
                    "the model was trained on meshes of {} vertices and {} faces; this set has {} \
                     vertices and {} faces",
                    self.vertices,
                    self.faces,
                    set.vertex_count(),
                    set.faces().len()
                ),
            ));
        }
        if set.faces() != template.faces.as_slice() {
            return Err(VaeError::model(
                dir,
                "the set's faces differ from the model's template: another connectivity",
            ));
        }
        Ok(())
    }
}

/// Paths of a model folder's files.
#[derive(Debug, Clone)]
pub struct ModelFolder {
    pub dir: PathBuf,
}

impl ModelFolder {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }
    pub fn config(&self) -> PathBuf {
        self.dir.join("config.json")
    }
    /// `hierarchy.safetensors`, or the `hierarchy.json` of a model trained before it (when
    /// that is the one present).
    pub fn hierarchy(&self) -> PathBuf {
        let binary = self.dir.join("hierarchy.safetensors");
        let json = self.legacy_hierarchy();
        if !binary.is_file() && json.is_file() {
            json
        } else {
            binary
        }
    }
    /// Where models trained before the binary hierarchy kept it.
    pub fn legacy_hierarchy(&self) -> PathBuf {
        self.dir.join("hierarchy.json")
    }
    pub fn normalization(&self) -> PathBuf {
        self.dir.join("normalization.json")
    }
    pub fn split(&self) -> PathBuf {
        self.dir.join("split.json")
    }
    pub fn template(&self) -> PathBuf {
        self.dir.join("template.obj")
    }
    pub fn weights(&self) -> PathBuf {
        self.dir.join("weights.safetensors")
    }
    /// Best weights written before their checkpoint, put in place after it (a kill in between
    /// leaves them here for the next start to settle).
    pub fn pending_weights(&self) -> PathBuf {
        self.dir.join("weights.pending.safetensors")
    }
    /// The weights with the lowest TEST loss, kept only to compare with the authors' protocol
    /// (`meshvae eval --select-on-test`).
    pub fn weights_selected_on_test(&self) -> PathBuf {
        self.dir.join("weights-selected-on-test.safetensors")
    }
    pub fn checkpoint(&self) -> PathBuf {
        self.dir.join("checkpoint.safetensors")
    }
    pub fn log(&self) -> PathBuf {
        self.dir.join("log.jsonl")
    }
    /// `run.json`: why training stopped ([`crate::RunStatus`]).
    pub fn status(&self) -> PathBuf {
        self.dir.join("run.json")
    }
    /// `loss.png`: the loss curves, drawn by the command line after training.
    pub fn loss_plot(&self) -> PathBuf {
        self.dir.join("loss.png")
    }

    /// Whether the folder holds a model (its `config.json`).
    pub fn has_model(&self) -> bool {
        self.config().is_file()
    }

    /// Removes the temporary files that a killed write left behind (`.<name>.tmp` and
    /// `.<name>.<pid>.tmp`: every file of a model folder is written beside its final name and
    /// renamed, so a kill mid-write leaves the old file whole and this one behind), and returns
    /// how many. Training calls it before it writes anything; no two processes write one model
    /// folder at once.
    pub fn remove_stale_temporaries(&self) -> Result<usize> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(VaeError::io(&self.dir, e)),
        };
        let mut removed = 0;
        for entry in entries {
            let path = entry.map_err(|e| VaeError::io(&self.dir, e))?.path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            let temporary = name.is_some_and(|n| n.starts_with('.') && n.ends_with(".tmp"));
            if temporary && path.is_file() {
                std::fs::remove_file(&path).map_err(|e| VaeError::io(&path, e))?;
                removed += 1;
            }
        }
        Ok(removed)
    }

    pub fn write_json<T: Serialize>(&self, path: &Path, value: &T) -> Result<()> {
        mesh_io::atomic::write_atomic(path, |w| {
            serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
            std::io::Write::write_all(w, b"\n")
        })?;
        Ok(())
    }

    pub fn read_json<T: for<'de> Deserialize<'de>>(&self, path: &Path) -> Result<T> {
        let bytes = std::fs::read(path).map_err(|e| VaeError::io(path, e))?;
        serde_json::from_slice(&bytes).map_err(|e| VaeError::model(path, e.to_string()))
    }

    pub fn read_spec(&self) -> Result<ModelSpec> {
        let path = self.config();
        if !path.is_file() {
            return Err(VaeError::model(
                &self.dir,
                "not a model folder (no config.json)",
            ));
        }
        let spec: ModelSpec = self.read_json(&path)?;
        if spec.format != FORMAT || spec.version != VERSION {
            return Err(VaeError::model(
                &path,
                format!(
                    "format {} version {}; this meshvae reads {FORMAT} version {VERSION}",
                    spec.format, spec.version
                ),
            ));
        }
        Ok(spec)
    }
}

/// Split indices with the names they had (a human can read which meshes were held out).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitFile {
    pub train: Vec<usize>,
    #[serde(default)]
    pub val: Vec<usize>,
    pub test: Vec<usize>,
    pub train_names: Vec<String>,
    #[serde(default)]
    pub val_names: Vec<String>,
    pub test_names: Vec<String>,
    /// Which loss chose `weights.safetensors` (models saved before validation sets existed
    /// chose on the test meshes).
    #[serde(default = "legacy_selection")]
    pub selected_on: Selection,
    /// Whether the random sets were drawn by shape (see [`TrainConfig::split_by_shape`]).
    #[serde(default)]
    pub by_shape: bool,
    /// The groups of meshes with the same shape (only groups of two or more), as found when
    /// the split was drawn; empty if the set has no repeats or they were not looked for.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeated_shapes: Vec<Vec<usize>>,
}

fn legacy_selection() -> Selection {
    Selection::Test
}

impl SplitFile {
    pub fn new(split: &Split, names: &[String]) -> Self {
        let pick = |idx: &[usize]| idx.iter().map(|&i| names[i].clone()).collect();
        Self {
            train: split.train.clone(),
            val: split.val.clone(),
            test: split.test.clone(),
            train_names: pick(&split.train),
            val_names: pick(&split.val),
            test_names: pick(&split.test),
            selected_on: split.selection(),
            by_shape: false,
            repeated_shapes: Vec::new(),
        }
    }

    /// Records that the sets were drawn by shape, with the groups of repeated shapes.
    pub fn with_shapes(mut self, groups: &ShapeGroups) -> Self {
        self.by_shape = true;
        self.repeated_shapes = groups
            .members()
            .into_iter()
            .filter(|g| g.len() > 1)
            .collect();
        self
    }

    /// The split it records.
    pub fn split(&self) -> Split {
        Split {
            train: self.train.clone(),
            val: self.val.clone(),
            test: self.test.clone(),
        }
    }
}

/// A model folder loaded for use: the network with its best weights and everything around it.
#[derive(Debug)]
pub struct TrainedModel {
    pub folder: ModelFolder,
    pub spec: ModelSpec,
    pub model: MeshVae,
    pub hierarchy: Hierarchy,
    pub normalization: Normalization,
    pub split: Split,
    pub template: TriMesh,
    /// Which loss chose the loaded weights.
    pub selected_on: Selection,
}

impl TrainedModel {
    /// Loads `dir` with its best weights (chosen on the validation meshes, or as recorded in
    /// its split file), or the last checkpoint's if no best was saved yet.
    pub fn load(dir: &Path, device: &Device) -> Result<Self> {
        Self::load_selected(dir, device, false)
    }

    /// As [`Self::load`]; with `select_on_test`, the weights with the lowest test loss instead
    /// (the authors' protocol, for comparison only: those errors are not on unseen data).
    ///
    /// Errors: `select_on_test` and a model without such weights (no test meshes, or trained
    /// before they were kept).
    pub fn load_selected(dir: &Path, device: &Device, select_on_test: bool) -> Result<Self> {
        let folder = ModelFolder::new(dir);
        let spec = folder.read_spec()?;
        spec.check_labels(dir)?;
        let hierarchy = Hierarchy::load(&folder.hierarchy())?;
        let normalization: Normalization = folder.read_json(&folder.normalization())?;
        normalization.validate()?;
        let split_file: SplitFile = folder.read_json(&folder.split())?;
        let split = split_file.split();
        split
            .check(spec.names.len())
            .map_err(|e| VaeError::model(folder.split(), e.to_string()))?;
        let template = mesh_io::read_mesh(&folder.template())?.value;
        if template.vertex_count() != spec.vertices
            || hierarchy.levels[0].vertex_count != spec.vertices
        {
            return Err(VaeError::model(
                dir,
                "template, hierarchy and config disagree on the vertex count",
            ));
        }
        let mut model = MeshVae::new(&spec.model, &hierarchy, device, spec.train.seed)?;
        let weights = folder.weights();
        let mut selected_on = split_file.selected_on;
        if select_on_test && selected_on != Selection::Test {
            let on_test = folder.weights_selected_on_test();
            let status = crate::train::read_status(&folder)?;
            let chosen_epoch = status.as_ref().and_then(|s| s.best_test_epoch);
            if !on_test.is_file() {
                let chosen = (status.as_ref())
                    .and_then(|s| s.best_test_epoch.zip(s.best_test_loss))
                    .map_or(String::new(), |(epoch, loss)| {
                        format!(" (the test loss chose epoch {epoch}, loss {loss:.4})")
                    });
                return Err(VaeError::model(
                    dir,
                    format!(
                        "no weights selected on the test meshes{chosen}: they are kept only when \
                         training is asked to (meshvae train --keep-selected-on-test), and \
                         exist only for a model with test meshes"
                    ),
                ));
            }
            let epoch = model.load_epoch(&on_test)?;
            if let (Some(held), Some(chosen)) = (epoch, chosen_epoch)
                && held != chosen
            {
                return Err(VaeError::model(
                    &on_test,
                    format!(
                        "holds the weights of epoch {held}, but the test loss chose epoch \
                         {chosen} (run.json): stale"
                    ),
                ));
            }
            selected_on = Selection::Test;
        } else if weights.is_file() {
            model.load(&weights)?;
        } else {
            crate::checkpoint::Checkpoint::load_model_only(&folder.checkpoint(), &mut model)?;
        }
        Ok(Self {
            folder,
            spec,
            model,
            hierarchy,
            normalization,
            split,
            template,
            selected_on,
        })
    }
}

impl TrainedModel {
    /// A conditional model's label of each mesh of its set (`spec.names` order).
    pub fn mesh_labels(&self) -> Option<&[String]> {
        self.spec.labels.as_deref()
    }

    /// The one-hot labels `[B, L]` of the meshes `ids` of the model's set for a conditional
    /// model, `None` for an unconditional one: what `MeshVae::encode_cond` and friends take.
    ///
    /// Errors: an index out of range.
    pub fn conditions(&self, ids: &[usize]) -> Result<Option<candle_core::Tensor>> {
        let Some(labels) = self.mesh_labels() else {
            return Ok(None);
        };
        let picked = crate::model::pick_labels(labels, ids)?;
        Ok(Some(self.model.one_hot(&picked)?))
    }

    /// Epochs trained so far and the epoch whose weights are loaded, from `log.jsonl`.
    pub fn epochs_trained(&self) -> Result<(usize, usize)> {
        let path = self.folder.log();
        if !path.is_file() {
            return Ok((0, 0));
        }
        let log = crate::train::read_log(&path)?;
        let last = log.last().map_or(0, |r| r.epoch);
        let best = log
            .iter()
            .min_by(|a, b| {
                a.score(self.selected_on)
                    .total_cmp(&b.score(self.selected_on))
            })
            .map_or(0, |r| r.epoch);
        Ok((last, best))
    }
}
