//! [`BaselinePlan`]: the other auto-encoders ([`Network::Tan2018`], [`Network::Coma`],
//! [`Network::SpiralNet`]) as a list of layers over their variables, before any executor: what
//! the candle executor runs (`candle/baseline.rs`) and what their parameter count is.
//!
//! Variable names: `enc.conv{i}.{weight, bias}`, `enc.fc{i}.{weight, bias}`, `enc.mu.{weight,
//! bias}`, `enc.sigma.{weight, bias}` (VAEs only), `dec.fc{i}.{weight, bias}`,
//! `dec.conv{i}.{weight, bias}` (decoder convolutions numbered in the order they run). Weights
//! start Glorot-uniform (SpiralNet++'s initialisation; CoMA's code draws a truncated normal of
//! σ 0.1, the mesh VAE's is not published), biases at zero.

use super::network::{Activation, DenseNet, GraphConvKind, Network, PositionNet};
use super::vars::{Ids, ParamHandle, ParamId, VarList, VarPlan};
use crate::error::{Result, VaeError};

/// A dense layer `[c_in] → [c_out]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Dense {
    pub c_in: usize,
    pub c_out: usize,
    pub weight: ParamId,
    pub bias: ParamId,
    pub activation: Activation,
}

/// A graph convolution on level `level`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct GraphLayer {
    pub level: usize,
    pub conv: GraphConvKind,
    pub c_in: usize,
    pub c_out: usize,
    pub weight: ParamId,
    pub bias: Option<ParamId>,
    pub activation: Activation,
}

/// One step on the per-vertex values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BaselineStep {
    Conv(GraphLayer),
    /// Down-sampling from level `from` to `from + 1`.
    Down {
        from: usize,
    },
    /// Up-sampling from level `to + 1` to `to`.
    Up {
        to: usize,
    },
}

/// The network: per-vertex steps, dense layers, heads (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BaselinePlan {
    pub network: Network,
    /// Trained variables, sorted by name ([`ParamId`] = position).
    pub params: Vec<VarPlan>,
    /// Vertices of the levels the network uses, template first.
    pub vertex_counts: Vec<usize>,
    /// Per-vertex channels of the input and the output.
    pub channels: usize,
    pub encoder: Vec<BaselineStep>,
    /// Dense layers after flattening the coarsest level, before the heads.
    pub enc_dense: Vec<Dense>,
    pub mu: Dense,
    /// σ = √(2·sigmoid(hW_σ + b_σ)) as ours (VAEs only).
    pub sigma: Option<Dense>,
    /// Dense layers from z; the last one's output is the coarsest level's values.
    pub dec_dense: Vec<Dense>,
    /// Channels per vertex after the decoder's dense layers.
    pub coarse_channels: usize,
    pub decoder: Vec<BaselineStep>,
}

struct Planned {
    c_in: usize,
    c_out: usize,
    weight: ParamHandle,
    bias: ParamHandle,
    activation: Activation,
}

impl Planned {
    fn dense(&self, ids: &Ids) -> Dense {
        Dense {
            c_in: self.c_in,
            c_out: self.c_out,
            weight: ids.param(self.weight),
            bias: ids.param(self.bias),
            activation: self.activation,
        }
    }
}

fn dense(vars: &mut VarList, name: &str, c_in: usize, c_out: usize, act: Activation) -> Planned {
    Planned {
        c_in,
        c_out,
        weight: vars.glorot_weight(&format!("{name}.weight"), vec![c_in, c_out], c_in, c_out),
        bias: vars.bias(&format!("{name}.bias"), c_out),
        activation: act,
    }
}

impl BaselinePlan {
    /// The plan of `network` (not ours) with latent size `latent` on levels of
    /// `vertex_counts` vertices (template first; the position networks need five levels).
    pub fn new(network: Network, latent: usize, vertex_counts: &[usize]) -> Result<Self> {
        if vertex_counts.first().is_none_or(|&v| v == 0) {
            return Err(VaeError::argument(
                "hierarchy",
                format!("{network} needs a template with vertices; got levels {vertex_counts:?}"),
            ));
        }
        if let Some(net) = network.position_net() {
            return Self::positions(network, net, latent, vertex_counts);
        }
        match network {
            Network::Tan2018 => Ok(Self::dense_net(
                network,
                super::network::TAN2018,
                latent,
                vertex_counts,
            )),
            _ => Err(VaeError::argument(
                "net",
                format!("{network} is built from its configuration, not a baseline plan"),
            )),
        }
    }

