//! [`Network`]: which auto-encoder a model is. The paper's network (ours) is built from the
//! rest of [`crate::ModelConfig`]; the others are fixed as their authors define them, so that
//! `meshvae train --net …` trains each on the same set, split, validation protocol, stopping
//! rule and error measures as ours. What each takes and how it is defined is said here, once.

use crate::error::{Result, VaeError};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// The auto-encoder a model is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Network {
    /// The paper's network (Yuan et al. 2020): graph convolutions and edge-contraction pooling
    /// on ACAP features, as the rest of the configuration says.
    #[default]
    Ours,
    /// The fully connected mesh VAE of Tan et al. 2018 on the same ACAP features.
    Tan2018,
    /// CoMA (Ranjan et al. 2018): Chebyshev convolutions on vertex positions with its mesh
    /// sampling between four levels.
    Coma,
    /// SpiralNet++ (Gong et al. 2019): spiral convolutions on vertex positions with the same
    /// sampling.
    SpiralNet,
}

/// What a network reads and writes per vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// The 9 ACAP feature channels, normalised into ±0.95 (positions by the Poisson solve).
    Features,
    /// The 3 coordinates, standardised per vertex and coordinate over the training meshes.
    Positions,
}

impl Input {
    /// Channels per vertex.
    pub fn channels(self) -> usize {
        match self {
            Self::Features => crate::net::config::FEATURE_CHANNELS,
            Self::Positions => 3,
        }
    }
}

/// The reconstruction term of a network's loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecLoss {
    /// Batch mean of each mesh's sum of squared errors (ours and Tan et al., as their code).
    SumOfSquares,
    /// Mean absolute error over every value (CoMA's and SpiralNet++'s L1 loss).
    MeanAbsolute,
}

/// A layer's activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    Linear,
    Tanh,
    Relu,
    Elu,
}

/// The graph convolution of a position network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraphConvKind {
    /// Chebyshev polynomials of order 0 … K−1 of the level's rescaled Laplacian.
    Chebyshev { k: usize },
    /// A dense layer over the features gathered along each vertex's spiral.
    Spiral { length: usize },
}

/// A position network's layers: the encoder's convolutions (each followed by down-sampling to
/// the next level), the dense layer to the latent vector, and the decoder mirroring them (a
/// dense layer, then per level up-sampling and a convolution, then a last convolution to 3
/// channels without activation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionNet {
    pub conv: GraphConvKind,
    /// Output channels of the encoder's convolutions, one per level.
    pub channels: [usize; 4],
    pub activation: Activation,
    /// The activation of the dense layers into and out of the latent vector.
    pub dense_activation: Activation,
    /// Vertices kept per level: 1/4.
    pub factor: usize,
}

/// Tan et al.'s fully connected VAE: 9V → hidden (each with `activation`) → μ, σ; the decoder
/// latent → hidden reversed → 9V (tanh).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DenseNet {
    pub hidden: &'static [usize],
    pub activation: Activation,
}

/// CoMA as its released TensorFlow code defines it: K = 6 (orders 0 … 5), filters 16, 16, 16,
/// 32, down-sampling by 4 at each of four levels, a bias and ReLU after every convolution but
/// the last (which has neither), and ReLU after both dense layers, the latent code's included
/// (its dense layer's default).
pub const COMA: PositionNet = PositionNet {
    conv: GraphConvKind::Chebyshev { k: 6 },
    channels: [16, 16, 16, 32],
    activation: Activation::Relu,
    dense_activation: Activation::Relu,
    factor: 4,
};

/// SpiralNet++ as its reconstruction experiment defines it: spirals of 9, channels 32, 32, 32,
/// 64, ELU, the same sampling by 4 at four levels.
pub const SPIRALNET: PositionNet = PositionNet {
    conv: GraphConvKind::Spiral { length: 9 },
    channels: [32, 32, 32, 64],
    activation: Activation::Elu,
    dense_activation: Activation::Linear,
    factor: 4,
};

/// Tan et al. 2018's fully connected network (see [`Network::Tan2018`] for the sources).
pub const TAN2018: DenseNet = DenseNet {
    hidden: &[1024],
    activation: Activation::Tanh,
};

impl Network {
    pub const ALL: [Network; 4] = [Self::Ours, Self::Tan2018, Self::Coma, Self::SpiralNet];

    /// What the network reads and writes.
    pub fn input(self) -> Input {
        match self {
            Self::Ours | Self::Tan2018 => Input::Features,
            Self::Coma | Self::SpiralNet => Input::Positions,
        }
    }

