//! [`Checkpoint`]: what an interrupted run resumes from, beside the weights it continues from.
//!
//! A checkpoint holds the training state of the best epoch so far, the epoch whose weights are
//! `weights.safetensors`: Adam's moments and step, the random stream, the schedule and the
//! counters. It does not hold the weights again (the folder would carry two copies, one of them
//! of a later, worse epoch): resuming loads `weights.safetensors`, checks that its `epoch`
//! metadata is the checkpoint's, and trains again the epochs after it. Every random draw comes
//! from the saved stream, so those epochs come out bit for bit as they did, and the resumed run
//! ends as an uninterrupted one would. Written atomically with the `mesh_io::stamped`
//! convention (`format` = `meshvae-checkpoint`, `version` = `3`, `writer`, `checksum`, verified
//! on loading).
//!
//! Tensors: Adam's state as `adam.step`, `adam.restarted_at`, `adam.m.<name>` and
//! `adam.v.<name>`, and the progress counters as `progress.*`, each described by the metadata
//! entry `progress` (see [`PROGRESS_DOC`]). Versions 1 and 2 held the state of the last epoch
//! and its weights as `model.<name>` (version 1: `adam.adam.*` and three-number `meta.*`
//! tensors); both still load.

use crate::candle::model::{MeshVae, stamped_error, tensor_entry};
use crate::error::{Result, VaeError};
use crate::net::config::ModelConfig;
use crate::optim::adam::Adam;
use crate::train::schedule::ScheduleState;
use candle_core::{DType, Device, Tensor};
use mesh_io::stamped::{Stamp, format_of, read_stamped, write_stamped};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// What a checkpoint's metadata says it is.
pub const CHECKPOINT_STAMP: Stamp = Stamp {
    format: "meshvae-checkpoint",
    version: 3,
};

