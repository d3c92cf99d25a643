//! Parameter counts: ours by the paper's formula (checked against `meshvae::param_count`), and
//! the fully connected Mesh VAE of Tan et al. 2018 derived from its architecture.

use meshvae::{FEATURE_CHANNELS, ModelConfig, param_count};

/// The paper's count of our network, biases left out: the μ and σ heads (each 9·V₂ × 128; the
/// decoder's dense layer is tied to the μ head) plus six Chebyshev matrices of (3·9) × 9.
pub fn ours_formula(coarse: usize) -> usize {
    2 * coarse * 9 * 128 + 6 * (3 * 9) * 9
}

/// `meshvae`'s own count of the default network (`CCPC`) whose coarse level has `coarse`
/// vertices, under `vertices` on the template.
pub fn ours_meshvae(vertices: usize, coarse: usize) -> meshvae::ParamCount {
    param_count(&ModelConfig::default(), &[vertices, coarse])
}

/// Our reading of Tan et al.'s fully connected Mesh VAE. The paper compared against gives only
/// its totals, so every width here is a stated assumption (see [`tan2018`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TanArchitecture {
    /// Values per vertex of the input feature (the 9 of the rotation + stretch representation,
    /// which Yuan et al. say they normalise "following" Tan et al.).
    pub per_vertex: usize,
    /// Width of the one hidden fully connected layer of the encoder, mirrored in the decoder.
    pub hidden: usize,
    /// Latent size (128, as ours).
    pub latent: usize,
}

/// The architecture [`tan2018`] counts.
pub const TAN_ARCHITECTURE: TanArchitecture = TanArchitecture {
    per_vertex: FEATURE_CHANNELS,
    hidden: 1024,
    latent: 128,
};

impl TanArchitecture {
    /// Weights (no biases) on a mesh of `vertices` vertices: encoder 9V → h, μ and σ heads
    /// h → latent, decoder latent → h → 9V with its own weights.
    pub fn weights(&self, vertices: usize) -> usize {
        let input = self.per_vertex * vertices;
        2 * input * self.hidden + 3 * self.hidden * self.latent
    }

    /// The hidden width that would make [`Self::weights`] equal `count` exactly (generally not
    /// an integer): shows how far the paper's figures are from any one width.
    pub fn width_for(&self, vertices: usize, count: usize) -> f64 {
        let per_width = 2 * self.per_vertex * vertices + 3 * self.latent;
        count as f64 / per_width as f64
    }
}

/// Tan et al.'s weight count for `vertices` under [`TAN_ARCHITECTURE`].
pub fn tan2018(vertices: usize) -> usize {
    TAN_ARCHITECTURE.weights(vertices)
}

/// (derived − paper) / paper in percent.
pub fn distance_percent(derived: usize, paper: usize) -> f64 {
    (derived as f64 - paper as f64) / paper as f64 * 100.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::paper::PARAMS;

    #[test]
    fn our_formula_and_meshvae_give_the_papers_rows_exactly() {
        assert_eq!(ours_formula(3446), 7_941_042);
        assert_eq!(ours_formula(1787), 4_118_706);
        for row in PARAMS {
            assert_eq!(ours_formula(row.coarse), row.ours, "{}", row.dataset);
            let counted = ours_meshvae(row.vertices, row.coarse);
            assert_eq!(counted.without_biases, row.ours, "{}", row.dataset);
            assert!(counted.with_biases > counted.without_biases);
        }
    }

    #[test]
    fn tan_count_by_hand_and_its_distance() {
        // 2 · 62,010 · 1024 + 3 · 1024 · 128.
        assert_eq!(tan2018(6890), 126_996_480 + 393_216);
        assert_eq!(tan2018(3573), 65_857_536 + 393_216);
        let d = distance_percent(tan2018(6890), 129_745_920);
        assert!((d + 1.816).abs() < 0.01, "{d}");
        let d = distance_percent(tan2018(3573), 68_610_048);
        assert!((d + 3.439).abs() < 0.01, "{d}");
        // No single width fits both rows.
        let a = TAN_ARCHITECTURE.width_for(6890, 129_745_920);
        let b = TAN_ARCHITECTURE.width_for(3573, 68_610_048);
        assert!(
            (a - 1042.9).abs() < 0.1 && (b - 1060.5).abs() < 0.1,
            "{a} {b}"
        );
        let exact = TanArchitecture {
            hidden: 7,
            ..TAN_ARCHITECTURE
        };
        let count = exact.weights(10);
        assert!((exact.width_for(10, count) - 7.0).abs() < 1e-12);
    }
}
