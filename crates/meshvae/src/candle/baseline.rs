//! The other auto-encoders ([`BaselinePlan`]) in candle: their layers built on the plan's
//! variables, run with candle's autograd (the CPU engine covers ours only).
//!
//! Activations stay batch-major `[B, V, C]` between graph layers, the layout of spectral-conv's
//! layers: its Chebyshev convolution for CoMA, its spiral convolution (one dense layer over
//! each vertex's spiral, index s·C + c in SpiralNet++'s order) for SpiralNet++.

use crate::error::{Result, VaeError};
use crate::net::baseline::{BaselinePlan, BaselineStep, Dense, GraphLayer};
use crate::net::network::{Activation, GraphConvKind};
use candle_core::{Device, Tensor, Var};
use mesh_hierarchy::{Hierarchy, Pooler, spirals};
use spectral_conv::{ChebConv, Sampling, SparseOp, SpiralConv};
use std::sync::Arc;

/// A graph convolution of a baseline.
#[derive(Debug, Clone)]
enum Conv {
    Cheb(ChebConv),
    Spiral(SpiralConv),
}

#[derive(Debug, Clone)]
enum Layer {
    Conv { conv: Conv, activation: Activation },
    Resample(Sampling),
}

#[derive(Debug, Clone)]
struct DenseLayer {
    weight: Tensor,
    bias: Tensor,
    activation: Activation,
}

/// A baseline network on its variables.
#[derive(Debug, Clone)]
pub(crate) struct BaselineNet {
    pub plan: Arc<BaselinePlan>,
    encoder: Vec<Layer>,
    enc_dense: Vec<DenseLayer>,
    mu: DenseLayer,
    sigma: Option<DenseLayer>,
    dec_dense: Vec<DenseLayer>,
    decoder: Vec<Layer>,
}

fn activate(x: Tensor, a: Activation) -> Result<Tensor> {
    Ok(match a {
        Activation::Linear => x,
        Activation::Tanh => x.tanh()?,
        Activation::Relu => x.relu()?,
        Activation::Elu => super::elu::elu(&x, 1.0)?,
    })
}

impl DenseLayer {
    /// x `[B, c_in]` → `[B, c_out]`.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        activate(
            x.matmul(&self.weight)?.broadcast_add(&self.bias)?,
            self.activation,
        )
    }
}

impl Layer {
    /// x `[B, V, C]`.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        match self {
            Self::Resample(s) => Ok(s.forward(x)?),
            Self::Conv { conv, activation } => activate(conv.forward(x)?, *activation),
        }
    }
}

impl Conv {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        match self {
            Self::Cheb(c) => Ok(c.forward(x)?),
            Self::Spiral(c) => Ok(c.forward(x)?),
        }
    }
}

impl BaselineNet {
    /// The layers of `plan` on `hierarchy` over the variables `params` (the plan's order).
    pub fn new(
        plan: BaselinePlan,
        hierarchy: &Hierarchy,
        params: &[Var],
        device: &Device,
    ) -> Result<Self> {
        check_hierarchy(&plan, hierarchy)?;
        let t = |id: crate::net::vars::ParamId| params[id.0].as_tensor().clone();
        let dense = |d: &Dense| DenseLayer {
            weight: t(d.weight),
            bias: t(d.bias),
            activation: d.activation,
        };
        let mut operators: Vec<Option<SparseOp>> = vec![None; plan.vertex_counts.len()];
        let mut conv = |g: &GraphLayer| -> Result<Layer> {
            let conv = match g.conv {
                GraphConvKind::Chebyshev { k } => {
                    let op = match &operators[g.level] {
                        Some(op) => op.clone(),
                        None => {
                            let op = SparseOp::new(&hierarchy.levels[g.level].laplacian, device)?;
                            operators[g.level] = Some(op.clone());
                            op
                        }
                    };
                    Conv::Cheb(ChebConv::from_weights(op, k, t(g.weight), g.bias.map(t))?)
                }
                GraphConvKind::Spiral { length } => {
                    let level = &hierarchy.levels[g.level];
                    let s = spirals(&level.positions, &level.faces, length, 1)?;
                    Conv::Spiral(SpiralConv::from_weights(
                        &s.indices,
                        length,
                        t(g.weight),
                        g.bias.map(t),
                    )?)
                }
            };
            Ok(Layer::Conv {
                conv,
                activation: g.activation,
            })
        };
        let mut layers = |steps: &[BaselineStep]| -> Result<Vec<Layer>> {
            steps
                .iter()
                .map(|s| match s {
                    BaselineStep::Conv(g) => conv(g),
                    BaselineStep::Down { from } => Ok(Layer::Resample(Sampling::new(
                        &hierarchy.pooling[*from].pool,
                        device,
                    )?)),
                    BaselineStep::Up { to } => Ok(Layer::Resample(Sampling::new(
                        &hierarchy.pooling[*to].depool,
                        device,
                    )?)),
                })
                .collect()
        };
        let encoder = layers(&plan.encoder)?;
        let decoder = layers(&plan.decoder)?;
        Ok(Self {
            encoder,
            decoder,
            enc_dense: plan.enc_dense.iter().map(dense).collect(),
            mu: dense(&plan.mu),
            sigma: plan.sigma.as_ref().map(dense),
            dec_dense: plan.dec_dense.iter().map(dense).collect(),
            plan: Arc::new(plan),
        })
    }

