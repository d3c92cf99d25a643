//! A finished run's record (`<column>.result.json` beside its model folder): its numbers, and the
//! commit, settings and machine that made it; whether a record is today's (reused) or stale
//! (trained again).

use super::ReproError;
use super::commit::Commit;
use super::plan::{Budget, Run};
pub use super::settings::{RunSettings, setting_differences};
use meshvae::{ModelConfig, Platform, StopReason};
use serde::{Deserialize, Serialize};
use std::path::Path;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::plan::{self, COLUMNS, PROTOCOLS};
    use meshvae::DEFAULT_MAX_STEPS;

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
}
