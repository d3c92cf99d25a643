//! Executors: what computes a model's training steps and its inference passes. Two implement
//! [`Executor`]: the hand-written CPU engine ([`EngineExecutor`] over `cpu::Engine`, whose own
//! API knows no tensor library) and candle's autograd ([`CandleExecutor`], the reference).
//! Training and the applications ask [`ExecutorChoice::choose`] once which one runs a model; the
//! choice, and why candle where it is, is written on every line of `log.jsonl`, in `run.json`
//! and in the summary, so that a run never changes path without a word.
//!
//! The device is chosen here too ([`default_device`]): the one place a command's models are
//! placed.

mod candle;
mod engine;

pub use self::candle::CandleExecutor;
pub use engine::EngineExecutor;

use crate::candle::model::MeshVae;
use crate::error::Result;
use crate::net::loss_weights::LossWeights;
use crate::optim::adam::Adam;
use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};
use std::fmt;

/// The device every command trains and runs its models on: the one place that chooses it. The
/// CPU, where the engine runs; on another device the steps would fall to candle's autograd
/// ([`ExecutorChoice::choose`] says so in every run's log).
pub fn default_device() -> Device {
    Device::Cpu
}

/// A batch of rows (features x `[B, V, C]`, or latent vectors `[B, latent]` to decode) and,
/// exactly for a conditional model, their one-hot labels c `[B, L]`.
#[derive(Debug, Clone, Copy)]
pub struct Batch<'a> {
    pub x: &'a Tensor,
    pub c: Option<&'a Tensor>,
}

/// What one training step takes: a batch, its reparameterisation noise ε `[B, latent]`, the
/// optimiser (built on the model's trainable variables) and the loss weights.
#[derive(Debug)]
pub struct TrainStep<'a> {
    pub batch: Batch<'a>,
    pub eps: &'a Tensor,
    pub adam: &'a mut Adam,
    pub loss: &'a LossWeights,
}

/// What one training step did: its loss terms (weighted as in [`crate::Loss`]), whether they
/// were finite, and where its time went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// rec + kl + l2.
    pub total: f64,
    pub rec: f64,
    pub kl: f64,
    /// The L2 term of the weights the step started from.
    pub l2: f64,
    /// `false`: a term is not finite (the run has diverged). Adam's update is skipped where the
    /// forward pass shows it already.
    pub finite: bool,
    /// Seconds in the forward and backward passes.
    pub forward_backward_seconds: f64,
    /// Seconds in Adam's update.
    pub update_seconds: f64,
}

impl StepReport {
    /// The terms as `[total, rec, kl, l2]`.
    pub fn terms(&self) -> [f64; 4] {
        [self.total, self.rec, self.kl, self.l2]
    }
}

/// What computes a model's passes. Every method takes the model whose variables it reads and
/// (in [`Self::step`]) trains; an executor that keeps buffers (the engine) refuses another
/// model than its own.
pub trait Executor: Send {
    /// Which implementation this is.
    fn kind(&self) -> ExecutorKind;

    /// One training step: forward and backward passes in train mode (the batch norms' running
    /// statistics move), then Adam's update of the model's trainable variables with the L2
    /// term's gradient `loss.l2 · θ`.
    fn step(&mut self, model: &MeshVae, step: TrainStep<'_>) -> Result<StepReport>;

    /// w_rec · batch mean of the reconstruction error of the input in inference mode (z = μ,
    /// the batch norms' running statistics); changes nothing.
    fn rec_error(&mut self, model: &MeshVae, batch: Batch<'_>, loss: &LossWeights) -> Result<f64>;

    /// μ and σ `[B, latent]` of the input in inference mode.
    fn encode(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<(Tensor, Tensor)>;

    /// x̂ from latent vectors `[B, latent]` (and labels) in inference mode.
    fn decode(&mut self, model: &MeshVae, z: Batch<'_>) -> Result<Tensor>;

    /// decode(μ(x, c), c) in inference mode.
    fn reconstruct(&mut self, model: &MeshVae, batch: Batch<'_>) -> Result<Tensor>;
}

/// The implementation that computes the steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExecutorKind {
    /// The hand-written forward, backward and Adam step over reused buffers (CPU).
    Engine,
    /// candle's autograd: the reference, and the path for models and devices the engine does
    /// not cover.
    Candle,
}

impl fmt::Display for ExecutorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Engine => "engine",
            Self::Candle => "candle",
        })
    }
}

/// Which executor runs a model and, for candle, why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExecutorChoice {
    pub kind: ExecutorKind,
    /// Why candle and not the engine (`None` for the engine).
    pub reason: Option<String>,
}

impl ExecutorChoice {
    /// The engine where it supports `model` and is allowed, candle otherwise.
    pub fn choose(model: &MeshVae, engine_allowed: bool) -> Self {
        let reason = if engine_allowed {
            EngineExecutor::unsupported(model).map(|why| format!("the engine does not cover {why}"))
        } else {
            Some("the engine was switched off (--no-engine)".into())
        };
        Self {
            kind: match reason {
                None => ExecutorKind::Engine,
                Some(_) => ExecutorKind::Candle,
            },
            reason,
        }
    }

    /// The chosen executor for `model`, with buffers for batches of up to `max_batch`.
    pub fn build(&self, model: &MeshVae, max_batch: usize) -> Result<Box<dyn Executor>> {
        Ok(match self.kind {
            ExecutorKind::Engine => Box::new(EngineExecutor::new(model, max_batch)?),
            ExecutorKind::Candle => Box::new(CandleExecutor),
        })
    }
}

impl fmt::Display for ExecutorChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.reason {
            Some(why) => write!(f, "{} ({why})", self.kind),
            None => write!(f, "{}", self.kind),
        }
    }
}
