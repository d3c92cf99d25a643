//! Recovery from a divergence: a non-finite loss sends training back to the weights of its
//! best epoch, with fresh Adam moments and half the learning rate, instead of ending the run.
//! At a rate as large as the default 1e-2 a run blows up now and then (the loss grows twenty-
//! fold in a few steps, then turns NaN); the halving acts as the rate cut the plateau rule had
//! not made yet.

use crate::adam::Adam;
use crate::checkpoint::Progress;
use crate::error::{Result, VaeError};
use crate::model::MeshVae;
use crate::schedule::Schedule;
use candle_core::Tensor;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Restarts from the best weights this many times before a diverging run is given up.
const MAX_ROLLBACKS: usize = 3;

/// One divergence and what training can go back to.
pub(super) struct Recovery<'a> {
    /// What went wrong, e.g. "epoch 12: the loss is NaN (…)".
    pub what: String,
    /// The best weights kept in memory, if any (otherwise they are in `weights`).
    pub best: Option<&'a BTreeMap<String, Tensor>>,
    /// The best weights' file (written at every new best when the model is too large to keep
    /// in memory, and at every checkpoint).
    pub weights: &'a Path,
    pub schedule: &'a Schedule,
    pub base_lr: f64,
}

impl Recovery<'_> {
    /// Puts the best weights back, forgets Adam's moments and halves the rate; an error when
    /// there is nothing to go back to or the run has already restarted [`MAX_ROLLBACKS`] times.
    pub fn apply(
        &self,
        model: &mut MeshVae,
        adam: &mut Adam,
        progress: &mut Progress,
    ) -> Result<()> {
        let restarts = progress.schedule.rollbacks;
        if progress.best_epoch == 0 || restarts >= MAX_ROLLBACKS {
            let tried = if progress.best_epoch == 0 {
                "before any epoch finished, so there are no weights to go back to".to_string()
            } else {
                format!("after {restarts} restarts from the best weights at a smaller rate")
            };
            return Err(VaeError::Diverged(format!(
                "{}, {tried}; the checkpoint of epoch {} is kept — try a smaller learning rate \
                 (--lr)",
                self.what, progress.epoch
            )));
        }
        match self.best {
            Some(tensors) => {
                let tensors: HashMap<_, _> = tensors
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect();
                model.set_tensors(&tensors, self.weights)?;
            }
            None => model.load(self.weights)?,
        }
        adam.restart()?;
        progress.schedule.rollback();
        Ok(())
    }

    /// The warning once [`Self::apply`] succeeded.
    pub fn message(&self, progress: &Progress) -> String {
        format!(
            "warning: {}; training goes on from the weights of epoch {} at half the learning \
             rate ({:.1e})",
            self.what,
            progress.best_epoch,
            progress.schedule.lr(self.schedule, self.base_lr, u64::MAX)
        )
    }
}
