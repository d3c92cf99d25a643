//! A run's starting point: a fresh model folder (split, hierarchy, normalisation, files) or
//! the state of one being resumed, with the checks that keep a folder from being overwritten.

use super::EpochRecord;
use crate::error::{Result, VaeError};
use crate::net::config::ModelConfig;
use crate::net::network::Input;
use crate::train::config::TrainConfig;
use crate::train::data::{MeshData, NormalizationFit};
use crate::train::folder::{FORMAT, ModelFolder, ModelSpec, SplitFile, VERSION};
use crate::train::scaling::InputScaling;
use crate::train::schedule::StopReason;
use crate::train::split::Split;
use mesh_hierarchy::{Hierarchy, HierarchyConfig};
use mesh_io::{MeshSet, ShapeGroups, TriMesh};

use super::TrainRequest;

pub(super) fn fresh_setup(
    request: &TrainRequest,
    folder: &ModelFolder,
    force: bool,
    hierarchy_config: HierarchyConfig,
) -> Result<(ModelSpec, Hierarchy, MeshData, NewFiles)> {
    let set = request.set;
    let train = &request.train;
    let shapes = set.shape_groups(ShapeGroups::DEFAULT_TOLERANCE)?;
    // Singletons split exactly as mesh by mesh, so one code path serves both settings.
    let test_groups = if train.split_by_shape {
        shapes.clone()
    } else {
        ShapeGroups::singletons(set.len())
    };
    // Validation is drawn by shape even when the test set is drawn by mesh: a validation mesh
    // whose copy trains measures memory, not unseen poses, so its loss keeps improving long
    // after the test error has stopped, and the stop rule waits for it.
    let split = match &request.split {
        Some(s) => {
            s.check(set.len())?;
            s.clone()
        }
        None => Split::random_by_shape(&test_groups, train.test_fraction, train.seed)?,
    }
    .with_validation_by_shape(&shapes, train.val_fraction, train.seed)?;
    let mut split_file = SplitFile::new(&split, set.names());
    if train.split_by_shape {
        split_file = split_file.with_shapes(&test_groups);
    }
    let labels = mesh_labels(&request.model, set, &split)?;
    let net = request.model.net;
    if set.vertex_count() < net.min_vertices() {
        return Err(VaeError::argument(
            "net",
            format!(
                "{net} samples the template down by 4 at each of its 4 levels, which needs at \
                 least {} vertices; the set has {}",
                net.min_vertices(),
                set.vertex_count()
            ),
        ));
    }
    prepare_out_dir(folder, force)?;
    let template = set.template();
    let hierarchy = Hierarchy::build(&template, &hierarchy_config)?;
    let fit = NormalizationFit {
        on_all: train.normalize_on_all,
        quantile: train.normalize_quantile,
    };
    let mut data = match request.model.net.input() {
        Input::Features => MeshData::prepare_fitted(set, split, request.features, fit)?,
        Input::Positions => MeshData::prepare_positions(set, split)?,
    };
    if let Some(labels) = &labels {
        data = data.with_labels(labels.clone())?;
    }
    let spec = ModelSpec {
        format: FORMAT.into(),
        version: VERSION,
        model: request.model.clone(),
        train: request.train.clone(),
        features: request.features,
        hierarchy: hierarchy_config,
        vertices: set.vertex_count(),
        faces: set.faces().len(),
        names: set.names().to_vec(),
        source: request.source.clone(),
        labels,
    };
    let files = NewFiles {
        template,
        split: split_file,
    };
    Ok((spec, hierarchy, data, files))
}

/// What a new model folder gets beside its spec, hierarchy and normalisation.
pub(super) struct NewFiles {
    pub(super) template: TriMesh,
    pub(super) split: SplitFile,
}

/// The set's labels for a conditional model (`None` for an unconditional one), checked: every
/// mesh has one of the model's labels and every label has a training mesh.
fn mesh_labels(model: &ModelConfig, set: &MeshSet, split: &Split) -> Result<Option<Vec<String>>> {
    if !model.is_conditional() {
        return Ok(None);
    }
    let known = model.labels.join(", ");
    let labels = set.labels().ok_or_else(|| {
        VaeError::argument(
            "labels",
            format!(
                "the model is conditional on {known}, but the mesh set has no labels (give a \
                 labels file)"
            ),
        )
    })?;
    if let Some(i) = labels.iter().position(|l| !model.labels.contains(l)) {
        return Err(VaeError::argument(
            "labels",
            format!(
                "mesh {:?} has label {:?}, not one of the model's ({known})",
                set.names()[i],
                labels[i]
            ),
        ));
    }
    if let Some(missing) = model
        .labels
        .iter()
        .find(|c| !split.train.iter().any(|&i| &labels[i] == *c))
    {
        return Err(VaeError::argument(
            "labels",
            format!(
                "no training mesh has label {missing:?} (the split left them all for testing); \
                 use another seed or training list"
            ),
        ));
    }
    Ok(Some(labels.to_vec()))
}

