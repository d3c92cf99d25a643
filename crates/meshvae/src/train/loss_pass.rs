//! The losses measured after an epoch: the validation and test passes (inference mode, z = μ).

use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::train::data::MeshData;
use crate::train::loss::LossWeights;
use candle_core::Device;

/// w_rec · mean over `ids` of the reconstruction error with z = μ (inference mode), or `None`
/// without meshes; through `engine` if given (it must be the model's: the same error without
/// candle's per-op allocations).
pub fn validation_loss(
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
            Some(engine) => engine.rec_error(model, &x, c.as_ref(), weights)?,
            None => model.rec_error(&x, c.as_ref(), weights)?,
        };
        sum += error * chunk.len() as f64;
    }
    Ok(Some(sum / ids.len() as f64))
}
