//! The losses measured after an epoch: the validation and test passes (inference mode, z = μ).

use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::train::data::MeshData;
use crate::train::loss::LossWeights;
use candle_core::Device;

/// w_rec · mean over `ids` of the squared error with z = μ (inference mode), or `None`.
pub fn validation_loss(
    model: &MeshVae,
    data: &MeshData,
    ids: &[usize],
    batch: usize,
    weights: &LossWeights,
    device: &Device,
) -> Result<Option<f64>> {
    epoch_loss(model, data, ids, batch, weights, device, None)
}

/// [`validation_loss`], through `engine` if given (it must be the model's).
pub(super) fn epoch_loss(
    model: &MeshVae,
    data: &MeshData,
    ids: &[usize],
    batch: usize,
    weights: &LossWeights,
    device: &Device,
    mut engine: Option<&mut crate::cpu::Engine>,
) -> Result<Option<f64>> {
    if ids.is_empty() {
        return Ok(None);
    }
    let mut sum = 0.0;
    for chunk in ids.chunks(batch.max(1)) {
        let x = data.batch(chunk, device)?;
        let c = data.conditions(model, chunk)?;
        let error = match engine.as_deref_mut() {
            Some(engine) => engine.rec_error_cond(model, &x, c.as_ref(), weights)?,
            None => model.rec_error_cond(&x, c.as_ref(), weights)?,
        };
        sum += error * chunk.len() as f64;
    }
    Ok(Some(sum / ids.len() as f64))
}
