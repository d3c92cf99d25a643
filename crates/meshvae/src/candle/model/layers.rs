//! The building blocks of [`super::MeshVae`]: graph convolutions (own weights or the adjoint of
//! an encoder convolution), convolution blocks (conv → batch norm → tanh), the pooling and
//! de-pooling between levels, and [`Stage`]: one of those per step of the plan.

use crate::candle::batch_norm::BatchNorm;
use crate::candle::batch_norm::Mode;
use crate::error::{Result, VaeError};
use crate::net::config::ConvSpec;
use candle_core::Tensor;
use spectral_conv::{ChebConv, DePool, MaxPool, MeanPool, Sampling, SparseOp, SpatialConv};

/// A graph convolution with weights (no bias: batch norm's β is the layers' only offset).
#[derive(Debug, Clone)]
pub(crate) enum GraphConv {
    Cheb(ChebConv),
    Spatial(SpatialConv),
}

impl GraphConv {
    /// x `[B, V, C]` (the tests' reference; the network runs vertex-major).
    #[cfg(test)]
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::Cheb(c) => c.forward(x)?,
            Self::Spatial(c) => c.forward(x)?,
        })
    }

    /// x `[V, B, C]`, the layout the network keeps its activations in (no layer transposes).
    pub fn forward_vertex_major(&self, x: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::Cheb(c) => c.forward_vertex_major(x)?,
            Self::Spatial(c) => c.forward_vertex_major(x)?,
        })
    }

    /// The adjoint convolution (⟨conv x, y⟩ = ⟨x, adjoint y⟩) on `op_t` = Aᵀ, built from the
    /// current weights (differentiably, so gradients reach them):
    /// - Chebyshev: Σ_k T_k(L̃) X W_k ↦ Σ_k T_k(L̃ᵀ) Y W_kᵀ, i.e. the per-order blocks of W
    ///   transposed: row fin·K + k, column o → row o·K + k, column fin;
    /// - spatial: X W_s + M X W_n ↦ Y W_sᵀ + Mᵀ Y W_nᵀ.
    pub fn adjoint(&self, op_t: &SparseOp) -> Result<Self> {
        Ok(match self {
            Self::Cheb(c) => {
                let (k, c_in, c_out) = (c.k(), c.c_in(), c.c_out());
                let w = c
                    .weight()
                    .reshape((c_in, k, c_out))?
                    .permute((2, 1, 0))?
                    .contiguous()?
                    .reshape((c_out * k, c_in))?;
                Self::Cheb(ChebConv::from_weights(op_t.clone(), k, w, None)?)
            }
            Self::Spatial(c) => Self::Spatial(SpatialConv::from_weights(
                op_t.clone(),
                c.w_self().t()?.contiguous()?,
                c.w_nb().t()?.contiguous()?,
                None,
            )?),
        })
    }
}

/// Where a convolution block's weights come from.
#[derive(Debug, Clone)]
pub(crate) enum Weights {
    Own(GraphConv),
    /// The adjoint of encoder convolution `spec.index` (tied decoder convolutions), on the
    /// level's transposed operator Aᵀ.
    Tied(SparseOp),
}

/// conv → optional batch norm → optional tanh.
#[derive(Debug, Clone)]
pub(crate) struct ConvBlock {
    pub spec: ConvSpec,
    pub weights: Weights,
    pub bn: Option<BatchNorm>,
}

impl ConvBlock {
    /// Runs the block on x `[V, B, C]` (batch norm and tanh act per channel, so they do not
    /// care about the order of the other two dimensions); `tied` supplies the convolution of a
    /// [`Weights::Tied`] block.
    pub fn forward(&self, x: &Tensor, mode: Mode, tied: Option<&GraphConv>) -> Result<Tensor> {
        let y = self.conv(tied)?.forward_vertex_major(x)?;
        Ok(match (&self.bn, self.spec.tanh) {
            (Some(bn), true) => bn.forward_tanh(&y, mode)?,
            (Some(bn), false) => bn.forward(&y, mode)?,
            (None, true) => y.tanh()?,
            (None, false) => y,
        })
    }

    /// The convolution alone (no batch norm, no activation) on x `[B, V, C]`.
    #[cfg(test)]
    pub fn linear(&self, x: &Tensor, tied: Option<&GraphConv>) -> Result<Tensor> {
        self.conv(tied)?.forward(x)
    }

    fn conv<'a>(&'a self, tied: Option<&'a GraphConv>) -> Result<&'a GraphConv> {
        match (&self.weights, tied) {
            (Weights::Own(conv), _) => Ok(conv),
            (Weights::Tied(_), Some(conv)) => Ok(conv),
            (Weights::Tied(_), None) => Err(VaeError::shape(
                "ConvBlock::forward",
                format!(
                    "tied convolution {} without its encoder weights",
                    self.spec.index
                ),
            )),
        }
    }
}

/// One step of the encoder or decoder, as the plan lists them.
#[derive(Debug, Clone)]
pub(crate) enum Stage {
    Conv(ConvBlock),
    Down(Down),
    Up(Up),
}

/// Pooling from level i to level i + 1.
#[derive(Debug, Clone)]
pub(crate) enum Down {
    /// Mean pooling (ours, qem, remesh).
    Mean(MeanPool),
    /// Max pooling: signed magnitude over clusters (max) or the plain max over overlapping
    /// neighbourhoods (graph), as the layer's mode says.
    Max(MaxPool),
    Sampling(Sampling),
    Identity,
}

impl Down {
    /// x `[V_i, B, C]` → `[V_{i+1}, B, C]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::Mean(p) => p.forward_vertex_major(x)?,
            Self::Max(p) => p.forward_vertex_major(x)?,
            Self::Sampling(p) => p.forward_vertex_major(x)?,
            Self::Identity => x.clone(),
        })
    }
}

/// De-pooling from level i + 1 back to level i.
#[derive(Debug, Clone)]
pub(crate) enum Up {
    DePool(DePool),
    Sampling(Sampling),
    Identity,
}

impl Up {
    /// x `[V_{i+1}, B, C]` → `[V_i, B, C]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::DePool(p) => p.forward_vertex_major(x)?,
            Self::Sampling(p) => p.forward_vertex_major(x)?,
            Self::Identity => x.clone(),
        })
    }
}
