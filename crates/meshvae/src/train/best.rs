//! The best epoch's state and how it reaches the model folder.
//!
//! The folder holds the weights of the best epoch (`weights.safetensors`) and, in the
//! checkpoint, the rest of that epoch's training state: a resumed run starts from the best
//! epoch and trains the later ones again, identically. A small model's best state is copied in
//! memory whenever it improves and written every `checkpoint_seconds`; a large one's is written
//! at once (a copy of its weights and moments would stay in memory beside the training buffers).
//!
//! The weights and the checkpoint must be of one epoch, and two files cannot be replaced at
//! once: the new weights are written whole to `weights.pending.safetensors` first, the
//! checkpoint replaces the old one (the moment the new state counts), and only then do the
//! weights take their place. A run killed between the two finds the pending weights of its
//! checkpoint's epoch and puts them in place ([`settle_pending`]); killed before the
//! checkpoint, the old pair is whole and the pending file is dropped.

use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::optim::adam::Adam;
use crate::train::checkpoint::{Checkpoint, Progress};
use crate::train::folder::ModelFolder;
use candle_core::{Tensor, Var};
use std::collections::BTreeMap;
use std::path::Path;

/// Copies of the weights, Adam's state and the progress of one epoch.
///
/// The copies are made once and then overwritten in place at each new best: a fresh copy is
/// 117 MB on horse-gallop (weights and both moments), and touching that much new memory every
/// few steps cost more than the copy itself.
pub(super) struct BestState {
    weights: BTreeMap<String, Var>,
    adam: Vec<(String, Var)>,
    progress: Progress,
    /// Whether the folder holds it already.
    written: bool,
}

impl BestState {
    /// The state of `model` and `adam` after the epoch `progress.epoch`.
    pub fn capture(model: &MeshVae, adam: &Adam, progress: &Progress) -> Result<Self> {
        let own = |t: Tensor| Var::from_tensor(&t);
        Ok(Self {
            weights: (model.tensors()?.into_iter())
                .map(|(n, t)| Ok((n, own(t)?)))
                .collect::<Result<_>>()?,
            adam: (adam.state_tensors()?.into_iter())
                .map(|(n, t)| Ok((n, own(t)?)))
                .collect::<Result<_>>()?,
            progress: *progress,
            written: false,
        })
    }

    /// Makes this the state after `progress.epoch`, reusing the copies' memory.
    pub fn recapture(&mut self, model: &MeshVae, adam: &Adam, progress: &Progress) -> Result<()> {
        let live = adam.state_shared()?;
        let same_adam = live.len() == self.adam.len()
            && (live.iter().zip(&self.adam)).all(|((a, t), (b, v))| a == b && t.dims() == v.dims());
        let same_weights = model.named_vars().count() == self.weights.len()
            && (model.named_vars()).all(|(n, _)| self.weights.contains_key(n));
        if !(same_adam && same_weights) {
            // A rollback adds a counter to Adam's state: copy afresh.
            *self = Self::capture(model, adam, progress)?;
            return Ok(());
        }
        for (name, var) in model.named_vars() {
            self.weights[name].set(var.as_tensor())?;
        }
        for ((_, t), (_, copy)) in live.iter().zip(&self.adam) {
            copy.set(t)?;
        }
        self.progress = *progress;
        self.written = false;
        Ok(())
    }

    /// The weights, sharing the copies' memory (valid until the next [`Self::recapture`]).
    pub fn weights(&self) -> BTreeMap<String, Tensor> {
        (self.weights.iter())
            .map(|(n, v)| (n.clone(), v.as_tensor().clone()))
            .collect()
    }

    /// Writes the weights, then the checkpoint, unless already written.
    pub fn write(&mut self, model: &MeshVae, folder: &ModelFolder) -> Result<()> {
        if self.written {
            return Ok(());
        }
        let adam = self
            .adam
            .iter()
            .map(|(n, v)| (n.clone(), v.as_tensor().clone()));
        commit(
            model,
            &self.weights(),
            adam.collect(),
            &self.progress,
            folder,
        )?;
        self.written = true;
        Ok(())
    }
}

/// Writes `weights` and the checkpoint of `progress.epoch` as one pair (see the module doc).
fn commit(
    model: &MeshVae,
    weights: &BTreeMap<String, Tensor>,
    adam: Vec<(String, Tensor)>,
    progress: &Progress,
    folder: &ModelFolder,
) -> Result<()> {
    let pending = folder.pending_weights();
    model.save_snapshot(weights, &pending, Some(progress.epoch))?;
    Checkpoint::save(&folder.checkpoint(), model.config(), adam, progress)?;
    let target = folder.weights();
    std::fs::rename(&pending, &target).map_err(|e| VaeError::io(&target, e))
}

/// Finishes or undoes a write that a kill interrupted: pending weights of the checkpoint's
/// epoch take their place, any others are removed. `model` only reads the file.
pub(super) fn settle_pending(folder: &ModelFolder, model: &mut MeshVae) -> Result<()> {
    let pending = folder.pending_weights();
    if !pending.is_file() {
        return Ok(());
    }
    let checkpoint = folder.checkpoint();
    let of_checkpoint = match checkpoint.is_file() {
        true => Checkpoint::epoch(&checkpoint)?,
        false => None,
    };
    // Reading the weights checks them whole (checksum) and tells their epoch.
    let of_pending = model.load_epoch(&pending).ok().flatten();
    if of_checkpoint.is_some() && of_pending == of_checkpoint {
        let target = folder.weights();
        std::fs::rename(&pending, &target).map_err(|e| VaeError::io(&target, e))
    } else {
        std::fs::remove_file(&pending).map_err(|e| VaeError::io(&pending, e))
    }
}

/// Writes the current state (weights, then checkpoint) as the best epoch's, without copying it.
pub(super) fn write_current(
    model: &MeshVae,
    adam: &Adam,
    progress: &Progress,
    folder: &ModelFolder,
) -> Result<()> {
    // The live tensors, not copies: nothing changes them while they are written.
    let weights: BTreeMap<String, Tensor> = (model.trainable_vars().into_iter())
        .chain(model.state_vars())
        .map(|(name, var)| (name, var.as_tensor().clone()))
        .collect();
    commit(model, &weights, adam.state_shared()?, progress, folder)
}

/// A copy of the model's tensors if small enough to keep in memory until the next write;
/// otherwise the weights are written to `path` now (so that a copy of a large model, ~200 MB on
/// a 42k-vertex mesh, does not stay in memory through the next epochs).
pub(super) fn keep_weights(
    model: &MeshVae,
    in_memory: bool,
    path: &Path,
    epoch: usize,
) -> Result<Option<BTreeMap<String, Tensor>>> {
    if in_memory {
        return Ok(Some(model.tensors()?));
    }
    model.save_snapshot(&model.tensors()?, path, Some(epoch))?;
    Ok(None)
}
