//! One run: train (resuming a model folder left by an interrupted run), evaluate, and record the
//! numbers in a small JSON beside the model folder. A run whose JSON holds today's settings is
//! not repeated; one made with other settings is trained again.

use super::ReproError;
use super::commit::{Commit, TrainedBy};
use super::plan::{Budget, Run};
pub use super::settings::{RunSettings, setting_differences};
use candle_core::Device;
use mesh_io::MeshSet;
use meshvae::Platform;
use meshvae::{
    EpochRecord, ModelConfig, ModelFolder, StopReason, TrainOptions, TrainRequest, TrainedModel,
};
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
    /// The plan's epochs; in the converged plan, the epochs the run took.
    pub epochs: usize,
    /// The converged plan's step budget: the run trained with `meshvae train`'s default rate
    /// and schedule until converged or this many steps (`Budget::Converged`). Absent from
    /// fixed-epoch runs (every result written before the converged plan), whose `epochs` is
    /// their budget.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_budget: Option<usize>,
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
    /// Blow-ups: how often the loss went NaN and training went back to its best weights (its
    /// initial ones where those diverge again) at half the rate (`run.json`'s `rollbacks`). A run that loses its rate early can stop
    /// higher, so a close comparison needs it; absent from results written before records
    /// kept it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rollbacks: Option<usize>,
    /// The rigid mean distance over the test meshes whose shape a training mesh repeats, and
    /// over the others, with their counts; present where the split put copies of test shapes
    /// among the training meshes (`--split-by-mesh` on horse-gallop).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub copy_split: Option<CopySplitRecord>,
    /// The training, feature and hierarchy settings the run trained with, so that a record is
    /// not reused once a default changes (learning rate, schedule, normalisation, de-pooling).
    /// Absent from results written before records kept them; those match on the rest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<RunSettings>,
    /// The code that wrote this record (`cargo xtask reproduce --check` retrains it and says
    /// whether the numbers still agree). Absent from records written before they kept it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commit: Option<Commit>,
    /// Every commit that trained the run, when that is not `commit` alone: a run resumed by
    /// other code, or a finished model folder evaluated again (`unrecorded`: training before
    /// this was kept; empty: none known). Absent when `commit` trained it all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trained_by: Option<Vec<Commit>>,
    /// The machine that trained it, as far as the numbers depend on it (`--check` can match
    /// them digit for digit only on the same). Absent from records written before they kept it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub platform: Option<Platform>,
}

/// [`meshvae::CopySplit`] as a run records it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CopySplitRecord {
    pub copy_in_training_meshes: usize,
    pub copy_in_training_mean_distance_rigid: f64,
    pub unseen_meshes: usize,
    pub unseen_mean_distance_rigid: Option<f64>,
}

impl RunResult {
    /// The plan the run belongs to.
    pub fn budget(&self) -> Budget {
        match self.step_budget {
            Some(max_steps) => Budget::Converged { max_steps },
            None => Budget::Epochs(self.epochs),
        }
    }

    /// Whether this result was produced by `run` (same data set, protocol, column, seed,
    /// budget, kind of split and network, and the same settings; a record without settings
    /// is taken to have trained with [`RunSettings::unrecorded`]).
    pub fn matches(&self, run: &Run, model: &ModelConfig) -> bool {
        self.matches_settings(run, model, &RunSettings::of(run, model))
    }

    /// [`Self::matches`] against the settings `current` rather than today's.
    pub fn matches_settings(&self, run: &Run, model: &ModelConfig, current: &RunSettings) -> bool {
        self.differences(run, model, current).is_empty()
    }

