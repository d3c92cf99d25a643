//! What [`train`](super::train) is asked ([`TrainRequest`]: the set and the settings;
//! [`TrainOptions`]: how to run) and what it returns ([`TrainSummary`]).

use super::EpochRecord;
use super::config::TrainConfig;
use super::stop::StopFlag;
use crate::executor::ExecutorChoice;
use crate::net::config::ModelConfig;
use crate::train::schedule::StopReason;
use crate::train::split::{Selection, Split};
use candle_core::Device;
use deform_features::FeatureOptions;
use mesh_hierarchy::HierarchyConfig;
use mesh_io::MeshSet;
use std::path::PathBuf;

/// What to train on and with which settings.
#[derive(Debug, Clone)]
pub struct TrainRequest<'a> {
    pub set: &'a MeshSet,
    /// Where the set came from (recorded so that `eval` can find it again).
    pub source: Option<PathBuf>,
    pub out: PathBuf,
    pub model: ModelConfig,
    pub train: TrainConfig,
    pub features: FeatureOptions,
    /// Ratio, λmax and de-pooling of the hierarchy; its pooler and level count are taken from
    /// the model configuration.
    pub hierarchy: HierarchyConfig,
    /// Explicit split; `None` draws one from `train.seed` and `train.test_fraction`.
    pub split: Option<Split>,
}

/// How to run.
#[derive(Debug, Clone)]
pub struct TrainOptions {
    /// Continue the model in `out` from its checkpoint (settings must match, epochs may grow).
    pub resume: bool,
    /// Replace a model already in `out`.
    pub force: bool,
    /// Draw a progress bar on stderr.
    pub progress: bool,
    /// Write the checkpoint (and the best weights) after an epoch once this many seconds have
    /// passed since the last write, and always after the last epoch. 0 = after every epoch.
    /// A checkpoint of the paper's network on horse-gallop is ~120 MB, so writing it every
    /// epoch of a 0.5 s epoch would dominate the run; a kill loses at most this much work.
    pub checkpoint_seconds: f64,
    /// Models with up to this many parameters keep their best weights in memory until the next
    /// checkpoint, and their training engine from one epoch to the next; larger ones write their
    /// best weights as soon as they improve and rebuild the engine every epoch, so that neither
    /// a copy of a large model (~200 MB on a 42k-vertex mesh) nor the engine's buffers stay in
    /// memory beside the validation and checkpoint work.
    pub best_in_memory_params: usize,
    /// Keep the weights with the lowest test loss in `weights-selected-on-test.safetensors`
    /// (for `meshvae eval --select-on-test`, the authors' protocol); otherwise only their epoch
    /// and loss are recorded, in `run.json`.
    pub keep_selected_on_test: bool,
    /// Measure the test loss (only logged, never used for a choice of the run) after an epoch
    /// once this many optimizer steps have passed since it was last measured, and after the
    /// last epoch; 1 = every epoch. On a small set (one step an epoch) the test pass costs as
    /// much as a third of the step, so measuring it every epoch would slow training by that.
    pub test_every_steps: usize,
    pub device: Device,
    /// Train with the hand-written CPU step ([`crate::EngineExecutor`]) whenever it supports the model;
    /// `false` forces candle's autograd path (the reference).
    pub engine: bool,
    /// Stops the run cleanly once raised (see [`StopFlag`]; [`StopFlag::on_interrupt`] for
    /// Ctrl-C): the best epoch's state is written and [`train`](super::train) returns
    /// [`VaeError::Interrupted`](crate::VaeError::Interrupted).
    pub stop: Option<StopFlag>,
    /// Tests only: the loss of this optimizer step (counted from 1) is taken as non-finite,
    /// once, to exercise the recovery from a divergence.
    #[doc(hidden)]
    pub fail_step: Option<u64>,
    /// Tests only: with `fail_step`, the first step after that rollback fails too (best
    /// weights that cannot take a step).
    #[doc(hidden)]
    pub fail_after_rollback: bool,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            resume: false,
            force: false,
            progress: false,
            checkpoint_seconds: 60.0,
            best_in_memory_params: 16 << 20,
            keep_selected_on_test: false,
            test_every_steps: 10,
            device: crate::executor::default_device(),
            engine: true,
            stop: None,
            fail_step: None,
            fail_after_rollback: false,
        }
    }
}

/// The outcome of [`train`](super::train).
#[derive(Debug, Clone, PartialEq)]
pub struct TrainSummary {
    /// Epochs run by this call (0 if the checkpoint had already reached the target).
    pub epochs_run: usize,
    /// The budget in epochs.
    pub epochs_total: usize,
    /// Why the run ended: converged or budget (an interrupted run returns no summary).
    pub stop_reason: StopReason,
    /// Optimizer steps over the whole run (resumed parts included).
    pub steps: u64,
    /// Whether the validation loss reached a new best within the schedule's patience (or the
    /// last tenth of the run): a run cut by its budget while this holds had not finished
    /// learning.
    pub still_improving: bool,
    /// The learning rate at the end.
    pub lr: f64,
    /// Seconds of training over every resumed part of the run.
    pub seconds_total: f64,
    pub last: Option<EpochRecord>,
    pub best_epoch: usize,
    /// The best epoch's loss on the meshes that chose it (`selected_on`).
    pub best_loss: f64,
    pub selected_on: Selection,
    pub seconds: f64,
    /// What computed this call's steps (`None` when it ran none).
    pub executor: Option<ExecutorChoice>,
}

/// The hierarchy settings a model configuration needs: `base` (the user's λmax and
/// de-pooling) with the model's pooler and levels, and for the other networks their own ratio.
pub fn hierarchy_config(model: &ModelConfig, base: HierarchyConfig) -> HierarchyConfig {
    let own = model.hierarchy_config();
    HierarchyConfig {
        pooler: own.pooler,
        levels: own.levels,
        ratio: if model.net.is_ours() {
            base.ratio
        } else {
            own.ratio
        },
        ..base
    }
}