/// The `progress` metadata entry: what each counter tensor holds.
pub const PROGRESS_DOC: &str = "progress.epochs_done: the epoch this state is of, whose weights \
    are weights.safetensors (its metadata entry `epoch` says the same); progress.best_epoch: the \
    same epoch, the best so far (lowest validation loss, or training loss without validation \
    meshes) and progress.best_loss its loss; \
    progress.best_test_epoch and progress.best_test_loss: the same on the test loss; \
    progress.rng: the training random stream's xoshiro256 state after the last epoch, four \
    u64 words as eight u32 (high word first); progress.schedule: the learning-rate schedule's \
    state; progress.seconds: training seconds over every resumed part; adam.step: optimizer \
    steps taken; adam.restarted_at: the step of the last moment reset, if any";

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
    /// Writes `adam` (Adam's state, [`Adam::state_tensors`]) and `progress` to `path`
    /// atomically: the state of epoch `progress.epoch`, whose weights (of a model configured
    /// as `config`) must already be in the folder's `weights.safetensors`.
    pub fn save(
        path: &Path,
        config: &ModelConfig,
        adam: Vec<(String, Tensor)>,
        progress: &Progress,
    ) -> Result<()> {
        // Adam's own names start with `adam.`.
        let mut map: BTreeMap<String, Tensor> = adam.into_iter().collect();
        let cpu = Device::Cpu;
        // safetensors has no u64 in candle: the random state as eight u32 words.
        let words: Vec<u32> = progress
            .rng
            .iter()
            .flat_map(|&w| [(w >> 32) as u32, w as u32])
            .collect();
        let count = |n: usize| Tensor::new(&[n as i64], &cpu);
        let real = |x: f64| Tensor::new(&[x], &cpu);
        map.insert("progress.rng".into(), Tensor::new(words.as_slice(), &cpu)?);
        map.insert("progress.epochs_done".into(), count(progress.epoch)?);
        map.insert("progress.best_epoch".into(), count(progress.best_epoch)?);
        map.insert(
            "progress.best_test_epoch".into(),
            count(progress.best_test_epoch)?,
        );
        map.insert("progress.best_loss".into(), real(progress.best_loss)?);
        map.insert(
            "progress.best_test_loss".into(),
            real(progress.best_test_loss)?,
        );
        map.insert(
            "progress.schedule".into(),
            Tensor::new(progress.schedule.to_vec().as_slice(), &cpu)?,
        );
        map.insert("progress.seconds".into(), real(progress.seconds)?);
        let config = serde_json::to_string(config)
            .map_err(|e| VaeError::model(path, format!("config to JSON: {e}")))?;
        let metadata = BTreeMap::from([
            ("config".to_string(), config),
            ("progress".to_string(), PROGRESS_DOC.to_string()),
            (
                "weights".to_string(),
                format!(
                    "weights.safetensors of epoch {} (not repeated here)",
                    progress.epoch
                ),
            ),
        ]);
        let entries = map.iter().map(|(n, t)| tensor_entry(n, t)).collect();
        write_stamped(path, CHECKPOINT_STAMP, metadata, entries)?;
        Ok(())
    }

    /// Restores `model` (from `weights`, or from the checkpoint itself for versions 1 and 2)
    /// and `adam` from `path` and returns the progress.
    ///
    /// Errors: a damaged or foreign file, or weights of another epoch than the checkpoint's (a
    /// run killed between writing the one and the other).
    pub fn load(
        path: &Path,
        weights: &Path,
        model: &mut MeshVae,
        adam: &mut Adam,
    ) -> Result<Progress> {
        let (version, map) = read(path, model)?;
        if version < 3 {
            set_model(path, &map, model)?;
        }
        // Version 1 prefixed Adam's own `adam.` names once more.
        let adam_state: HashMap<String, Tensor> = map
            .iter()
            .filter_map(|(k, v)| {
                let k = if version == 1 {
                    k.strip_prefix("adam.")?
                } else {
                    k
                };
                k.starts_with("adam.").then(|| (k.to_string(), v.clone()))
            })
            .collect();
        adam.load_state(&adam_state)
            .map_err(|e| VaeError::model(path, format!("optimiser state: {e}")))?;
        let get = |name: &str| {
            map.get(name)
                .ok_or_else(|| VaeError::model(path, format!("no tensor `{name}`")))
        };
        let f64s =
            |name: &str| -> Result<Vec<f64>> { Ok(get(name)?.to_dtype(DType::F64)?.to_vec1()?) };
        let i64s =
            |name: &str| -> Result<Vec<i64>> { Ok(get(name)?.to_dtype(DType::I64)?.to_vec1()?) };
        let (words, epochs, best, schedule, seconds) = if version == 1 {
            (
                get("meta.rng")?.to_dtype(DType::U32)?.to_vec1::<u32>()?,
                i64s("meta.epoch")?,
                f64s("meta.best_loss")?,
                map.get("meta.schedule"),
                map.get("meta.seconds"),
            )
        } else {
            let one = |name: &str| -> Result<i64> {
                i64s(name)?
                    .first()
                    .copied()
                    .ok_or_else(|| VaeError::model(path, format!("empty tensor `{name}`")))
            };
            let real = |name: &str| -> Result<f64> {
                f64s(name)?
                    .first()
                    .copied()
                    .ok_or_else(|| VaeError::model(path, format!("empty tensor `{name}`")))
            };
            (
                get("progress.rng")?
                    .to_dtype(DType::U32)?
                    .to_vec1::<u32>()?,
                vec![
                    one("progress.epochs_done")?,
                    one("progress.best_epoch")?,
                    one("progress.best_test_epoch")?,
                ],
                vec![
                    real("progress.best_loss")?,
                    real("progress.best_test_loss")?,
                ],
                Some(get("progress.schedule")?),
                Some(get("progress.seconds")?),
            )
        };
        // Version-1 checkpoints written before the test-selected weights existed have two
        // epochs and one loss.
        let (8, &[epoch, best_epoch, ref test_epoch @ ..], &[best_loss, ref test_loss @ ..]) =
            (words.len(), epochs.as_slice(), best.as_slice())
        else {
            return Err(VaeError::model(path, "malformed progress tensors"));
        };
        let best_test_epoch = test_epoch.first().copied().unwrap_or(0);
        let best_test_loss = test_loss.first().copied().unwrap_or(f64::INFINITY);
        let mut rng = [0u64; 4];
        for (r, pair) in rng.iter_mut().zip(words.chunks_exact(2)) {
            *r = ((pair[0] as u64) << 32) | pair[1] as u64;
        }
        let schedule = match schedule {
            Some(t) => ScheduleState::from_slice(&t.to_dtype(DType::F64)?.to_vec1::<f64>()?)
                .ok_or_else(|| VaeError::model(path, "malformed schedule state"))?,
            None => ScheduleState::default(),
        };
        let seconds = match seconds {
            Some(t) => t.to_dtype(DType::F64)?.to_vec1::<f64>()?.first().copied(),
            None => None,
        };
        let epoch = epoch.max(0) as usize;
        if version >= 3 {
            let of_weights = model.load_epoch(weights)?;
            if of_weights != Some(epoch) {
                let found = of_weights.map_or("no epoch".into(), |e| format!("epoch {e}"));
                return Err(VaeError::model(
                    path,
                    format!(
                        "continues from the weights of epoch {epoch}, but {} holds {found} (the \
                         run was killed between writing the two): start again with --force",
                        weights.display()
                    ),
                ));
            }
        }
        Ok(Progress {
            epoch,
            rng,
            best_loss,
            best_epoch: best_epoch.max(0) as usize,
            best_test_loss,
            best_test_epoch: best_test_epoch.max(0) as usize,
            schedule,
            seconds: seconds.unwrap_or(0.0),
        })
    }

    /// The epoch whose state the checkpoint at `path` holds (`None` for versions 1 and 2,
    /// whose weights are inside).
    pub fn epoch(path: &Path) -> Result<Option<usize>> {
        let bytes = std::fs::read(path).map_err(|e| VaeError::io(path, e))?;
        if format_of(&bytes).is_none() {
            return Ok(None);
        }
        let file = read_stamped(&bytes, path, CHECKPOINT_STAMP).map_err(stamped_error)?;
        if file.version < 3 {
            return Ok(None);
        }
        let view = file
            .tensors
            .tensor("progress.epochs_done")
            .map_err(|e| VaeError::model(path, format!("no epoch: {e}")))?;
        let data: [u8; 8] = view
            .data()
            .try_into()
            .map_err(|_| VaeError::model(path, "malformed progress.epochs_done"))?;
        Ok(usize::try_from(i64::from_le_bytes(data)).ok())
    }

    /// Restores only the model's tensors from a version-1 or -2 checkpoint (to use an old model
    /// whose best weights were not saved); a version-3 checkpoint holds none.
    pub fn load_model_only(path: &Path, model: &mut MeshVae) -> Result<()> {
        let (version, map) = read(path, model)?;
        if version >= 3 {
            return Err(VaeError::model(
                path,
                "holds no weights (they are weights.safetensors, which is missing)",
            ));
        }
        set_model(path, &map, model)
    }
}

/// The checkpoint's version and tensors, its checksum verified.
fn read(path: &Path, model: &MeshVae) -> Result<(u32, HashMap<String, Tensor>)> {
    if !path.is_file() {
        return Err(VaeError::model(path, "no such checkpoint"));
    }
    let bytes = std::fs::read(path).map_err(|e| VaeError::io(path, e))?;
    // Version-1 checkpoints carry no metadata at all.
    let version = match format_of(&bytes) {
        None => 1,
        Some(_) => {
            read_stamped(&bytes, path, CHECKPOINT_STAMP)
                .map_err(stamped_error)?
                .version
        }
    };
    let map = candle_core::safetensors::load_buffer(&bytes, model.device())
        .map_err(|e| VaeError::model(path, format!("unreadable checkpoint: {e}")))?;
    Ok((version, map))
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
