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
//! (`tests.rs` compares the two).
//!
//! This folder holds the engine (here), its network of layers over reused buffers (`net.rs`;
//! `net/`: built from the model's network plan (`net::plan::NetPlan`: the layer list and
//! variable ids candle's model is built from too), per-layer forward and backward, convolution weights,
//! the latent heads, inference), its element-wise kernels (`kernels.rs`), the matrix products (`gemm.rs`) and
//! [`wide`](wide::wide) (AVX2 + FMA loops, also used by Adam's update). It imports `train/` only
//! for the [`Adam`] it steps and the [`LossWeights`] it reads.

mod gemm;
mod kernels;
mod net;
#[cfg(test)]
mod tests;

use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::net::loss_weights::LossWeights;
use crate::optim::adam::Adam;
use candle_core::{DType, Tensor};
use net::{Inputs, Net};

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
pub struct Engine {
    net: Typed,
}

impl Engine {
    /// Why the engine cannot train `model`, or `None` if it can.
    pub fn unsupported(model: &MeshVae) -> Option<String> {
        let c = model.config();
        if !c.net.is_ours() {
            return Some(format!("the network {} (it runs ours only)", c.net));
        }
        if !model.device().is_cpu() {
            return Some("the model is not on the CPU".into());
        }
        if !matches!(model.dtype(), DType::F32 | DType::F64) {
            return Some(format!("dtype {:?}", model.dtype()));
        }
        if c.k > 8 {
            return Some(format!("K = {} (at most 8)", c.k));
        }
        None
    }

    /// An engine for `model` with buffers for batches of up to `max_batch` meshes; an error
    /// saying why when [`Self::unsupported`] declines the model (training asks first and says
    /// which path it takes, `crate::Executor`).
    pub fn new(model: &MeshVae, max_batch: usize) -> Result<Self> {
        if let Some(why) = Self::unsupported(model) {
            return Err(VaeError::argument(
                "model",
                format!("the CPU engine does not cover {why}"),
            ));
        }
        if max_batch == 0 {
            return Err(VaeError::argument("max_batch", "must be at least 1"));
        }
        let net = match model.dtype() {
            DType::F32 => Typed::F32(Net::build(model, max_batch)?),
            _ => Typed::F64(Net::build(model, max_batch)?),
        };
        Ok(Self { net })
    }

    /// Forward and backward pass on features x `[B, V, 9]` (labels c `[B, L]`, one-hot rows as
    /// [`MeshVae::one_hot`] makes them, exactly for a conditional model) and noise ε
    /// `[B, latent]` (the model's dtype, CPU) in train mode: updates the batch norms' running
    /// statistics as the candle path does and leaves every trainable variable's gradient (of
    /// w_rec·rec + w_kl·KL, without the L2 term) in the engine.
    pub fn forward_backward(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
        eps: &Tensor,
        weights: &LossWeights,
    ) -> Result<StepLoss> {
        on_net!(&mut self.net, n => n.step(model, Inputs { x, c }, (eps, weights)))
    }

    /// w_rec · batch mean of Σ (x − x̂)² for features x `[B, V, 9]` (labels c exactly for a
    /// conditional model) in inference mode (z = μ, the batch norms' running statistics):
    /// [`MeshVae::rec_error`] without candle's per-op allocations. Does not disturb the last
    /// [`Self::forward_backward`]'s gradients.
    pub fn rec_error(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
        weights: &LossWeights,
    ) -> Result<f64> {
        on_net!(&mut self.net, n => n.rec_error(model, Inputs { x, c }, weights))
    }

    /// μ and σ `[B, latent]` of features x `[B, V, 9]` in inference mode (the batch norms'
    /// running statistics; labels c `[B, L]` exactly when the model is conditional), as
    /// [`MeshVae::encode`] in eval mode computes them.
    pub fn encode(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
    ) -> Result<(Tensor, Tensor)> {
        on_net!(&mut self.net, n => n.encode(model, Inputs { x, c }))
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]` in inference mode, as
    /// [`MeshVae::decode`] in eval mode.
    pub fn decode(&mut self, model: &MeshVae, z: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        on_net!(&mut self.net, n => n.decode(model, z, c))
    }

    /// decode(μ(x, c), c) in inference mode, as [`MeshVae::reconstruct`].
    pub fn reconstruct(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
    ) -> Result<Tensor> {
        on_net!(&mut self.net, n => n.reconstruct(model, Inputs { x, c }))
    }

    /// The largest batch the engine's buffers hold.
    pub fn max_batch(&self) -> usize {
        on_net!(&self.net, n => n.max_batch())
    }

    /// Adam's update from the gradients of the last [`Self::forward_backward`] plus the L2
    /// term's gradient `l2 · θ` (as `Adam::step_with_l2`); returns the L2 term's value
    /// l2 · Σ ½‖θ‖² of the weights before the update. `adam` must be built on
    /// `model.trainable_vars()`.
    pub fn apply_adam(&self, adam: &mut Adam, l2: f64) -> Result<f64> {
        let half_sq = on_net!(&self.net, n => n.apply_adam(adam, l2)?);
        Ok(half_sq * l2)
    }

    /// The norm of the last step's gradient (the L2 term's left out), as gradient clipping
    /// reads it; the dense weights' part comes from Gram matrices, without forming them.
    pub fn grad_norm(&self) -> f64 {
        on_net!(&self.net, n => n.grad_norm())
    }

    /// Copies of the last step's gradients, by variable name (for checks and tests).
    pub fn gradients(&self) -> Result<Vec<(String, Tensor)>> {
        on_net!(&self.net, n => n.gradients())
    }
}