/// The files of a new model folder; the config goes last: a folder without it is not (yet) a
/// model.
pub(super) fn write_model_files(
    folder: &ModelFolder,
    spec: &ModelSpec,
    hierarchy: &Hierarchy,
    data: &MeshData,
    files: &NewFiles,
) -> Result<()> {
    hierarchy.save(&folder.hierarchy())?;
    folder.write_json(&folder.normalization(), &data.normalization)?;
    folder.write_json(&folder.split(), &files.split)?;
    mesh_io::write_mesh(&folder.template(), &files.template)?;
    folder.write_json(&folder.config(), spec)
}

pub(super) fn resume_setup(
    request: &TrainRequest,
    folder: &ModelFolder,
    hierarchy_config: HierarchyConfig,
) -> Result<(ModelSpec, Hierarchy, MeshData)> {
    let mut spec = folder.read_spec()?;
    refuse_finished_without_checkpoint(folder, &spec.train)?;
    let template = mesh_io::read_mesh(&folder.template())?.value;
    spec.check_set(request.set, &template, &folder.dir)?;
    let mut differences = Vec::new();
    if spec.model != request.model {
        differences.push("model");
    }
    if spec.features != request.features {
        differences.push("features");
    }
    if spec.hierarchy != hierarchy_config {
        differences.push("hierarchy");
    }
    if spec.names != request.set.names() {
        differences.push("mesh names");
    }
    if spec.labels.is_some() && spec.labels.as_deref() != request.set.labels() {
        differences.push("mesh labels");
    }
    let (a, b) = (&spec.train, &request.train);
    if (
        a.batch,
        a.lr,
        a.seed,
        a.loss,
        a.test_fraction,
        a.val_fraction,
        a.split_by_shape,
        a.schedule,
        a.normalize_on_all,
        a.normalize_quantile,
        (a.adam_beta2, a.head_lr_scale, a.grad_clip),
    ) != (
        b.batch,
        b.lr,
        b.seed,
        b.loss,
        b.test_fraction,
        b.val_fraction,
        b.split_by_shape,
        b.schedule,
        b.normalize_on_all,
        b.normalize_quantile,
        (b.adam_beta2, b.head_lr_scale, b.grad_clip),
    ) {
        differences.push("training settings other than the budget");
    }
    if !differences.is_empty() {
        return Err(VaeError::model(
            &folder.dir,
            format!(
                "cannot resume: the {} differ from this model's (only the budget, --epochs or \
                 --steps, may change)",
                differences.join(", ")
            ),
        ));
    }
    refuse_smaller_budget(folder, &request.train)?;
    if (spec.train.epochs, spec.train.steps) != (request.train.epochs, request.train.steps) {
        spec.train.epochs = request.train.epochs;
        spec.train.steps = request.train.steps;
        folder.write_json(&folder.config(), &spec)?;
    }
    let hierarchy = Hierarchy::load(&folder.hierarchy())?;
    let scaling: InputScaling = folder.read_json(&folder.normalization())?;
    let split_file: SplitFile = folder.read_json(&folder.split())?;
    let split = split_file.split();
    split.check(request.set.len())?;
    let mut data = match scaling {
        InputScaling::Features(normalization) => {
            let features = deform_features::extract_features(request.set, spec.features)?;
            let (raw, warnings) = (features.features, features.warnings);
            MeshData::with_normalization(raw, split, normalization, warnings)
        }
        InputScaling::Positions(p) => MeshData::with_position_scaling(request.set, split, p),
    };
    if let Some(labels) = &spec.labels {
        data = data.with_labels(labels.clone())?;
    }
    Ok((spec, hierarchy, data))
}