    /// μ and, for a VAE, σ = √(2·sigmoid(·)) `[B, latent]` of x `[B, V, C]`.
    pub fn encode(&self, x: &Tensor) -> Result<(Tensor, Option<Tensor>)> {
        let batch = x.dim(0)?;
        let mut h = x.contiguous()?;
        for layer in &self.encoder {
            h = layer.forward(&h)?;
        }
        let mut h = h.reshape((batch, self.plan.flat_width()))?;
        for d in &self.enc_dense {
            h = d.forward(&h)?;
        }
        let mu = self.mu.forward(&h)?;
        let sigma = match &self.sigma {
            Some(s) => Some(crate::candle::model::sigma_head(&s.forward(&h)?)?),
            None => None,
        };
        Ok((mu, sigma))
    }

    /// x̂ `[B, V, C]` of z `[B, latent]`.
    pub fn decode(&self, z: &Tensor) -> Result<Tensor> {
        let batch = z.dim(0)?;
        let mut h = z.clone();
        for d in &self.dec_dense {
            h = d.forward(&h)?;
        }
        let coarse = self.plan.vertex_counts[self.plan.vertex_counts.len() - 1];
        let mut h = h.reshape((batch, coarse, self.plan.coarse_channels))?;
        for layer in &self.decoder {
            h = layer.forward(&h)?;
        }
        Ok(h)
    }
}

