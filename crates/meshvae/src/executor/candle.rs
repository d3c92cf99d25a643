//! [`CandleExecutor`]: candle's autograd runs the steps; the model's own tensor code is the
//! whole executor (the reference the engine is checked against, and the path for the networks
//! and devices the engine does not cover).

use super::{Batch, Executor, ExecutorKind, StepReport, TrainStep};
use crate::candle::batch_norm::Mode;
use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::net::loss_weights::LossWeights;
use candle_core::{DType, Tensor};
use std::time::Instant;

/// candle's autograd as an [`Executor`]; it keeps nothing between calls.
#[derive(Debug, Clone, Copy, Default)]
pub struct CandleExecutor;

impl Executor for CandleExecutor {
    fn step(&mut self, model: &MeshVae, step: TrainStep<'_>) -> Result<StepReport> {
        let (Batch { x, c }, loss) = (step.batch, step.loss);
        let t = Instant::now();
        // The L2 term's gradient is applied by Adam (see `MeshVae::training_loss`).
        let l = model.training_loss(x, c, step.eps, loss)?;
        let total = l.total.to_dtype(DType::F64)?.to_scalar::<f64>()? + l.l2;
        let mut report = StepReport {
            total,
            rec: l.rec,
            kl: l.kl,
            l2: l.l2,
            finite: total.is_finite(),
            forward_backward_seconds: 0.0,
            update_seconds: 0.0,
        };
        if !report.finite {
            return Ok(report);
        }
        let grads = model.backward(&l.total)?;
        report.forward_backward_seconds = t.elapsed().as_secs_f64();
        let t = Instant::now();
        step.adam.step_with_l2(&grads, loss.l2)?;
        report.update_seconds = t.elapsed().as_secs_f64();
        Ok(report)
    }

    fn rec_error(&mut self, model: &MeshVae, batch: Batch<'_>, loss: &LossWeights) -> Result<f64> {
        model.rec_error(batch.x, batch.c, loss)
    }

    fn encode(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<(Tensor, Tensor)> {
        let e = model.encode(batch.x, batch.c, Mode::Eval)?;
        Ok((e.mu, e.sigma))
    }

    fn decode(&mut self, model: &MeshVae, z: Batch<'_>) -> Result<Tensor> {
        model.decode(z.x, z.c, Mode::Eval)
    }

    fn reconstruct(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<Tensor> {
        model.reconstruct(batch.x, batch.c)
    }

    fn kind(&self) -> ExecutorKind {
        ExecutorKind::Candle
    }
}