/// A run interrupted before its first checkpoint restarts from scratch on `--resume`, losing at
/// most `checkpoint_seconds` of work. A *finished* run without its checkpoint (deleted by hand,
/// or by `cargo xtask reproduce`, which keeps only the weights of the runs it has finished)
/// would lose everything, its trained weights overwritten by a fresh run: that is refused.
/// `run.json` says which (`interrupted` until the run ends); only a folder from before it
/// existed is judged by its log against its epoch budget.
fn refuse_finished_without_checkpoint(folder: &ModelFolder, train: &TrainConfig) -> Result<()> {
    let log = folder.log();
    if folder.checkpoint().is_file() || !log.is_file() {
        return Ok(());
    }
    match super::read_status(folder)? {
        Some(status) if status.stop_reason == StopReason::Interrupted => return Ok(()),
        Some(status) => {
            return Err(VaeError::model(
                &folder.dir,
                format!(
                    "cannot resume: its run finished ({}, {} epochs) but {}, which --resume \
                     continues from, is gone; the trained weights are untouched. To train \
                     longer, start a new folder (or this one with --force)",
                    status.stop_reason,
                    status.epochs,
                    folder.checkpoint().display()
                ),
            ));
        }
        None => {}
    }
    // A step budget's epochs are not its length (`train.epochs` then only sizes other things).
    let logged = logged_epochs(folder)?;
    if train.steps.is_none() && logged > 0 && logged >= train.epochs {
        return Err(VaeError::model(
            &folder.dir,
            format!(
                "cannot resume: its run finished ({logged} epochs logged) but {}, which --resume \
                 continues from, is gone (`cargo xtask reproduce` removes it from the runs it \
                 has finished); the trained weights are untouched. To train longer, start a \
                 new folder (or this one with --force) with the larger --epochs",
                folder.checkpoint().display()
            ),
        ));
    }
    Ok(())
}

/// A budget below what the run has already trained would be met before the first step: the
/// run would stop at once while `config.json` claimed the smaller budget. Refused, with nothing
/// written. The run's own record (`run.json`, else the log) says how far it got.
fn refuse_smaller_budget(folder: &ModelFolder, train: &TrainConfig) -> Result<()> {
    let (epochs, steps) = match super::read_status(folder)? {
        Some(status) => (status.epochs, Some(status.steps)),
        None => (logged_epochs(folder)?, None),
    };
    let smaller = match (train.steps, steps) {
        (Some(budget), Some(done)) => (budget as u64) < done,
        // Without a step count (models from before run.json), compare epochs.
        (Some(_), None) => false,
        (None, _) => train.epochs < epochs,
    };
    if !smaller {
        return Ok(());
    }
    let (flag, budget, done) = match (train.steps, steps) {
        (Some(budget), Some(done)) => ("--steps", budget as u64, format!("{done} steps")),
        _ => ("--epochs", train.epochs as u64, format!("{epochs} epochs")),
    };
    Err(VaeError::model(
        &folder.dir,
        format!(
            "cannot resume with {flag} {budget}: the model has already trained {done}; give a larger budget to train longer (nothing was changed)"
        ),
    ))
}

/// The last epoch in the folder's log (0 without one).
fn logged_epochs(folder: &ModelFolder) -> Result<usize> {
    let log = folder.log();
    if !log.is_file() {
        return Ok(0);
    }
    let text = std::fs::read_to_string(&log).map_err(|e| VaeError::io(&log, e))?;
    Ok(text
        .lines()
        .filter_map(|line| serde_json::from_str::<EpochRecord>(line).ok())
        .map(|r| r.epoch)
        .max()
        .unwrap_or(0))
}

/// Creates `out`, refusing to overwrite a model (or any non-empty folder) unless `force`.
fn prepare_out_dir(folder: &ModelFolder, force: bool) -> Result<()> {
    let dir = &folder.dir;
    if dir.exists() {
        if !dir.is_dir() {
            return Err(VaeError::model(dir, "exists and is not a folder"));
        }
        // The training's own lock (taken before this) does not make the folder another's.
        let non_empty = std::fs::read_dir(dir)
            .map_err(|e| VaeError::io(dir, e))?
            .flatten()
            .any(|entry| entry.file_name() != super::lock::LOCK_FILE);
        if non_empty && !force {
            let what = if folder.has_model() {
                "already holds a model; pass --resume to continue it or --force to replace it"
            } else {
                "is not empty; choose a new folder or pass --force"
            };
            return Err(VaeError::model(dir, what));
        }
        if force {
            for path in [
                folder.config(),
                folder.checkpoint(),
                folder.weights(),
                folder.weights_selected_on_test(),
                folder.pending_weights(),
                folder.log(),
                folder.status(),
                folder.loss_plot(),
                folder.hierarchy(),
                folder.legacy_hierarchy(),
                folder.normalization(),
                folder.split(),
                folder.template(),
            ] {
                if path.exists() {
                    std::fs::remove_file(&path).map_err(|e| VaeError::io(&path, e))?;
                }
            }
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| VaeError::io(dir, e))
}
