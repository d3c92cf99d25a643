//! [`Checkpoint`]: the whole training state after an epoch, in one safetensors file, so that an
//! interrupted run resumes exactly where the last finished epoch left it: the model's trainable
//! and batch-norm tensors (`model.*`), Adam's moments and step (`adam.*`), and the epoch, random
//! state, best validation and test losses so far, learning-rate schedule and training time
//! (`meta.*`). One file, written atomically: a kill at any
//! moment leaves either the previous checkpoint or the new one.

use crate::adam::Adam;
use crate::error::{Result, VaeError};
use crate::model::MeshVae;
use crate::schedule::ScheduleState;
use candle_core::{DType, Device, Tensor};
use std::collections::HashMap;
use std::path::Path;

/// Training progress besides the tensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Epochs finished.
    pub epoch: usize,
    /// State of the training random stream after `epoch`.
    pub rng: [u64; 4],
    /// Lowest loss so far on the meshes that choose the best weights (validation, or training
    /// without validation meshes) and its epoch (infinite and 0 before any).
    pub best_loss: f64,
    pub best_epoch: usize,
    /// Lowest test loss so far and its epoch (for the weights selected on test).
    pub best_test_loss: f64,
    pub best_test_epoch: usize,
    /// The learning-rate schedule's state (checkpoints written before schedules existed read
    /// as a fresh state).
    pub schedule: ScheduleState,
    /// Seconds of training so far, over every resumed part (0 in older checkpoints).
    pub seconds: f64,
}

pub struct Checkpoint;

impl Checkpoint {
    /// Writes the state of `model`, `adam` and `progress` to `path` atomically.
    pub fn save(path: &Path, model: &MeshVae, adam: &Adam, progress: &Progress) -> Result<()> {
        let mut map: HashMap<String, Tensor> = HashMap::new();
        for (name, var) in model.trainable_vars().into_iter().chain(model.state_vars()) {
            map.insert(format!("model.{name}"), var.as_tensor().clone());
        }
        for (name, t) in adam.state_tensors()? {
            map.insert(format!("adam.{name}"), t);
        }
        let cpu = Device::Cpu;
        // safetensors has no u64 in candle: the random state as eight u32 words.
        let words: Vec<u32> = progress
            .rng
            .iter()
            .flat_map(|&w| [(w >> 32) as u32, w as u32])
            .collect();
        map.insert("meta.rng".into(), Tensor::new(words.as_slice(), &cpu)?);
        map.insert(
            "meta.epoch".into(),
            Tensor::new(
                &[
                    progress.epoch as i64,
                    progress.best_epoch as i64,
                    progress.best_test_epoch as i64,
                ],
                &cpu,
            )?,
        );
        map.insert(
            "meta.best_loss".into(),
            Tensor::new(&[progress.best_loss, progress.best_test_loss], &cpu)?,
        );
        map.insert(
            "meta.schedule".into(),
            Tensor::new(progress.schedule.to_vec().as_slice(), &cpu)?,
        );
        map.insert(
            "meta.seconds".into(),
            Tensor::new(&[progress.seconds], &cpu)?,
        );
        save_atomic(path, &map)
    }

