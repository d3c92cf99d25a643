//! [`param_count`]: the number of trained scalars of a configuration, without building it.
//!
//! The paper (Table 4) counts weights only: 2 · V_L · C · latent for the μ and σ heads (the
//! decoder's dense layer is tied to the μ head, so it adds no weights) plus the convolutions'
//! matrices (6 × 27·9 for `CCPC` with K = 3); for V₂ = 3,446 that is 7,941,042. Biases, the
//! decoder's dense bias and batch norm's γ and β are counted in `with_biases` only.
//!
//! A conditional model with L labels adds its label weights (see `candle/model/cond.rs`):
//! L·latent into each head and L·V_L·C into the decoder's dense layer. With L = 0 the count is
//! the paper's.

use crate::net::baseline::BaselinePlan;
use crate::net::config::{ConvKind, ConvSpec, ModelConfig};
use crate::net::vars::VarPlan;

/// Trained scalars, with and without biases (biases include batch norm's γ and β).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ParamCount {
    pub with_biases: usize,
    pub without_biases: usize,
}

/// The parameter count of `config` on a hierarchy with these level vertex counts (template
/// first; only the last one, the coarsest level the network reaches, matters, so a hierarchy's
/// `vertex_counts()` truncated to `config.pool_levels() + 1` entries is what to pass). An empty
/// slice counts as zero vertices.
///
/// The other networks ([`crate::Network`]) count every variable of their plan; they need the
/// counts of every level they use (template first), and count zero where those are missing.
pub fn param_count(config: &ModelConfig, vertex_counts: &[usize]) -> ParamCount {
    if !config.net.is_ours() {
        let plan = (!vertex_counts.is_empty())
            .then(|| BaselinePlan::new(config.net, config.latent, vertex_counts).ok())
            .flatten();
        return plan.map_or(
            ParamCount {
                with_biases: 0,
                without_biases: 0,
            },
            |p| count_of(&p.params),
        );
    }
    let coarse = vertex_counts.last().copied().unwrap_or(0);
    let conv_weights = |s: &ConvSpec| match config.conv {
        ConvKind::Spectral => s.c_in * config.k * s.c_out,
        ConvKind::Spatial => 2 * s.c_in * s.c_out,
    };
    let (enc, dec) = (config.encoder_convs(), config.decoder_convs());
    let mut weights: usize = enc.iter().map(conv_weights).sum();
    if !config.tie_decoder_convs {
        weights += dec.iter().map(conv_weights).sum::<usize>();
    }
    let flat = coarse * config.channels;
    weights += 2 * flat * config.latent;
    weights += config.labels.len() * (2 * config.latent + flat);
    let bn: usize = enc
        .iter()
        .chain(&dec)
        .filter(|s| s.batch_norm)
        .map(|s| 2 * s.c_out)
        .sum();
    let biases = 2 * config.latent + flat + bn;
    ParamCount {
        with_biases: weights + biases,
        without_biases: weights,
    }
}

/// The count of a list of variables (biases: [`VarPlan::bias`]).
pub(crate) fn count_of(params: &[VarPlan]) -> ParamCount {
    let (mut with_biases, mut without_biases) = (0, 0);
    for p in params {
        with_biases += p.len();
        if !p.bias {
            without_biases += p.len();
        }
    }
    ParamCount {
        with_biases,
        without_biases,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_papers_figures() {
        let c = ModelConfig::default();
        for (v2, paper) in [(3_446, 7_941_042), (1_787, 4_118_706)] {
            let p = param_count(&c, &[0, v2]);
            assert_eq!(p.without_biases, paper);
            assert_eq!(p.without_biases, 2 * v2 * 9 * 128 + 6 * 27 * 9);
            // b_μ, b_σ (128 each), b_dec (9·V₂), γ/β of 4 batch norms (9 each).
            assert_eq!(p.with_biases - p.without_biases, 256 + 9 * v2 + 4 * 18);
        }
    }

    #[test]
    fn options_change_the_count_as_they_should() {
        let base = ModelConfig::default();
        let p = param_count(&base, &[100, 50]);
        let tied = ModelConfig {
            tie_decoder_convs: true,
            ..base.clone()
        };
        assert_eq!(
            param_count(&tied, &[100, 50]).without_biases,
            p.without_biases - 3 * 243
        );
        let spatial = ModelConfig {
            conv: ConvKind::Spatial,
            ..base.clone()
        };
        assert_eq!(
            param_count(&spatial, &[100, 50]).without_biases,
            p.without_biases - 6 * 243 + 6 * 162
        );
        let no_bn = ModelConfig {
            batch_norm: false,
            ..base.clone()
        };
        assert_eq!(
            param_count(&no_bn, &[100, 50]).with_biases,
            p.with_biases - 72
        );
        // Wider layers: first 9→16, then 16→16; the decoder mirrors.
        let wide = ModelConfig {
            channels: 16,
            structure: "C".parse().unwrap(),
            ..base
        };
        let w = param_count(&wide, &[100]);
        assert_eq!(w.without_biases, 2 * 27 * 16 + 2 * 1600 * 128);
        assert_eq!(w.with_biases, w.without_biases + 256 + 1600);
    }

    #[test]
    fn labels_add_their_weights_only() {
        let base = ModelConfig::default();
        let p = param_count(&base, &[100, 50]);
        let cond = base.conditional_on(&["a", "b", "c"].map(String::from));
        let q = param_count(&cond, &[100, 50]);
        assert_eq!(q.without_biases, p.without_biases + 3 * (2 * 128 + 50 * 9));
        assert_eq!(
            q.with_biases - q.without_biases,
            p.with_biases - p.without_biases
        );
    }
}
