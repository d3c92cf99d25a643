//! [`Engine`]: the training step (forward, backward, Adam) written by hand for the CPU over
//! buffers allocated once, instead of candle's autograd.
//!
//! Why: with candle every op returns a fresh tensor (fresh pages, zeroed by the kernel on first
//! touch), gradients accumulate as `zeros + g`, and element-wise ops run as separate passes;
//! on horse-gallop that overhead, not the graph convolutions, dominated a step. The engine owns
//! every activation, gradient and scratch buffer (sized for the largest batch), keeps them
//! `[V, C, B]` (the graph kernels' own layout: no transposes between layers), fuses batch norm
//! with tanh and the loss with its gradient, and hands its gradient slices to a fused Adam pass.
//! The two dense weights' gradients (each as large as its weights: 19 MB on horse-gallop, 97 MB
//! on elephant-gallop) are never stored whole: Adam's pass makes them block by block from the
//! activations the backward pass keeps, and updates each block while it is in cache.
//! Training also evaluates the validation and test losses on the same buffers
//! ([`Engine::rec_error`]: z = μ, the batch norms' running statistics).
//!
//! It covers the model with Chebyshev convolutions (any K ≤ 8) or spatial ones (the Chebyshev
//! kernel with K = 2 on D⁻¹A), own or tied decoder weights (a tied convolution runs the encoder's adjoint on the
//! transposed operator), every pooling (graph pooling is a max pool
//! over overlapping member lists, remeshing is mean pooling) and the conditional VAE's labels
//! ([`Engine::forward_backward`]), in f32 or f64 on the CPU; [`Engine::unsupported`] says why
//! anything else is declined, and training then uses candle's path, which stays the reference
//! (`executor/engine/tests.rs` compares the two).
//!
//! The engine knows no tensor library: it reads a model through [`EngineModel`] (its plan,
//! configuration and variables, lent in place as host slices) and takes and returns host arrays
//! (`numerics/host.rs`). `executor/engine.rs` puts candle's model and tensors in that form.
//!
//! This folder holds the engine (here), what it needs of a model (`model.rs`), its network of
//! layers over reused buffers (`net.rs`; `net/`: built from the model's network plan
//! (`net::plan::NetPlan`: the layer list and variable ids candle's model is built from too),
//! per-layer forward and backward, convolution weights, the latent heads, inference), its
//! element-wise kernels (`kernels.rs`) and the matrix products (`gemm.rs`). Below it: the
//! shared formulas (`net/`), [`Adam`] (`optim/`), which it steps, and the float types and wide
//! loops (`numerics/`).

mod gemm;
mod kernels;
pub(crate) mod model;
mod net;

use crate::error::{Result, VaeError};
use crate::net::loss_weights::LossWeights;
use crate::numerics::host::{HostArray, HostTensor, Precision};
use crate::optim::adam::Adam;
use model::EngineModel;
pub(crate) use net::Inputs;
use net::Net;

pub(crate) use crate::numerics::real::Real;

/// The value in f64.
#[inline(always)]
pub(crate) fn f64_of<T: Real>(x: T) -> f64 {
    Real::as_f64(x)
}

/// An f64 in the float type.
#[inline(always)]
pub(crate) fn of<T: Real>(x: f64) -> T {
    <T as crate::numerics::real::Real>::of(x)
}

/// The loss terms of one engine step, weighted as in [`crate::Loss`] (the L2 term comes from
/// [`Engine::apply_adam`], which reads the weights anyway).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLoss {
    /// w_rec · batch mean of Σ (x − x̂)².
    pub rec: f64,
    /// w_kl · batch mean of the KL divergence.
    pub kl: f64,
}

/// μ and σ `[B, latent]`.
pub(crate) type Latents = (HostTensor, HostTensor);

#[derive(Debug)]
enum Typed {
    F32(Net<f32>),
    F64(Net<f64>),
}

/// `$body` with `$net` bound to the engine's network, whichever its float type.
macro_rules! on_net {
    ($net:expr, $n:ident => $body:expr) => {
        match $net {
            Typed::F32($n) => $body,
            Typed::F64($n) => $body,
        }
    };
}

/// The hand-written training step of one model (see the module documentation).
#[derive(Debug)]
pub(crate) struct Engine {
    net: Typed,
}

impl Engine {
    /// Why the engine cannot train `model`, or `None` if it can.
    pub fn unsupported(model: &dyn EngineModel) -> Option<String> {
        let c = model.config();
        if !c.net.is_ours() {
            return Some(format!("the network {} (it runs ours only)", c.net));
        }
        if let Err(why) = model.precision() {
            return Some(why);
        }
        if c.k > 8 {
            return Some(format!("K = {} (at most 8)", c.k));
        }
        None
    }

