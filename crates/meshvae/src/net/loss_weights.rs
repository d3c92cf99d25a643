//! [`LossWeights`]: the weights of the loss's three terms (reconstruction, KL, L2), part of a
//! network's definition that every executor reads. The loss itself, and why the defaults are
//! the authors' 40 / 3 / 1, is in `train/loss.rs`.

use serde::{Deserialize, Serialize};

/// Weights of the three loss terms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// Reconstruction (batch mean of the per-shape sum of squared errors).
    pub rec: f64,
    /// KL divergence to N(0, I).
    pub kl: f64,
    /// ½‖w‖² over every trainable variable.
    pub l2: f64,
}

impl Default for LossWeights {
    /// The authors' 40 / 3 / 1.
    fn default() -> Self {
        Self {
            rec: 40.0,
            kl: 3.0,
            l2: 1.0,
        }
    }
}
