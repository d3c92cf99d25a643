//! The losses measured after an epoch: the validation and test passes (inference mode, z = μ).

use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::executor::{Batch, Executor};
use crate::train::data::MeshData;
use crate::train::loss::LossWeights;
use candle_core::Device;

/// w_rec · mean over `ids` of the reconstruction error with z = μ (inference mode), or `None`
/// without meshes, computed by `executor` (the model's).
pub fn validation_loss(
    model: &MeshVae,
    data: &MeshData,
    ids: &[usize],
    batch: usize,
    weights: &LossWeights,
    device: &Device,
    executor: &mut dyn Executor,
) -> Result<Option<f64>> {
    if ids.is_empty() {
        return Ok(None);
    }
    let mut sum = 0.0;
    for chunk in ids.chunks(batch.max(1)) {
        let x = data.batch(chunk, device)?;
        let c = data.conditions(model, chunk)?;
        let batch = Batch {
            x: &x,
            c: c.as_ref(),
        };
        let error = executor.rec_error(model, batch, weights)?;
        sum += error * chunk.len() as f64;
    }
    Ok(Some(sum / ids.len() as f64))
}
