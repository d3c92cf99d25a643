//! The model folder a training run writes: its files' paths ([`ModelFolder`]), `config.json`
//! ([`ModelSpec`]) and `split.json` ([`SplitFile`]); everything needed to use a trained model
//! without the training run (loaded by [`crate::TrainedModel`], `trained.rs`).
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

use super::config::TrainConfig;
use crate::error::{Result, VaeError};
use crate::net::config::ModelConfig;
use crate::train::split::{Selection, Split};
use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::{MeshSet, ShapeGroups, TriMesh};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Tag of `config.json`.
pub const FORMAT: &str = "meshvae-model";
/// Version of the folder layout.
pub const VERSION: u32 = 1;

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
