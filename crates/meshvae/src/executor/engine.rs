//! [`EngineExecutor`]: the CPU engine (`cpu::Engine`) as an [`Executor`] on candle's model.
//! The engine's own API takes host slices and a [`EngineModel`]; this file is where candle
//! meets it: the model's `Var`s lent in place, tensors viewed as slices and results made into
//! tensors again.

use super::{Batch, Executor, ExecutorKind, StepReport, TrainStep};
use crate::candle::model::MeshVae;
use crate::cpu::model::EngineModel;
use crate::cpu::{Engine, Inputs, StepLoss};
use crate::error::{Result, VaeError};
use crate::net::config::ModelConfig;
use crate::net::loss_weights::LossWeights;
use crate::net::plan::NetPlan;
use crate::numerics::host::{HostArray, HostSlice, HostTensor, HostVec, Precision};
use crate::optim::adam::Adam;
use candle_core::{CpuStorage, DType, Device, Storage, Tensor, Var};
use std::hash::{DefaultHasher, Hash, Hasher};
use std::time::Instant;

#[cfg(test)]
mod tests;

/// The hand-written CPU step and inference passes of one model (see `cpu/`), built for batches
/// of up to a given size.
#[derive(Debug)]
pub struct EngineExecutor {
    engine: Engine,
}

impl EngineExecutor {
    /// Why the engine cannot run `model`, or `None` if it can.
    pub fn unsupported(model: &MeshVae) -> Option<String> {
        Engine::unsupported(model)
    }

    /// The engine for `model` with buffers for batches of up to `max_batch` meshes; an error
    /// saying why where [`Self::unsupported`] declines the model.
    pub fn new(model: &MeshVae, max_batch: usize) -> Result<Self> {
        Ok(Self {
            engine: Engine::new(model, max_batch)?,
        })
    }

    /// The largest batch the engine's buffers hold.
    pub fn max_batch(&self) -> usize {
        self.engine.max_batch()
    }

    /// The forward and backward passes of [`Executor::step`] alone: the loss terms (the L2 term
    /// left to [`Self::apply_adam`]); the gradients stay in the engine.
    pub fn forward_backward(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
        eps: &Tensor,
        loss: &LossWeights,
    ) -> Result<StepLoss> {
        let engine = &mut self.engine;
        with_inputs(Batch { x, c }, |inputs| {
            with_host(eps, "ε", |eps| {
                engine.forward_backward(model, inputs, eps, loss)
            })
        })
    }

    /// Adam's update from the last [`Self::forward_backward`]'s gradients plus `l2 · θ`;
    /// returns the L2 term l2 · Σ ½‖θ‖² of the weights before the update.
    pub fn apply_adam(&self, adam: &mut Adam, l2: f64) -> Result<f64> {
        self.engine.apply_adam(adam, l2)
    }

    /// The norm of the last step's gradient (the L2 term's left out).
    pub fn grad_norm(&self) -> f64 {
        self.engine.grad_norm()
    }

    /// The last step's gradients as tensors shaped like `model`'s variables (for checks).
    pub fn gradients(&self, model: &MeshVae) -> Result<Vec<(String, Tensor)>> {
        let vars = model.trainable_vars();
        (self.engine.gradients().into_iter().zip(vars))
            .map(|((name, g), (_, v))| {
                let t = Tensor::from_vec(g, v.shape(), v.device())?.to_dtype(v.dtype())?;
                Ok((name, t))
            })
            .collect()
    }
}

impl Executor for EngineExecutor {
    fn step(&mut self, model: &MeshVae, step: TrainStep<'_>) -> Result<StepReport> {
        let (Batch { x, c }, loss) = (step.batch, step.loss);
        let t = Instant::now();
        let l = self.forward_backward(model, x, c, step.eps, loss)?;
        let forward_backward_seconds = t.elapsed().as_secs_f64();
        let report = |l2: f64, update_seconds: f64| {
            let total = l.rec + l.kl + l2;
            StepReport {
                total,
                rec: l.rec,
                kl: l.kl,
                l2,
                finite: total.is_finite(),
                forward_backward_seconds,
                update_seconds,
            }
        };
        if !(l.rec + l.kl).is_finite() {
            let l2 = model.l2_term()?.to_dtype(DType::F64)?.to_scalar::<f64>()? * loss.l2;
            return Ok(report(l2, 0.0));
        }
        let t = Instant::now();
        // Adam also returns the L2 term of the weights it started from.
        let l2 = self.apply_adam(step.adam, loss.l2)?;
        Ok(report(l2, t.elapsed().as_secs_f64()))
    }

    fn rec_error(&mut self, model: &MeshVae, batch: Batch<'_>, loss: &LossWeights) -> Result<f64> {
        let engine = &mut self.engine;
        with_inputs(batch, |inputs| engine.rec_error(model, inputs, loss))
    }

