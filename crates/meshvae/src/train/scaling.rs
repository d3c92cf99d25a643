//! [`InputScaling`]: how a network's per-vertex inputs are scaled, fitted on the training
//! meshes and saved with the model (`normalization.json`). ACAP features go into ±0.95 by
//! `deform_features::Normalization` (ours, Tan et al.); positions are standardised per vertex
//! and coordinate, (x − mean) / std over the training meshes, as CoMA's and SpiralNet++'s data
//! loaders do.

use crate::error::{Result, VaeError};
use deform_features::Normalization;
use mesh_io::MeshSet;
use serde::{Deserialize, Serialize};

/// The scaling of a model's inputs (untagged in JSON: a features model's file reads as before).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum InputScaling {
    Features(Normalization),
    Positions(PositionScaling),
}

/// Per vertex and coordinate, the training meshes' mean and standard deviation (`[V·3]`, index
/// v·3 + axis).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PositionScaling {
    pub position_mean: Vec<f32>,
    pub position_std: Vec<f32>,
}

impl PositionScaling {
    /// Fitted on the meshes `train` of `set`. A coordinate that never moves (std 0, where
    /// CoMA's loader would divide by zero) gets a floor of 1e-3 of the mean std, so it maps to
    /// about 0 and back exactly.
    pub fn fit(set: &MeshSet, train: &[usize]) -> Result<Self> {
        if train.is_empty() {
            return Err(VaeError::argument(
                "split",
                "no training mesh to fit the scaling on",
            ));
        }
        let n = set.vertex_count() * 3;
        let mut sum = vec![0f64; n];
        let mut sq = vec![0f64; n];
        for &i in train {
            for (k, x) in set.frame(i).iter().flatten().enumerate() {
                let x = f64::from(*x);
                sum[k] += x;
                sq[k] += x * x;
            }
        }
        let m = train.len() as f64;
        let mean: Vec<f64> = sum.iter().map(|s| s / m).collect();
        let std: Vec<f64> = (sq.iter().zip(&mean))
            .map(|(q, mu)| (q / m - mu * mu).max(0.0).sqrt())
            .collect();
        let floor = 1e-3 * std.iter().sum::<f64>() / n.max(1) as f64;
        Ok(Self {
            position_mean: mean.iter().map(|&x| x as f32).collect(),
            position_std: std
                .iter()
                .map(|&s| s.max(floor).max(1e-12) as f32)
                .collect(),
        })
    }

    /// Standardised positions (`[V·3]`).
    pub fn apply(&self, positions: &[[f32; 3]]) -> Vec<f32> {
        (positions.iter().flatten().zip(&self.position_mean))
            .zip(&self.position_std)
            .map(|((x, m), s)| (x - m) / s)
            .collect()
    }

    /// Positions from standardised values `[V·3]`.
    pub fn invert(&self, values: &[f32]) -> Vec<[f64; 3]> {
        let x: Vec<f64> = (values.iter().zip(&self.position_mean))
            .zip(&self.position_std)
            .map(|((y, m), s)| f64::from(*y) * f64::from(*s) + f64::from(*m))
            .collect();
        x.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect()
    }

    /// Checks the lengths and values against a mesh of `vertices` vertices.
    pub fn validate(&self, vertices: usize) -> Result<()> {
        let n = vertices * 3;
        if self.position_mean.len() != n || self.position_std.len() != n {
            return Err(VaeError::argument(
                "normalization",
                format!(
                    "{} means and {} deviations for {vertices} vertices (expected {n} each)",
                    self.position_mean.len(),
                    self.position_std.len()
                ),
            ));
        }
        let bad = self.position_mean.iter().any(|x| !x.is_finite())
            || self
                .position_std
                .iter()
                .any(|s| !(s.is_finite() && *s > 0.0));
        if bad {
            return Err(VaeError::argument(
                "normalization",
                "a mean is not finite or a deviation not positive",
            ));
        }
        Ok(())
    }
}

impl InputScaling {
    /// Checks it against a model of `vertices` vertices whose network reads `positions` or not.
    pub fn validate(&self, vertices: usize, positions: bool) -> Result<()> {
        match (self, positions) {
            (Self::Features(n), false) => Ok(n.validate()?),
            (Self::Positions(p), true) => p.validate(vertices),
            _ => Err(VaeError::argument(
                "normalization",
                "holds the scaling of the other kind of input than the network reads",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh_io::synth::{SynthConfig, generate};

    #[test]
    fn positions_round_trip_and_training_meshes_are_standardised() {
        let set = generate(&SynthConfig {
            meshes_per_label: 4,
            ..SynthConfig::default()
        })
        .unwrap()
        .set;
        let train = [0, 2, 3, 5];
        let s = PositionScaling::fit(&set, &train).unwrap();
        s.validate(set.vertex_count()).unwrap();
        assert!(s.validate(set.vertex_count() + 1).is_err());
        let scaled: Vec<Vec<f32>> = train.iter().map(|&i| s.apply(set.frame(i))).collect();
        // Over the training meshes each moving coordinate has mean 0 and variance 1.
        let moving = (0..s.position_std.len())
            .find(|&k| s.position_std[k] > 1e-3)
            .unwrap();
        let mean: f64 = scaled.iter().map(|v| f64::from(v[moving])).sum::<f64>() / 4.0;
        let var: f64 = scaled
            .iter()
            .map(|v| (f64::from(v[moving]) - mean).powi(2))
            .sum::<f64>()
            / 4.0;
        assert!(
            mean.abs() < 1e-5 && (var - 1.0).abs() < 1e-4,
            "{mean} {var}"
        );
        let back = s.invert(&s.apply(set.frame(1)));
        for (b, p) in back.iter().zip(set.frame(1)) {
            for k in 0..3 {
                assert!((b[k] - f64::from(p[k])).abs() < 1e-5);
            }
        }
        let json = serde_json::to_string(&InputScaling::Positions(s.clone())).unwrap();
        assert_eq!(
            serde_json::from_str::<InputScaling>(&json).unwrap(),
            InputScaling::Positions(s)
        );
        assert!(PositionScaling::fit(&set, &[]).is_err());
    }
}
