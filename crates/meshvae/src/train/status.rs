//! `run.json`: where a run stands and why it ended, written with every checkpoint.

use crate::error::Result;
use crate::train::folder::ModelFolder;
use crate::train::phases::PhaseSeconds;
use crate::train::schedule::StopReason;
use crate::train::split::Selection;
use serde::{Deserialize, Serialize};

/// The state of a model's training run. While the run goes on (and if it is killed) its
/// `stop_reason` is `interrupted`; the last checkpoint of a finished run writes `converged` or
/// `budget`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStatus {
    pub stop_reason: StopReason,
    /// Epochs finished, and the budget in epochs.
    pub epochs: usize,
    pub epoch_budget: usize,
    /// Optimizer steps taken, and how many one epoch takes.
    pub steps: u64,
    pub steps_per_epoch: usize,
    /// The epoch of the weights in `weights.safetensors`, and the loss that chose it.
    pub best_epoch: usize,
    pub selected_on: Selection,
    /// Whether the validation loss reached a new best within the schedule's patience (or the
    /// last tenth of the run without early stopping).
    pub still_improving: bool,
    /// The learning rate at the end, and how many times the schedule cut it.
    pub lr: f64,
    pub lr_cuts: usize,
    /// Times the loss diverged (became non-finite) and training went back to the best weights
    /// at half the rate (counted in `lr_cuts` too).
    #[serde(default)]
    pub rollbacks: usize,
    /// Steps whose gradient was clipped (`--clip`; absent when clipping was off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clipped_steps: Option<u64>,
    /// Seconds of training over every resumed part.
    pub seconds: f64,
    /// What computed the steps: `engine` (the hand-written CPU step) or `candle` (autograd).
    pub path: String,
    /// Why `candle` rather than the engine (absent for the engine and from older records).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub executor_reason: Option<String>,
    /// The epoch with the lowest test loss and that loss (the authors' choice of checkpoint;
    /// its weights are kept only when asked, `weights-selected-on-test.safetensors`). Absent
    /// without test meshes, and from older records.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_test_epoch: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_test_loss: Option<f64>,
    /// Where the training time went, by phase (of this process's part of the run; absent from
    /// older records).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phases: Option<PhaseSeconds>,
}

/// The folder's `run.json`, or `None` for a model trained before it existed.
pub fn read_status(folder: &ModelFolder) -> Result<Option<RunStatus>> {
    let path = folder.status();
    if !path.is_file() {
        return Ok(None);
    }
    folder.read_json(&path).map(Some)
}
