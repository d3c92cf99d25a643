//! One run: train (resuming a model folder left by an interrupted run), evaluate, and record the
//! numbers in a small JSON beside the model folder ([`super::record`]). A run whose JSON holds
//! today's settings is not repeated; one made with other settings is trained again.

use super::ReproError;
use super::commit::{Commit, TrainedBy};
use super::plan::{Budget, Run};
use super::record::{CopySplitRecord, RunResult, RunSettings};
use candle_core::Device;
use mesh_io::MeshSet;
use meshvae::Platform;
use meshvae::{EpochRecord, ModelFolder, StopReason, TrainOptions, TrainRequest, TrainedModel};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where [`execute`] trains and records, and with which code.
#[derive(Debug, Clone, Copy)]
pub struct Place<'a> {
    /// Folder of the model folders.
    pub work: &'a Path,
    /// Folder of the result JSONs (laid out as `work`).
    pub records: &'a Path,
    /// Seconds between checkpoints.
    pub checkpoint_seconds: f64,
    /// The code, written into the record.
    pub commit: Option<&'a Commit>,
}

/// Trains `run` with `settings` on `set` and evaluates it, resuming its model folder if it
/// holds an interrupted run with the same settings (a folder trained with others is replaced),
/// and writes its result under `place.records` (the same layout as `place.work`). `on_epoch`
/// sees each epoch as it ends.
pub fn execute(
    run: &Run,
    settings: &RunSettings,
    set: &MeshSet,
    source: Option<PathBuf>,
    place: Place<'_>,
    mut on_epoch: impl FnMut(&EpochRecord),
) -> Result<RunResult, ReproError> {
    let started = Instant::now();
    let out = run.model_dir(place.work);
    let model = run.column.model().map_err(|e| ReproError::run(run, e))?;
    let folder = ModelFolder::new(&out);
    // A folder with a config is a model (perhaps interrupted): continue it if it trained with
    // these settings. Anything else there is an interrupted set-up or an older run, replaced.
    let resume = folder.config().is_file()
        && folder
            .read_spec()
            .is_ok_and(|spec| RunSettings::of_spec(&spec).resumable_with(settings));
    let request = TrainRequest {
        set,
        source,
        out: out.clone(),
        model: model.clone(),
        train: settings.train.clone(),
        features: settings.features,
        hierarchy: settings.hierarchy,
        split: None,
    };
    let options = TrainOptions {
        resume,
        force: !resume,
        progress: false,
        checkpoint_seconds: place.checkpoint_seconds,
        // The results page reports the authors' choice beside ours.
        keep_selected_on_test: true,
        stop: Some(meshvae::StopFlag::on_interrupt()),
        ..TrainOptions::default()
    };
    let mut session_train = 0.0;
    // A run whose training finished but whose result was lost (or deleted) is only evaluated
    // again: its checkpoint was dropped when the result was first written.
    let trained_by = TrainedBy::of(&out);
    if !(resume && training_finished(&folder, run.budget)?) {
        // Stopped before its first checkpoint, a run restarts from step 1: this code's alone.
        let continues = resume && folder.checkpoint().is_file();
        trained_by
            .note(place.commit, !continues)
            .map_err(|e| ReproError::io(&out, e))?;
        meshvae::train(&request, &options, |record| {
            session_train += record.seconds;
            on_epoch(record);
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
    let (epochs_run, best_epoch) = trained
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
        epochs: run.budget.epochs().unwrap_or(epochs_run),
        step_budget: run.budget.max_steps(),
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
        rollbacks: status.as_ref().map(|s| s.rollbacks),
        test_mean_distance_rigid: Some(report.test.mean_distance_rigid),
        copy_split: report.copies.map(|c| CopySplitRecord {
            copy_in_training_meshes: c.copy_in_training.meshes,
            copy_in_training_mean_distance_rigid: c.copy_in_training.mean_distance_rigid,
            unseen_meshes: c.unseen.map_or(0, |u| u.meshes),
            unseen_mean_distance_rigid: c.unseen.map(|u| u.mean_distance_rigid),
        }),
        settings: Some(RunSettings {
            train: trained.spec.train.clone(),
            features: trained.spec.features,
            hierarchy: trained.spec.hierarchy,
        }),
        commit: place.commit.cloned(),
        trained_by: trained_by.for_record(place.commit),
        platform: Some(Platform::this()),
    };
    let path = run.result_path(place.records);
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

/// Whether the run's training is over and its selected weights were written: a fixed-epoch
/// run's log reaches its last epoch; a converged-plan run's `run.json` says it converged or used
/// its budget (`interrupted` while it trains, and after a kill).
fn training_finished(folder: &ModelFolder, budget: Budget) -> Result<bool, ReproError> {
    if !folder.weights().is_file() {
        return Ok(false);
    }
    match budget {
        Budget::Epochs(epochs) => {
            let path = folder.log();
            if !path.is_file() {
                return Ok(false);
            }
            let log = meshvae::read_log(&path).map_err(|e| ReproError::Results {
                path: path.clone(),
                message: e.to_string(),
            })?;
            Ok(log.last().is_some_and(|r| r.epoch == epochs))
        }
        Budget::Converged { .. } => {
            let status = meshvae::read_status(folder).map_err(|e| ReproError::Results {
                path: folder.status(),
                message: e.to_string(),
            })?;
            Ok(status.is_some_and(|s| {
                matches!(s.stop_reason, StopReason::Converged | StopReason::Budget)
            }))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshvae::{RunStatus, Selection};

    #[test]
    fn a_converged_run_is_finished_when_run_json_says_converged_or_budget() {
        let dir =
            std::env::temp_dir().join(format!("xtask-training-finished-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let folder = ModelFolder::new(&dir);
        let finished = |budget| training_finished(&folder, budget).unwrap();
        // Two epochs logged, no weights yet: nothing is finished.
        let line = |epoch: usize| {
            format!(
                "{{\"epoch\":{epoch},\"train_loss\":1.0,\"rec\":1.0,\"kl\":0.0,\"l2\":0.0,\
                 \"test_loss\":null,\"seconds\":0.1,\"step\":{epoch}}}\n"
            )
        };
        std::fs::write(folder.log(), line(1) + &line(2)).unwrap();
        assert!(!finished(Budget::Epochs(2)) && !finished(Budget::CONVERGED));
        std::fs::write(folder.weights(), b"").unwrap();
        // A fixed-epoch run goes by its log, a converged one by run.json.
        assert!(finished(Budget::Epochs(2)) && !finished(Budget::Epochs(3)));
        assert!(!finished(Budget::CONVERGED), "no run.json");
        let mut status = RunStatus {
            stop_reason: StopReason::Interrupted,
            epochs: 2,
            epoch_budget: 20_000,
            steps: 2,
            steps_per_epoch: 1,
            best_epoch: 2,
            selected_on: Selection::Validation,
            still_improving: true,
            lr: 1e-2,
            lr_cuts: 0,
            rollbacks: 0,
            clipped_steps: None,
            seconds: 0.2,
            path: "engine".into(),
            executor_reason: None,
            best_test_epoch: None,
            best_test_loss: None,
            phases: None,
        };
        for (reason, done) in [
            (StopReason::Interrupted, false),
            (StopReason::Budget, true),
            (StopReason::Converged, true),
        ] {
            status.stop_reason = reason;
            std::fs::write(folder.status(), serde_json::to_string(&status).unwrap()).unwrap();
            assert_eq!(finished(Budget::CONVERGED), done, "{reason}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