/// The position networks need four steps of CoMA's sampling.
fn check_hierarchy(plan: &BaselinePlan, h: &Hierarchy) -> Result<()> {
    h.check_shapes()
        .map_err(|what| VaeError::argument("hierarchy", what))?;
    let need = plan.vertex_counts.len() - 1;
    let steps = &h.pooling[..need.min(h.pooling.len())];
    if steps.len() < need || steps.iter().any(|op| op.kind != Pooler::Sampling) {
        return Err(VaeError::argument(
            "hierarchy",
            format!(
                "{} needs {need} steps of mesh sampling; this hierarchy has {} ({})",
                plan.network,
                h.pooling.len(),
                h.pooling
                    .iter()
                    .map(|op| op.kind.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    if h.levels[0].vertex_count != plan.vertex_counts[0] {
        return Err(VaeError::argument(
            "hierarchy",
            format!(
                "has {} vertices; the network was planned for {}",
                h.levels[0].vertex_count, plan.vertex_counts[0]
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::candle::model::MeshVae;
    use crate::net::config::ModelConfig;
    use crate::net::loss_weights::LossWeights;
    use crate::net::network::Network;
    use crate::numerics::rng::Rng;
    use candle_core::DType;

    fn random(shape: &[usize], seed: u64) -> Tensor {
        let n = shape.iter().product();
        Tensor::from_vec(Rng::new(seed).normals(n), shape, &Device::Cpu).unwrap()
    }

    #[test]
    fn a_spiral_convolution_is_a_dense_layer_over_the_gathered_spiral() {
        let mesh = qem_simplify::shapes::icosphere(1);
        let (v, b, c, o, s) = (mesh.vertex_count(), 2, 3, 4, 5);
        let sp = spirals(&mesh.positions, &mesh.faces, s, 1).unwrap();
        let spiral = SpiralConv::from_weights(
            &sp.indices,
            s,
            random(&[s * c, o], 2),
            Some(random(&[o], 3)),
        );
        let conv = Conv::Spiral(spiral.unwrap());
        let x = random(&[b, v, c], 1);
        let y: Vec<f64> = conv
            .forward(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let (xs, w, bias): (Vec<f64>, Vec<f64>, Vec<f64>) = (
            x.flatten_all().unwrap().to_vec1().unwrap(),
            random(&[s * c, o], 2)
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap(),
            random(&[o], 3).to_vec1().unwrap(),
        );
        for vi in 0..v {
            for bi in 0..b {
                for oi in 0..o {
                    let mut want = bias[oi];
                    for (si, &u) in sp.of(vi).iter().enumerate() {
                        for ci in 0..c {
                            want += xs[(bi * v + u as usize) * c + ci] * w[(si * c + ci) * o + oi];
                        }
                    }
                    let got = y[(bi * v + vi) * o + oi];
                    assert!(
                        (got - want).abs() < 1e-12,
                        "{vi} {bi} {oi}: {got} vs {want}"
                    );
                }
            }
        }
    }

    /// The training loss's gradient by candle's autograd against central differences in f64,
    /// on a few entries of every variable: checks the assembled network (spiral gathers, the
    /// sampling operators' backward, the activations, the heads).
    fn gradients_match_finite_differences(net: Network) {
        let sphere = qem_simplify::shapes::icosphere(4);
        let config = ModelConfig {
            latent: 3,
            ..ModelConfig::for_network(net)
        };
        let h = Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap();
        let model = MeshVae::with_dtype(&config, &h, &Device::Cpu, DType::F64, 7).unwrap();
        // Biases start at zero, where a ReLU unit whose inputs are all zero sits exactly on its
        // kink (no derivative): move them off it.
        for (i, (name, var)) in model.trainable_vars().into_iter().enumerate() {
            if name.ends_with(".bias") {
                let t = (random(var.dims(), 100 + i as u64) * 0.1).unwrap();
                var.set(&t).unwrap();
            }
        }
        let channels = net.input().channels();
        let x = (random(&[2, sphere.vertex_count(), channels], 11) * 0.5).unwrap();
        let eps = random(&[2, 3], 12);
        let weights = LossWeights {
            rec: 1.0,
            kl: 0.5,
            l2: 0.0,
        };
        let loss = |m: &MeshVae| -> f64 {
            let l = m.training_loss(&x, None, &eps, &weights).unwrap();
            l.total.to_scalar::<f64>().unwrap()
        };
        let l = model.training_loss(&x, None, &eps, &weights).unwrap();
        let grads = model.backward(&l.total).unwrap();
        let mut checked = 0;
        for (name, var) in model.trainable_vars() {
            let g: Vec<f64> = grads
                .get(var.as_tensor())
                .unwrap_or_else(|| panic!("{name} has no gradient"))
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap();
            let n = g.len();
            for i in [0, n / 2, n - 1] {
                let original: Vec<f64> = var.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
                let h = 1e-5;
                let at = |delta: f64| {
                    let mut w = original.clone();
                    w[i] += delta;
                    let t = Tensor::from_vec(w, var.shape(), &Device::Cpu).unwrap();
                    var.set(&t).unwrap();
                    loss(&model)
                };
                let fd = (at(h) - at(-h)) / (2.0 * h);
                at(0.0);
                // The loss is summed in parallel, in an order that varies by ~1e-13: a noise of
                // ~1e-8 in the difference quotient.
                let tol = 2e-4 * fd.abs().max(g[i].abs()) + 1e-6;
                assert!(
                    (fd - g[i]).abs() < tol,
                    "{net} {name}[{i}]: autograd {} vs {fd}",
                    g[i]
                );
                checked += 1;
            }
        }
        assert!(checked >= 3 * 10, "{net}: {checked} entries checked");
    }

    #[test]
    fn coma_gradients_match_finite_differences() {
        gradients_match_finite_differences(Network::Coma);
    }

    #[test]
    fn spiralnet_gradients_match_finite_differences() {
        gradients_match_finite_differences(Network::SpiralNet);
    }

    #[test]
    fn tan2018_is_a_vae_on_features_and_its_gradients_match() {
        let sphere = qem_simplify::shapes::icosphere(1);
        let config = ModelConfig::for_network(Network::Tan2018);
        let h = Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap();
        assert_eq!(h.pooling.len(), 0);
        let model = MeshVae::with_dtype(&config, &h, &Device::Cpu, DType::F64, 3).unwrap();
        let x = random(&[2, sphere.vertex_count(), 9], 1);
        let e = model
            .encode(&x, None, crate::candle::batch_norm::Mode::Eval)
            .unwrap();
        assert_eq!(e.mu.dims(), &[2, 128]);
        let sigma: Vec<f64> = e.sigma.flatten_all().unwrap().to_vec1().unwrap();
        assert!(sigma.iter().all(|&s| s > 0.0 && s < 2f64.sqrt()));
        let l = model
            .training_loss(&x, None, &random(&[2, 128], 2), &LossWeights::default())
            .unwrap();
        assert!(l.kl > 0.0 && l.rec > 0.0);
        // A position network's input has 3 channels: features are refused.
        let coma = ModelConfig::for_network(Network::Coma);
        let big = qem_simplify::shapes::icosphere(4);
        let hc = Hierarchy::build(&big, &coma.hierarchy_config()).unwrap();
        let m = MeshVae::new(&coma, &hc, &Device::Cpu, 1).unwrap();
        let x9 = Tensor::zeros((1, big.vertex_count(), 9), DType::F32, &Device::Cpu).unwrap();
        let err = m
            .encode(&x9, None, crate::candle::batch_norm::Mode::Eval)
            .unwrap_err();
        assert!(err.to_string().contains("positions"), "{err}");
        // A hierarchy built for ours is refused.
        let ours = Hierarchy::build(&big, &ModelConfig::default().hierarchy_config()).unwrap();
        assert!(MeshVae::new(&coma, &ours, &Device::Cpu, 1).is_err());
    }
}
