//! Recovery from a divergence: a non-finite loss sends training back to the weights of its
//! best epoch, with fresh Adam moments and half the learning rate, instead of ending the run.
//! At a rate as large as the default 1e-2 a run blows up now and then (the loss grows twenty-
//! fold in a few steps, then turns NaN); the halving acts as the rate cut the plateau rule had
//! not made yet.

use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::optim::adam::Adam;
use crate::train::checkpoint::Progress;
use crate::train::schedule::Schedule;
use candle_core::{CpuStorage, DType, Storage, Tensor};
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
    /// The initial weights, when the best ones cannot train (they diverged again before an
    /// epoch finished after the last rollback): training starts over from them.
    pub initial: Option<&'a HashMap<String, Tensor>>,
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
        match (self.initial, self.best) {
            (Some(initial), _) => model.set_tensors(initial, self.weights)?,
            (None, Some(tensors)) => {
                let tensors: HashMap<_, _> = tensors
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect();
                model.set_tensors(&tensors, self.weights)?;
            }
            (None, None) => model.load(self.weights)?,
        }
        adam.restart()?;
        progress.schedule.rollback(adam.step_count());
        Ok(())
    }

    /// The warning once [`Self::apply`] succeeded.
    pub fn message(&self, progress: &Progress) -> String {
        let from = if self.initial.is_some() {
            format!(
                "the weights of epoch {} diverged again, so training starts over from the \
                 initial weights",
                progress.best_epoch
            )
        } else {
            format!(
                "training goes on from the weights of epoch {}",
                progress.best_epoch
            )
        };
        format!(
            "warning: {}; {from} at half the learning rate ({:.1e})",
            self.what,
            progress.schedule.lr(self.schedule, self.base_lr, u64::MAX)
        )
    }
}

/// The name of the first weight (or batch-norm statistic) holding a NaN or an infinity, if any.
pub(super) fn non_finite_weight(model: &MeshVae) -> Result<Option<String>> {
    for (name, var) in model.trainable_vars().into_iter().chain(model.state_vars()) {
        if !all_finite(var.as_tensor())? {
            return Ok(Some(name));
        }
    }
    Ok(None)
}

/// Whether every element of `t` is finite. CPU floats are read in place: a converted copy of
/// every weight, checked after each epoch, cost 78 MB of fresh memory on horse-gallop.
fn all_finite(t: &Tensor) -> Result<bool> {
    {
        let (storage, layout) = t.storage_and_layout();
        if let (Storage::Cpu(cpu), Some((lo, hi))) = (&*storage, layout.contiguous_offsets()) {
            match cpu {
                CpuStorage::F32(v) => return Ok(finite_f32(&v[lo..hi])),
                CpuStorage::F64(v) => return Ok(v[lo..hi].iter().all(|x| x.is_finite())),
                _ => {}
            }
        }
    }
    let sum = t
        .to_dtype(DType::F64)?
        .abs()?
        .sum_all()?
        .to_scalar::<f64>()?;
    Ok(sum.is_finite())
}

/// Whether every value is finite, 8 lanes at a time: 0·x is 0 for a finite x and NaN for an
/// infinite or NaN one, and the lanes' sums keep a NaN (a short-circuiting `all` does not
/// vectorise: checked once per epoch over 9.75 M weights it was 1.8 % of a horse-gallop run).
fn finite_f32(v: &[f32]) -> bool {
    let mut lanes = [0.0f32; 8];
    let chunks = v.chunks_exact(8);
    let tail = chunks.remainder();
    for chunk in chunks {
        for (l, &x) in lanes.iter_mut().zip(chunk) {
            *l += x * 0.0;
        }
    }
    lanes.iter().all(|l| *l == 0.0) && tail.iter().all(|x| x.is_finite())
}

/// Every weight and batch-norm statistic of `model` by name (what [`MeshVae::set_tensors`]
/// takes).
pub(super) fn tensors_of(model: &MeshVae) -> HashMap<String, Tensor> {
    model
        .trainable_vars()
        .into_iter()
        .chain(model.state_vars())
        .map(|(name, var)| (name, var.as_tensor().clone()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::all_finite;
    use candle_core::{Device, Tensor};

    #[test]
    fn all_finite_reads_f32_f64_and_strided_tensors() -> candle_core::Result<()> {
        let cpu = &Device::Cpu;
        let f32s = |v: &[f32]| Tensor::new(v, cpu);
        assert!(all_finite(&f32s(&[1.0, -2.0, f32::MAX])?).unwrap());
        assert!(!all_finite(&f32s(&[1.0, f32::NAN])?).unwrap());
        assert!(!all_finite(&f32s(&[f32::NEG_INFINITY, 0.0])?).unwrap());
        // Past the 8-lane chunks, and in every lane of them.
        for at in 0..19 {
            let mut v = vec![1.5f32; 19];
            assert!(all_finite(&f32s(&v)?).unwrap());
            v[at] = f32::INFINITY;
            assert!(!all_finite(&f32s(&v)?).unwrap(), "inf at {at}");
            v[at] = f32::NAN;
            assert!(!all_finite(&f32s(&v)?).unwrap(), "NaN at {at}");
        }
        assert!(!all_finite(&Tensor::new(&[0.0f64, f64::INFINITY], cpu)?).unwrap());
        // A transposed view is not contiguous: the converted copy decides.
        let m = Tensor::new(&[[1.0f32, f32::NAN], [3.0, 4.0]], cpu)?.t()?;
        assert!(!m.is_contiguous());
        assert!(!all_finite(&m).unwrap());
        let m = Tensor::new(&[[1.0f32, 2.0], [3.0, 4.0]], cpu)?.t()?;
        assert!(all_finite(&m).unwrap());
        Ok(())
    }
}
