//! Training: a mesh set in, a model folder out (see [`folder`]; loaded for use by
//! [`crate::TrainedModel`]).
//!
//! Each epoch shuffles the training meshes, takes Adam steps on batches, measures the
//! validation and test losses (the authors' validation loss: w_rec · mean squared error with
//! z = μ and batch norm in inference mode, here a true mean over the meshes) and appends a line
//! to `log.jsonl`. The validation loss also drives the [`Schedule`]: the run stops, *converged*,
//! once the loss has not reached a new best for the schedule's patience after its decay (or,
//! without a decay, the rate is cut on plateaus); otherwise it ends with its budget ([`TrainConfig::steps`](crate::TrainConfig::steps) or
//! `epochs`). `run.json` says which ([`RunStatus`]; `interrupted` until the run ends). Every [`TrainOptions::checkpoint_seconds`] (and after the last epoch) it
//! writes the weights with the lowest validation loss so far (the training loss without
//! validation meshes) to `weights.safetensors`, and the whole state to
//! `checkpoint.safetensors`. The test loss is only logged, and chooses a second set of weights,
//! `weights-selected-on-test.safetensors`, kept for comparison with the authors' protocol (they
//! picked their checkpoint on the test half); measuring it changes nothing else, so no test
//! mesh influences the model or its checkpoint. A raised [`StopFlag`] (Ctrl-C, with
//! [`StopFlag::on_interrupt`]) stops the run after its current step with that write made first;
//! killing the process at any moment loses at most the epochs since the last write. `resume`
//! restarts from the checkpoint, and because every random draw comes from one seeded stream
//! saved with it, the resumed run ends with the same weights as an uninterrupted one.
//!
//! A conditional model (`model.labels` non-empty, e.g. from [`ModelConfig::conditional_on`](crate::ModelConfig::conditional_on))
//! trains on the set's labels: every mesh needs one of the model's labels and every label needs
//! a training mesh. The meshes' labels are saved in `config.json`; the split is drawn as for
//! any model.
//!
//! This folder: the epoch loop (`trainer.rs`; request and summary in `request.rs`, the stop
//! request in `stop.rs`), the saved settings (`config.rs`), losses, schedule, data, split, the
//! files a run writes (`folder.rs`, `checkpoint.rs`, `epoch_log.rs`, `status.rs`) and the loop's
//! helpers.

use crate::error::Result;
use trainer::Trainer;

mod bar;
mod best;
pub(crate) mod checkpoint;
pub(crate) mod config;
pub(crate) mod data;
mod epoch_log;
pub(crate) mod folder;
mod lock;
pub(crate) mod loss;
mod loss_pass;
mod phases;
mod request;
mod rollback;
pub(crate) mod scaling;
pub(crate) mod schedule;
mod setup;
pub(crate) mod split;
mod status;
mod stop;
mod trainer;

pub use epoch_log::{EpochRecord, SPIKE_FACTOR, SPIKE_WINDOW, loss_spikes, read_log};
pub use loss_pass::validation_loss;
pub use phases::PhaseSeconds;
pub use request::{TrainOptions, TrainRequest, TrainSummary, hierarchy_config};
pub use status::{RunStatus, read_status};
pub use stop::StopFlag;

/// Derives the training stream's seed from the user's (the split and the initial weights use
/// the seed itself).
fn stream_seed(seed: u64) -> u64 {
    seed ^ 0x7261_696E_5F73_6565
}

/// Trains (or resumes) a model; `on_epoch` sees every finished epoch.
pub fn train(
    request: &TrainRequest,
    options: &TrainOptions,
    on_epoch: impl FnMut(&EpochRecord),
) -> Result<TrainSummary> {
    let trainer = Trainer::new(request, options)?;
    match trainer.ended_before()? {
        Some(summary) => Ok(summary),
        None => trainer.run(on_epoch),
    }
}