    fn encode(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<(Tensor, Tensor)> {
        let engine = &mut self.engine;
        let (mu, sigma) = with_inputs(batch, |inputs| engine.encode(model, inputs))?;
        let device = batch.x.device();
        Ok((tensor(mu, device)?, tensor(sigma, device)?))
    }

    fn decode(&mut self, model: &MeshVae, z: Batch<'_>) -> Result<Tensor> {
        let engine = &mut self.engine;
        let out = with_host(z.x, "z", |zh| {
            with_optional(z.c, |c| engine.decode(model, zh, c))
        })?;
        tensor(out, z.x.device())
    }

    fn reconstruct(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<Tensor> {
        let engine = &mut self.engine;
        let out = with_inputs(batch, |inputs| engine.reconstruct(model, inputs))?;
        tensor(out, batch.x.device())
    }

    fn kind(&self) -> ExecutorKind {
        ExecutorKind::Engine
    }
}

/// Runs `f` on the values of `t` (made contiguous) in host memory, borrowed in place.
fn with_host<R>(t: &Tensor, what: &str, f: impl FnOnce(HostArray<'_>) -> Result<R>) -> Result<R> {
    let not = |why: &str| VaeError::shape("Engine", format!("{what} {why}"));
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    let Storage::Cpu(cpu) = &*storage else {
        return Err(not("is not on the CPU"));
    };
    let (lo, hi) = (layout.contiguous_offsets()).ok_or_else(|| not("is not contiguous"))?;
    let data = match cpu {
        CpuStorage::F32(v) => HostSlice::F32(&v[lo..hi]),
        CpuStorage::F64(v) => HostSlice::F64(&v[lo..hi]),
        _ => return Err(not("has another dtype")),
    };
    f(HostArray {
        data,
        dims: t.dims(),
    })
}

/// [`with_host`] on a tensor that may be absent (a model's labels).
fn with_optional<R>(
    t: Option<&Tensor>,
    f: impl FnOnce(Option<HostArray<'_>>) -> Result<R>,
) -> Result<R> {
    match t {
        Some(t) => with_host(t, "the labels", |h| f(Some(h))),
        None => f(None),
    }
}

/// Runs `f` on the features x and labels c viewed as the engine's inputs.
fn with_inputs<R>(batch: Batch<'_>, f: impl FnOnce(Inputs<'_>) -> Result<R>) -> Result<R> {
    with_host(batch.x, "the features", |x| {
        with_optional(batch.c, |c| f(Inputs { x, c }))
    })
}

/// A tensor of the engine's output on `device`.
fn tensor(t: HostTensor, device: &Device) -> Result<Tensor> {
    Ok(match t.data {
        HostVec::F32(v) => Tensor::from_vec(v, t.dims, device)?,
        HostVec::F64(v) => Tensor::from_vec(v, t.dims, device)?,
    })
}

/// Candle's model as the engine reads it: its plan, and its `Var`s lent in place.
impl EngineModel for MeshVae {
    fn config(&self) -> &ModelConfig {
        MeshVae::config(self)
    }

    fn plan(&self) -> Option<&NetPlan> {
        MeshVae::plan(self)
    }

    fn precision(&self) -> std::result::Result<Precision, String> {
        if !self.device().is_cpu() {
            return Err("the model is not on the CPU".into());
        }
        match self.dtype() {
            DType::F32 => Ok(Precision::F32),
            DType::F64 => Ok(Precision::F64),
            other => Err(format!("dtype {other:?}")),
        }
    }

    fn vertex_count(&self) -> usize {
        MeshVae::vertex_count(self)
    }

    fn trainable(&self) -> Vec<(String, usize)> {
        (self.trainable_vars().into_iter())
            .map(|(name, v)| (name, v.elem_count()))
            .collect()
    }

    fn var_ids(&self) -> Vec<u64> {
        (self.trainable_vars().iter())
            .map(|(_, v)| {
                let mut h = DefaultHasher::new();
                v.as_tensor().id().hash(&mut h);
                h.finish()
            })
            .collect()
    }

    fn with_weights(&self, f: &mut dyn FnMut(&[HostSlice<'_>]) -> Result<()>) -> Result<()> {
        let vars = self.trainable_vars();
        let guards: Vec<_> = (vars.iter())
            .map(|(_, v)| v.as_tensor().storage_and_layout())
            .collect();
        let slices: Vec<HostSlice<'_>> = (guards.iter().zip(&vars))
            .map(|((storage, layout), (name, _))| {
                let not = |why: &str| VaeError::shape("Engine", format!("weight {name} {why}"));
                let Storage::Cpu(cpu) = &**storage else {
                    return Err(not("is not on the CPU"));
                };
                let (lo, hi) =
                    (layout.contiguous_offsets()).ok_or_else(|| not("is not contiguous"))?;
                match cpu {
                    CpuStorage::F32(v) => Ok(HostSlice::F32(&v[lo..hi])),
                    CpuStorage::F64(v) => Ok(HostSlice::F64(&v[lo..hi])),
                    _ => Err(not("has another dtype")),
                }
            })
            .collect::<Result<_>>()?;
        f(&slices)
    }

    fn state(&self, id: usize) -> Result<Vec<f64>> {
        Ok(state_var(self, id)?
            .as_tensor()
            .to_dtype(DType::F64)?
            .to_vec1()?)
    }

    fn set_state(&self, id: usize, values: &[f64]) -> Result<()> {
        let var = state_var(self, id)?;
        let t = Tensor::from_vec(values.to_vec(), values.len(), var.device())?;
        var.set(&t.to_dtype(var.dtype())?)?;
        Ok(())
    }
}

/// State variable `id` of `model`.
fn state_var(model: &MeshVae, id: usize) -> Result<Var> {
    (model.state_vars().into_iter().nth(id))
        .map(|(_, v)| v)
        .ok_or_else(|| VaeError::shape("Engine", format!("no state variable {id}")))
}