    fn dense_net(network: Network, net: DenseNet, latent: usize, vertex_counts: &[usize]) -> Self {
        let channels = network.input().channels();
        let flat = vertex_counts[0] * channels;
        let mut vars = VarList::default();
        let mut widths = vec![flat];
        widths.extend(net.hidden);
        let enc: Vec<Planned> = widths
            .windows(2)
            .enumerate()
            .map(|(i, w)| dense(&mut vars, &format!("enc.fc{i}"), w[0], w[1], net.activation))
            .collect();
        let h = *widths.last().unwrap_or(&flat);
        let mu = dense(&mut vars, "enc.mu", h, latent, Activation::Linear);
        let sigma = dense(&mut vars, "enc.sigma", h, latent, Activation::Linear);
        let mut back = vec![latent];
        back.extend(net.hidden.iter().rev());
        back.push(flat);
        // Every decoder layer ends in tanh, the output too (features live in ±0.95).
        let dec: Vec<Planned> = back
            .windows(2)
            .enumerate()
            .map(|(i, w)| {
                dense(
                    &mut vars,
                    &format!("dec.fc{i}"),
                    w[0],
                    w[1],
                    Activation::Tanh,
                )
            })
            .collect();
        let (params, _, ids) = vars.finish();
        Self {
            network,
            params,
            vertex_counts: vertex_counts[..1].to_vec(),
            channels,
            encoder: Vec::new(),
            enc_dense: enc.iter().map(|p| p.dense(&ids)).collect(),
            mu: mu.dense(&ids),
            sigma: Some(sigma.dense(&ids)),
            dec_dense: dec.iter().map(|p| p.dense(&ids)).collect(),
            coarse_channels: channels,
            decoder: Vec::new(),
        }
    }

    fn positions(
        network: Network,
        net: PositionNet,
        latent: usize,
        vertex_counts: &[usize],
    ) -> Result<Self> {
        let levels = net.channels.len();
        if vertex_counts.len() < levels + 1 {
            return Err(VaeError::argument(
                "hierarchy",
                format!(
                    "has {} levels; {network} needs {}",
                    vertex_counts.len(),
                    levels + 1
                ),
            ));
        }
        let channels = network.input().channels();
        let mut vars = VarList::default();
        let taps = |c_in: usize| match net.conv {
            GraphConvKind::Chebyshev { k } => c_in * k,
            GraphConvKind::Spiral { length } => c_in * length,
        };
        let mut conv = |side: &str, i: usize, level: usize, c_in: usize, c_out: usize, last| {
            let name = format!("{side}.conv{i}");
            let w = vars.glorot_weight(
                &format!("{name}.weight"),
                vec![taps(c_in), c_out],
                taps(c_in),
                c_out,
            );
            // CoMA's last convolution has no bias (its biases come with the ReLU).
            let bias = !(last && matches!(net.conv, GraphConvKind::Chebyshev { .. }));
            let b = bias.then(|| vars.bias(&format!("{name}.bias"), c_out));
            let activation = if last {
                Activation::Linear
            } else {
                net.activation
            };
            (level, c_in, c_out, w, b, activation)
        };
        let mut enc_convs = Vec::new();
        let mut c = channels;
        for (i, &out) in net.channels.iter().enumerate() {
            enc_convs.push(conv("enc", i, i, c, out, false));
            c = out;
        }
        let mut dec_convs = Vec::new();
        for (i, level) in (0..levels).rev().enumerate() {
            let out = net.channels[level];
            dec_convs.push(conv("dec", i, level, c, out, false));
            c = out;
        }
        dec_convs.push(conv("dec", levels, 0, c, channels, true));
        let coarse_channels = net.channels[levels - 1];
        let flat = vertex_counts[levels] * coarse_channels;
        let act = net.dense_activation;
        let mu = dense(&mut vars, "enc.mu", flat, latent, act);
        let dec_fc = dense(&mut vars, "dec.fc0", latent, flat, act);
        let (params, _, ids) = vars.finish();
        let layer = |(level, c_in, c_out, w, b, activation): (_, _, _, _, Option<_>, _)| {
            BaselineStep::Conv(GraphLayer {
                level,
                conv: net.conv,
                c_in,
                c_out,
                weight: ids.param(w),
                bias: b.map(|b| ids.param(b)),
                activation,
            })
        };
        let mut encoder = Vec::new();
        for (from, c) in enc_convs.into_iter().enumerate() {
            encoder.push(layer(c));
            encoder.push(BaselineStep::Down { from });
        }
        let mut decoder = Vec::new();
        let mut convs = dec_convs.into_iter();
        for to in (0..levels).rev() {
            decoder.push(BaselineStep::Up { to });
            decoder.extend(convs.next().map(layer));
        }
        decoder.extend(convs.map(layer));
        Ok(Self {
            network,
            params,
            vertex_counts: vertex_counts[..=levels].to_vec(),
            channels,
            encoder,
            enc_dense: Vec::new(),
            mu: mu.dense(&ids),
            sigma: None,
            dec_dense: vec![dec_fc.dense(&ids)],
            coarse_channels,
            decoder,
        })
    }