    /// An engine for `model` with buffers for batches of up to `max_batch` meshes; an error
    /// saying why when [`Self::unsupported`] declines the model (training asks first and says
    /// which path it takes, `crate::ExecutorChoice`).
    pub fn new(model: &dyn EngineModel, max_batch: usize) -> Result<Self> {
        if let Some(why) = Self::unsupported(model) {
            return Err(VaeError::argument(
                "model",
                format!("the CPU engine does not cover {why}"),
            ));
        }
        if max_batch == 0 {
            return Err(VaeError::argument("max_batch", "must be at least 1"));
        }
        let net = match model.precision() {
            Ok(Precision::F32) => Typed::F32(Net::build(model, max_batch)?),
            _ => Typed::F64(Net::build(model, max_batch)?),
        };
        Ok(Self { net })
    }

    /// Forward and backward pass on features x `[B, V, 9]` (labels c `[B, L]`, one-hot rows,
    /// exactly for a conditional model) and noise ε `[B, latent]` (the model's float type) in
    /// train mode: updates the batch norms' running statistics as candle's batch norm does and
    /// leaves every trainable variable's gradient (of w_rec·rec + w_kl·KL, without the L2
    /// term) in the engine.
    pub fn forward_backward(
        &mut self,
        model: &dyn EngineModel,
        inputs: Inputs<'_>,
        eps: HostArray<'_>,
        weights: &LossWeights,
    ) -> Result<StepLoss> {
        on_net!(&mut self.net, n => n.step(model, inputs, (eps, weights)))
    }

    /// w_rec · batch mean of Σ (x − x̂)² for features x `[B, V, 9]` (labels c exactly for a
    /// conditional model) in inference mode (z = μ, the batch norms' running statistics). Does
    /// not disturb the last [`Self::forward_backward`]'s gradients.
    pub fn rec_error(
        &mut self,
        model: &dyn EngineModel,
        inputs: Inputs<'_>,
        weights: &LossWeights,
    ) -> Result<f64> {
        on_net!(&mut self.net, n => n.rec_error(model, inputs, weights))
    }

    /// μ and σ `[B, latent]` of features x `[B, V, 9]` in inference mode (the batch norms'
    /// running statistics; labels c `[B, L]` exactly when the model is conditional).
    pub fn encode(&mut self, model: &dyn EngineModel, inputs: Inputs<'_>) -> Result<Latents> {
        on_net!(&mut self.net, n => n.encode(model, inputs))
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]` in inference mode.
    pub fn decode(
        &mut self,
        model: &dyn EngineModel,
        z: HostArray<'_>,
        c: Option<HostArray<'_>>,
    ) -> Result<HostTensor> {
        on_net!(&mut self.net, n => n.decode(model, z, c))
    }

    /// decode(μ(x, c), c) in inference mode.
    pub fn reconstruct(&mut self, model: &dyn EngineModel, x: Inputs<'_>) -> Result<HostTensor> {
        on_net!(&mut self.net, n => n.reconstruct(model, x))
    }

    /// Whether the full-resolution vertices run renumbered (for the tests).
    #[cfg(test)]
    pub fn renumbered(&self) -> bool {
        on_net!(&self.net, n => n.renumbered())
    }

    /// The largest batch the engine's buffers hold.
    pub fn max_batch(&self) -> usize {
        on_net!(&self.net, n => n.max_batch())
    }

    /// Adam's update from the gradients of the last [`Self::forward_backward`] plus the L2
    /// term's gradient `l2 · θ` (as `Adam::step_with_l2`); returns the L2 term's value
    /// l2 · Σ ½‖θ‖² of the weights before the update. `adam` must be built on the model's
    /// trainable variables.
    pub fn apply_adam(&self, adam: &mut Adam, l2: f64) -> Result<f64> {
        let half_sq = on_net!(&self.net, n => n.apply_adam(adam, l2)?);
        Ok(half_sq * l2)
    }

    /// The norm of the last step's gradient (the L2 term's left out), as gradient clipping
    /// reads it; the dense weights' part comes from Gram matrices, without forming them.
    pub fn grad_norm(&self) -> f64 {
        on_net!(&self.net, n => n.grad_norm())
    }

    /// The last step's gradients in f64, by variable name (for checks and tests).
    pub fn gradients(&self) -> Vec<(String, Vec<f64>)> {
        on_net!(&self.net, n => n.gradients())
    }
}