    /// A VAE (μ, σ and a KL term), or a plain auto-encoder (z = μ, no KL term).
    pub fn is_variational(self) -> bool {
        matches!(self, Self::Ours | Self::Tan2018)
    }

    /// The reconstruction term of its loss.
    pub fn rec_loss(self) -> RecLoss {
        match self {
            Self::Ours | Self::Tan2018 => RecLoss::SumOfSquares,
            Self::Coma | Self::SpiralNet => RecLoss::MeanAbsolute,
        }
    }

    /// The position network's layers, for CoMA and SpiralNet++.
    pub fn position_net(self) -> Option<PositionNet> {
        match self {
            Self::Coma => Some(COMA),
            Self::SpiralNet => Some(SPIRALNET),
            _ => None,
        }
    }

    /// Its latent size as its authors define it.
    pub fn default_latent(self) -> usize {
        match self {
            Self::Ours | Self::Tan2018 => 128,
            Self::Coma => 8,
            Self::SpiralNet => 16,
        }
    }

    /// Its peak learning rate: ours is tuned for our schedule; the others take the rate their
    /// authors train with (Adam at 1e-3), which our warm-up, cosine decay and early stop then
    /// shape as for ours.
    pub fn default_lr(self) -> Option<f64> {
        match self {
            Self::Ours => None,
            _ => Some(1e-3),
        }
    }

    /// Pooling steps of its hierarchy (0: it needs only the template).
    pub fn pool_levels(self) -> Option<usize> {
        match self {
            Self::Ours => None,
            Self::Tan2018 => Some(0),
            Self::Coma | Self::SpiralNet => Some(4),
        }
    }

    /// The fewest template vertices it can run on: the position networks sample down by 4 four
    /// times, and a closed surface cannot be simplified below 4 vertices.
    pub fn min_vertices(self) -> usize {
        match self.position_net() {
            Some(net) => 4 * net.factor.pow(net.channels.len() as u32),
            None => 3,
        }
    }

    /// Where its definition comes from, for the model's summary and the results pages.
    pub fn defined_by(self) -> &'static str {
        match self {
            Self::Ours => {
                "Yuan et al. 2020 as the authors' code runs it (Chebyshev K = 3, 9 channels, \
                 edge-contraction pooling, latent 128)"
            }
            Self::Tan2018 => {
                "Tan et al. 2018 (mesh VAE): fully connected 9V → 1024 (tanh) → μ, σ (latent 128), \
                 decoder 128 → 1024 (tanh) → 9V (tanh), on the same ACAP features and loss as ours"
            }
            Self::Coma => {
                "Ranjan et al. 2018 (CoMA): Chebyshev K = 6 on positions, filters 16, 16, 16, 32, \
                 mesh sampling by 4 at four levels, ReLU, latent 8, L1 loss"
            }
            Self::SpiralNet => {
                "Gong et al. 2019 (SpiralNet++): spirals of 9 on positions, channels 32, 32, 32, \
                 64, the same sampling, ELU, latent 16, L1 loss"
            }
        }
    }
}

impl fmt::Display for Network {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Ours => "ours",
            Self::Tan2018 => "tan2018",
            Self::Coma => "coma",
            Self::SpiralNet => "spiralnet",
        })
    }
}

impl FromStr for Network {
    type Err = VaeError;

    fn from_str(s: &str) -> Result<Self> {
        let lower = s.to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|n| n.to_string() == lower)
            .ok_or_else(|| {
                VaeError::argument(
                    "net",
                    format!("{s:?} is not one of ours, tan2018, coma, spiralnet"),
                )
            })
    }
}

impl Network {
    /// Whether `self` is ours (serde's test for leaving the field out of `config.json`, so that
    /// the paper's models read and write as before).
    pub fn is_ours(&self) -> bool {
        *self == Self::Ours
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_each_network_says_what_it_reads() {
        for n in Network::ALL {
            assert_eq!(n.to_string().parse::<Network>().unwrap(), n);
            let json = serde_json::to_string(&n).unwrap();
            assert_eq!(json, format!("\"{n}\""));
        }
        assert!("CoMA".parse::<Network>().is_ok());
        let err = "pointnet".parse::<Network>().unwrap_err().to_string();
        assert!(err.contains("net") && err.contains("spiralnet"), "{err}");
        assert_eq!(Network::Coma.input().channels(), 3);
        assert_eq!(Network::Tan2018.input().channels(), 9);
        assert!(!Network::SpiralNet.is_variational() && Network::Tan2018.is_variational());
    }
}