    /// The coarsest level's values per mesh: the width of the flattened encoder output.
    pub fn flat_width(&self) -> usize {
        self.vertex_counts[self.vertex_counts.len() - 1] * self.coarse_channels
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(plan: &BaselinePlan) -> (usize, usize) {
        let all: usize = plan.params.iter().map(|p| p.len()).sum();
        let weights: usize = plan
            .params
            .iter()
            .filter(|p| !p.bias)
            .map(|p| p.len())
            .sum();
        (all, weights)
    }

    #[test]
    fn coma_has_its_published_layers() {
        // A 5,023-vertex mesh (CoMA's face template) sampled by 4 four times.
        let counts = [5023, 1256, 314, 79, 20];
        let plan = BaselinePlan::new(Network::Coma, 8, &counts).unwrap();
        let convs: Vec<(usize, usize, usize)> = plan
            .encoder
            .iter()
            .chain(&plan.decoder)
            .filter_map(|s| match s {
                BaselineStep::Conv(c) => Some((c.level, c.c_in, c.c_out)),
                _ => None,
            })
            .collect();
        assert_eq!(
            convs,
            [
                (0, 3, 16),
                (1, 16, 16),
                (2, 16, 16),
                (3, 16, 32),
                (3, 32, 32),
                (2, 32, 16),
                (1, 16, 16),
                (0, 16, 16),
                (0, 16, 3)
            ]
        );
        assert_eq!(plan.flat_width(), 20 * 32);
        // Chebyshev weights 6·(3·16 + 16·16 + 16·16 + 16·32 + 32·32 + 32·16 + 16·16 + 16·16 +
        // 16·3), dense 640·8 twice, biases 16·3 + 32 + 32 + 16·3 (convolutions) + 8 + 640.
        let cheb = 6 * (48 + 256 + 256 + 512 + 1024 + 512 + 256 + 256 + 48);
        let (all, weights) = count(&plan);
        assert_eq!(weights, cheb + 2 * 640 * 8);
        assert_eq!(all - weights, 16 * 3 + 32 + 32 + 16 * 3 + 8 + 640);
        assert!(plan.sigma.is_none());
        let steps: Vec<_> = plan
            .decoder
            .iter()
            .map(|s| matches!(s, BaselineStep::Up { .. }))
            .collect();
        assert_eq!(
            steps,
            [true, false, true, false, true, false, true, false, false]
        );
    }

    #[test]
    fn spiralnet_and_tan2018_count_as_their_definitions_say() {
        let counts = [5023, 1256, 314, 79, 20];
        let plan = BaselinePlan::new(Network::SpiralNet, 16, &counts).unwrap();
        let convs = [
            (3, 32),
            (32, 32),
            (32, 32),
            (32, 64),
            (64, 64),
            (64, 32),
            (32, 32),
            (32, 32),
            (32, 3),
        ];
        let spiral: usize = convs.iter().map(|(i, o)| 9 * i * o).sum();
        let biases: usize = convs.iter().map(|(_, o)| o).sum::<usize>() + 16 + 20 * 64;
        let (all, weights) = count(&plan);
        assert_eq!(weights, spiral + 2 * 20 * 64 * 16);
        assert_eq!(all - weights, biases);

        // The mesh VAE on 3,573 vertices (the paper's Hand): 9V → 1024 → 128 (μ, σ), 128 → 1024
        // → 9V.
        let plan = BaselinePlan::new(Network::Tan2018, 128, &[3573]).unwrap();
        let (_, weights) = count(&plan);
        let flat = 9 * 3573;
        assert_eq!(weights, 2 * flat * 1024 + 3 * 1024 * 128);
        assert!(plan.sigma.is_some() && plan.encoder.is_empty());
        assert!(BaselinePlan::new(Network::Coma, 8, &[100, 25]).is_err());
        assert!(BaselinePlan::new(Network::Ours, 8, &[100]).is_err());
        assert!(BaselinePlan::new(Network::Tan2018, 8, &[]).is_err());
    }
}