    /// What differs between this record and `run` trained with `current`, one phrase each
    /// (`train.lr 0.001 → 0.01`); empty where the record is that run's.
    pub fn differences(
        &self,
        run: &Run,
        model: &ModelConfig,
        current: &RunSettings,
    ) -> Vec<String> {
        let mut differences = Vec::new();
        let mut field = |name: &str, recorded: String, now: String| {
            if recorded != now {
                differences.push(format!("{name} {recorded} → {now}"));
            }
        };
        field("data set", self.dataset.clone(), run.dataset.name.into());
        field("protocol", self.protocol.clone(), run.protocol.id.into());
        field("column", self.column.clone(), run.column.id.into());
        field("seed", self.seed.to_string(), run.seed.to_string());
        field("budget", self.budget().dir_name(), run.budget.dir_name());
        field(
            "split by shape",
            self.split_by_shape.to_string(),
            run.by_shape.to_string(),
        );
        if &self.model != model {
            differences.push("network (the column's definition changed)".into());
        }
        let recorded = match &self.settings {
            Some(s) => s.clone(),
            None => RunSettings::unrecorded(run, model),
        };
        differences.extend(setting_differences(&recorded, current));
        differences
    }

    /// Whether the run stopped because its validation loss converged.
    pub fn converged(&self) -> bool {
        self.stop_reason.as_deref() == Some(StopReason::Converged.as_str())
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

/// What `records` holds for one run.
#[derive(Debug, Clone, PartialEq)]
pub enum Recorded {
    /// No record: the run has not finished.
    Missing,
    /// A record of this very run, with today's settings: reused.
    Current(Box<RunResult>),
    /// A record of the run made with other settings (or another network): trained again,
    /// never reused. `differences` says what changed ([`RunResult::differences`]).
    Stale {
        record: Box<RunResult>,
        differences: Vec<String>,
    },
}

/// Reads `run`'s record from `records`, and whether it is today's.
pub fn recorded(run: &Run, records: &Path) -> Result<Recorded, ReproError> {
    let path = run.result_path(records);
    if !path.is_file() {
        return Ok(Recorded::Missing);
    }
    let record = read_record(&path).map_err(|e| match e {
        ReproError::Results { path, message } => ReproError::Results {
            path,
            message: format!("{message}; delete it to run again"),
        },
        other => other,
    })?;
    let model = run.column.model().map_err(|e| ReproError::run(run, e))?;
    let differences = record.differences(run, &model, &RunSettings::of(run, &model));
    Ok(if differences.is_empty() {
        Recorded::Current(Box::new(record))
    } else {
        Recorded::Stale {
            record: Box::new(record),
            differences,
        }
    })
}

/// Reads a run's record.
pub fn read_record(path: &Path) -> Result<RunResult, ReproError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReproError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| ReproError::Results {
        path: path.to_path_buf(),
        message: format!("unreadable run result ({e})"),
    })
}

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
    use crate::reproduce::plan::{self, COLUMNS, PROTOCOLS};
    use meshvae::{DEFAULT_MAX_STEPS, RunStatus, Selection};

    /// A record of the 600-epoch plan as it was written before the converged plan (and before
    /// records kept their commit and settings).
    const OLD_RECORD: &str = include_str!("../../testdata/e600-ours.result.json");

    fn run(budget: Budget) -> Run {
        Run {
            dataset: plan::dataset("horse-gallop").unwrap(),
            protocol: &PROTOCOLS[0],
            budget,
            seed: 1,
            column: COLUMNS.iter().find(|c| c.is_ours()).unwrap(),
            by_shape: true,
        }
    }

    fn matches(result: &RunResult, run: &Run) -> bool {
        result.matches(run, &run.column.model().unwrap())
    }

    #[test]
    fn old_records_match_their_fixed_epoch_runs_only() {
        let old: RunResult = serde_json::from_str(OLD_RECORD).unwrap();
        assert_eq!((old.epochs, old.step_budget), (600, None));
        assert_eq!(old.budget(), Budget::Epochs(600));
        assert!(matches(&old, &run(Budget::Epochs(600))));
        assert!(!matches(&old, &run(Budget::Epochs(601))));
        assert!(!matches(&old, &run(Budget::CONVERGED)));
        assert!(!old.converged());
        // Written back, it stays a fixed-epoch record.
        let value = serde_json::to_value(&old).unwrap();
        assert!(value.get("step_budget").is_none(), "{value}");
        assert_eq!(serde_json::from_value::<RunResult>(value).unwrap(), old);
    }

    #[test]
    fn converged_records_match_converged_runs_only() {
        let mut converged: RunResult = serde_json::from_str(OLD_RECORD).unwrap();
        converged.step_budget = Some(DEFAULT_MAX_STEPS);
        converged.stop_reason = Some("converged".into());
        converged.steps = Some(5400);
        let plan = run(Budget::CONVERGED);
        converged.settings = Some(RunSettings::of(&plan, &plan.column.model().unwrap()));
        // Even a converged run that took exactly 600 epochs is not a run of the 600-epoch plan.
        for epochs in [600, 1234] {
            converged.epochs = epochs;
            assert_eq!(converged.budget(), Budget::CONVERGED);
            assert!(matches(&converged, &run(Budget::CONVERGED)));
            assert!(!matches(&converged, &run(Budget::Epochs(600))));
            assert!(!matches(
                &converged,
                &run(Budget::Converged { max_steps: 4 })
            ));
        }
        assert!(converged.converged());
        let text = serde_json::to_string(&converged).unwrap();
        assert!(text.contains("\"step_budget\":20000"), "{text}");
        let back: RunResult = serde_json::from_str(&text).unwrap();
        assert_eq!(back, converged);
        assert!(matches(&back, &run(Budget::CONVERGED)));
    }

    #[test]
    fn a_record_trained_with_other_settings_is_not_reused() {
        let mut record: RunResult = serde_json::from_str(OLD_RECORD).unwrap();
        let plan = run(Budget::CONVERGED);
        record.step_budget = Some(DEFAULT_MAX_STEPS);
        let model = plan.column.model().unwrap();
        // Records written before they kept their settings trained with the defaults of that
        // time (the plateau schedule, TF's β₂, one rate, no clipping), not today's: they are
        // trained again rather than reused.
        assert!(record.settings.is_none() && !matches(&record, &plan));
        let mut then = RunSettings::of(&plan, &model);
        then.train.lr = 1e-2;
        then.train.schedule = meshvae::Schedule::plateau();
        then.train.adam_beta2 = 0.999;
        then.train.head_lr_scale = 1.0;
        then.train.grad_clip = 0.0;
        assert!(record.matches_settings(&plan, &model, &then));
        // Under those defaults, a change to any one of them would not reuse it either.
        let changed = |edit: &dyn Fn(&mut RunSettings)| {
            let mut current = then.clone();
            edit(&mut current);
            !record.matches_settings(&plan, &model, &current)
        };
        assert!(changed(&|s| s.train.lr = 5e-3));
        assert!(changed(&|s| s.train.schedule = meshvae::Schedule::cosine()));
        assert!(changed(&|s| s.train.schedule.validate_every_steps = 10));
        assert!(changed(&|s| s.train.adam_beta2 = 0.99));
        assert!(changed(&|s| s.train.head_lr_scale = 0.3));
        assert!(changed(&|s| s.train.grad_clip = 2.0));
        record.settings = Some(RunSettings::of(&plan, &model));
        assert!(matches(&record, &plan));
        // A default that changed since the run (the rate, the normalisation, the de-pooling)
        // makes the record stale: the run trains again.
        let stale = |edit: &dyn Fn(&mut RunSettings)| {
            let mut r = record.clone();
            edit(r.settings.as_mut().unwrap());
            !matches(&r, &plan)
        };
        assert!(stale(&|s| s.train.lr *= 0.5));
        assert!(stale(&|s| s.train.normalize_quantile = 0.0));
        assert!(stale(&|s| s.train.schedule.patience += 1));
        assert!(stale(&|s| s.features.integrable = !s.features.integrable));
        assert!(stale(&|s| s.hierarchy.ratio = 0.25));
        // Written and read back, the settings survive.
        let text = serde_json::to_string(&record).unwrap();
        assert!(text.contains("\"settings\""), "{text}");
        assert_eq!(serde_json::from_str::<RunResult>(&text).unwrap(), record);
    }

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