    /// Restores `model` and `adam` from `path` and returns the progress.
    pub fn load(path: &Path, model: &mut MeshVae, adam: &mut Adam) -> Result<Progress> {
        let map = read(path, model)?;
        set_model(path, &map, model)?;
        let adam_state: HashMap<String, Tensor> = map
            .iter()
            .filter_map(|(k, v)| k.strip_prefix("adam.").map(|k| (k.to_string(), v.clone())))
            .collect();
        adam.load_state(&adam_state)
            .map_err(|e| VaeError::model(path, format!("optimiser state: {e}")))?;
        let get = |name: &str| {
            map.get(name)
                .ok_or_else(|| VaeError::model(path, format!("no tensor `{name}`")))
        };
        let words: Vec<u32> = get("meta.rng")?.to_dtype(DType::U32)?.to_vec1()?;
        let epochs: Vec<i64> = get("meta.epoch")?.to_vec1()?;
        let best: Vec<f64> = get("meta.best_loss")?.to_vec1()?;
        // Checkpoints written before the test-selected weights existed have two epochs and
        // one loss.
        let (8, &[epoch, best_epoch, ref test_epoch @ ..], &[best_loss, ref test_loss @ ..]) =
            (words.len(), epochs.as_slice(), best.as_slice())
        else {
            return Err(VaeError::model(path, "malformed meta tensors"));
        };
        let best_test_epoch = test_epoch.first().copied().unwrap_or(0);
        let best_test_loss = test_loss.first().copied().unwrap_or(f64::INFINITY);
        let mut rng = [0u64; 4];
        for (r, pair) in rng.iter_mut().zip(words.chunks_exact(2)) {
            *r = ((pair[0] as u64) << 32) | pair[1] as u64;
        }
        let schedule = match map.get("meta.schedule") {
            Some(t) => ScheduleState::from_slice(&t.to_dtype(DType::F64)?.to_vec1::<f64>()?)
                .ok_or_else(|| VaeError::model(path, "malformed meta.schedule"))?,
            None => ScheduleState::default(),
        };
        let seconds = match map.get("meta.seconds") {
            Some(t) => t.to_dtype(DType::F64)?.to_vec1::<f64>()?.first().copied(),
            None => None,
        };
        Ok(Progress {
            epoch: epoch.max(0) as usize,
            rng,
            best_loss,
            best_epoch: best_epoch.max(0) as usize,
            best_test_loss,
            best_test_epoch: best_test_epoch.max(0) as usize,
            schedule,
            seconds: seconds.unwrap_or(0.0),
        })
    }

    /// Restores only the model's tensors (to use a model whose best weights were not saved).
    pub fn load_model_only(path: &Path, model: &mut MeshVae) -> Result<()> {
        let map = read(path, model)?;
        set_model(path, &map, model)
    }
}

fn read(path: &Path, model: &MeshVae) -> Result<HashMap<String, Tensor>> {
    if !path.is_file() {
        return Err(VaeError::model(path, "no such checkpoint"));
    }
    candle_core::safetensors::load(path, model.device())
        .map_err(|e| VaeError::model(path, format!("unreadable checkpoint: {e}")))
}

fn set_model(path: &Path, map: &HashMap<String, Tensor>, model: &mut MeshVae) -> Result<()> {
    for (name, var) in model.trainable_vars().into_iter().chain(model.state_vars()) {
        let key = format!("model.{name}");
        let t = map.get(&key).ok_or_else(|| {
            VaeError::model(
                path,
                format!("no tensor `{name}`: another model's checkpoint?"),
            )
        })?;
        if t.dims() != var.dims() {
            return Err(VaeError::model(
                path,
                format!(
                    "tensor `{name}` has shape {:?}, the model expects {:?}",
                    t.dims(),
                    var.dims()
                ),
            ));
        }
        var.set(&t.to_dtype(var.dtype())?)?;
    }
    Ok(())
}

/// candle's `safetensors::save` writes tensor by tensor, without first building the whole file
/// in memory (a checkpoint of elephant-gallop is ~600 MB), but not atomically: so it writes a
/// hidden temporary file beside `path` and renames it.
fn save_atomic(path: &Path, map: &HashMap<String, Tensor>) -> Result<()> {
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{file_name}.tmp"));
    let result = candle_core::safetensors::save(map, &tmp)
        .map_err(VaeError::from)
        .and_then(|()| {
            // On disk before the rename, so that a crash cannot leave a renamed, empty file.
            std::fs::File::open(&tmp)
                .and_then(|f| f.sync_all())
                .and_then(|()| std::fs::rename(&tmp, path))
                .map_err(|e| VaeError::io(path, e))
        });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
