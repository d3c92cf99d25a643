//! [`NetPlan`]: the network as a list of layers, built once from a [`ModelConfig`] and a
//! [`Hierarchy`], that every executor reads (candle's reference model and the CPU engine).
//!
//! It holds what is decided before any arithmetic: the variables (named here, in `vars.rs`, and
//! referred to by id everywhere else), each level's convolution operator, the encoder's and
//! decoder's steps in the order they run (convolution blocks with their variables; poolings
//! with their matrix and how the hierarchy says it applies), and the dense heads. Executors
//! turn it into their own layers; none of them names a variable, re-reads the structure
//! string or asks which pooler built the hierarchy.

use super::config::{ConvKind, ConvSpec, ModelConfig};
use super::structure::Layer;
use super::vars::{
    ConvHandles, Ids, LABEL_NAMES, ParamHandle, ParamId, Side, StateHandle, StateId, VarList,
    VarPlan,
};
use crate::error::{Result, VaeError};
use mesh_hierarchy::{CsrMatrix, Hierarchy, PoolMode, adjacency};
use spectral_conv::neighbour_mean_matrix;

/// The dense heads' weights, W_μ and W_σ (`[V_L·C, latent]`): every latent unit sums all of the
/// coarsest level's values, tens of thousands of inputs.
pub const HEAD_WEIGHTS: [&str; 2] = ["enc.mu.weight", "enc.sigma.weight"];

/// One level the network runs on.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Level {
    pub vertices: usize,
    /// Its convolution operator: an index into [`NetPlan::operators`] (without pooling every
    /// level is the template and shares level 0's).
    pub operator: usize,
}

/// A convolution's weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ConvVars {
    /// Chebyshev: `[C_in·K, C_out]`, row c·K + k for input channel c and order k.
    Cheb(ParamId),
    /// Spatial: X·W_self + (D⁻¹A X)·W_nb, each `[C_in, C_out]`.
    Spatial { w_self: ParamId, w_nb: ParamId },
    /// A decoder convolution tied to the encoder's: the adjoint of encoder convolution
    /// `spec.index`, on the transposed operator.
    Tied,
}

/// A batch norm's variables.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BnVars {
    pub gamma: ParamId,
    pub beta: ParamId,
    pub running_mean: StateId,
    pub running_var: StateId,
}

/// conv → [batch norm] → [tanh] on level `spec.level`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ConvStep {
    pub spec: ConvSpec,
    pub weights: ConvVars,
    pub bn: Option<BnVars>,
}

/// Pooling (encoder: level `from` → `from + 1`) or de-pooling (decoder: `from` → `from − 1`),
/// applied as `mode` says with `matrix` (`to × from` vertices).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PoolStep {
    pub from: usize,
    pub to: usize,
    pub mode: PoolMode,
    pub matrix: CsrMatrix,
}

impl PoolStep {
    /// Whether the step is a de-pooling (decoder).
    pub fn is_depool(&self) -> bool {
        self.to < self.from
    }
}

/// One step of the encoder or decoder.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Step {
    Conv(ConvStep),
    Pool(PoolStep),
}

/// The label weights of a conditional model, into μ, σ and the decoder's dense layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct LabelVars {
    pub mu: ParamId,
    pub sigma: ParamId,
    pub dec: ParamId,
}

/// The dense layers between the coarsest level and the latent space: μ = hW_μ + b_μ,
/// σ from hW_σ + b_σ, and the decoder's zW_μᵀ + b_dec (tied to the μ head).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Heads {
    pub w_mu: ParamId,
    pub b_mu: ParamId,
    pub w_sigma: ParamId,
    pub b_sigma: ParamId,
    pub b_dec: ParamId,
    pub labels: Option<LabelVars>,
}

/// The network: variables, levels, steps and heads (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NetPlan {
    /// Trained variables, sorted by name ([`ParamId`] = position).
    pub params: Vec<VarPlan>,
    /// Batch norms' running statistics, sorted by name ([`StateId`] = position).
    pub state: Vec<VarPlan>,
    /// The levels the network uses, template first.
    pub levels: Vec<Level>,
    /// The distinct convolution operators: L̃ for spectral, D⁻¹A for spatial convolutions.
    pub operators: Vec<CsrMatrix>,
    /// The encoder's steps in order.
    pub encoder: Vec<Step>,
    /// The decoder's steps in the order they run (coarsest level first).
    pub decoder: Vec<Step>,
    pub heads: Heads,
}

/// A convolution step while its variables are planned.
struct PlannedConv {
    spec: ConvSpec,
    weights: Option<ConvHandles>,
    bn: Option<([ParamHandle; 2], [StateHandle; 2])>,
}

enum Planned {
    Conv(PlannedConv),
    Pool(PoolStep),
}

impl NetPlan {
    /// The network of `config` on `hierarchy` (built with `config.pool` and at least
    /// `config.pool_levels()` pooling steps).
    ///
    /// Errors: a hierarchy with too few pooling steps, built by another pooler, or with
    /// operators of the wrong shapes.
    pub fn new(config: &ModelConfig, hierarchy: &Hierarchy) -> Result<Self> {
        check_hierarchy(config, hierarchy)?;
        let (levels, operators) = levels_of(config, hierarchy)?;
        let mut vars = VarList::default();
        let mut conv = |side: Side, spec: ConvSpec, own: bool| {
            let shape = match config.conv {
                ConvKind::Spectral => vec![spec.c_in * config.k, spec.c_out],
                ConvKind::Spatial => vec![spec.c_in, spec.c_out],
            };
            let weights = own.then(|| vars.conv(side, spec.index, config.conv, shape));
            let bn = spec
                .batch_norm
                .then(|| vars.batch_norm(side, spec.index, spec.c_out));
            Planned::Conv(PlannedConv { spec, weights, bn })
        };

        let layers = config.structure.layers();
        let (mut encoder, mut level) = (Vec::new(), 0);
        let mut specs = config.encoder_convs().into_iter();
        for layer in layers {
            encoder.push(match layer {
                Layer::Conv => conv(Side::Encoder, next(&mut specs)?, true),
                Layer::Pool => {
                    let op = &hierarchy.pooling[level];
                    level += 1;
                    Planned::Pool(PoolStep {
                        from: level - 1,
                        to: level,
                        mode: op.mode(),
                        matrix: op.pool.clone(),
                    })
                }
            });
        }
        let mut decoder = Vec::new();
        let mut specs = config.decoder_convs().into_iter();
        for layer in layers.iter().rev() {
            decoder.push(match layer {
                Layer::Conv => conv(Side::Decoder, next(&mut specs)?, !config.tie_decoder_convs),
                Layer::Pool => {
                    level -= 1;
                    let op = &hierarchy.pooling[level];
                    Planned::Pool(PoolStep {
                        from: level + 1,
                        to: level,
                        mode: op.mode(),
                        matrix: op.depool.clone(),
                    })
                }
            });
        }

        let flat = levels[levels.len() - 1].vertices * config.channels;
        let latent = config.latent;
        let [mu_name, sigma_name] = HEAD_WEIGHTS;
        let w_mu = vars.weight(mu_name, vec![flat, latent]);
        let b_mu = vars.bias("enc.mu.bias", latent);
        let w_sigma = vars.weight(sigma_name, vec![flat, latent]);
        let b_sigma = vars.bias("enc.sigma.bias", latent);
        let b_dec = vars.bias("dec.fc.bias", flat);
        let l = config.labels.len();
        let labels = (l > 0).then(|| {
            let [mu, sigma, dec] = LABEL_NAMES;
            [
                vars.zero_weight(mu, vec![l, latent]),
                vars.zero_weight(sigma, vec![l, latent]),
                vars.zero_weight(dec, vec![l, flat]),
            ]
        });

        let (params, state, ids) = vars.finish();
        let steps = |planned: Vec<Planned>| -> Vec<Step> {
            planned.into_iter().map(|p| step(p, &ids)).collect()
        };
        Ok(Self {
            params,
            state,
            levels,
            operators,
            encoder: steps(encoder),
            decoder: steps(decoder),
            heads: Heads {
                w_mu: ids.param(w_mu),
                b_mu: ids.param(b_mu),
                w_sigma: ids.param(w_sigma),
                b_sigma: ids.param(b_sigma),
                b_dec: ids.param(b_dec),
                labels: labels.map(|[mu, sigma, dec]| LabelVars {
                    mu: ids.param(mu),
                    sigma: ids.param(sigma),
                    dec: ids.param(dec),
                }),
            },
        })
    }

    /// Vertices of every level the network uses, template first.
    pub fn vertex_counts(&self) -> Vec<usize> {
        self.levels.iter().map(|l| l.vertices).collect()
    }

    /// The coarsest level's vertex count times the channels: the dense layers' width.
    pub fn flat_width(&self) -> usize {
        self.params[self.heads.b_dec.0].len()
    }

    /// The convolution operator of `level`.
    pub fn operator(&self, level: usize) -> &CsrMatrix {
        &self.operators[self.levels[level].operator]
    }

    /// The first pooling step of the encoder, if any.
    pub fn first_pool(&self) -> Option<&PoolStep> {
        self.encoder.iter().find_map(|s| match s {
            Step::Pool(p) => Some(p),
            Step::Conv(_) => None,
        })
    }
}

fn next(specs: &mut impl Iterator<Item = ConvSpec>) -> Result<ConvSpec> {
    specs.next().ok_or_else(|| {
        VaeError::shape(
            "NetPlan::new",
            "internal: fewer convolutions than the structure has",
        )
    })
}

fn step(planned: Planned, ids: &Ids) -> Step {
    match planned {
        Planned::Pool(p) => Step::Pool(p),
        Planned::Conv(c) => Step::Conv(ConvStep {
            spec: c.spec,
            weights: match c.weights {
                None => ConvVars::Tied,
                Some(ConvHandles::Cheb(w)) => ConvVars::Cheb(ids.param(w)),
                Some(ConvHandles::Spatial(s, n)) => ConvVars::Spatial {
                    w_self: ids.param(s),
                    w_nb: ids.param(n),
                },
            },
            bn: c.bn.map(|([gamma, beta], [mean, var])| BnVars {
                gamma: ids.param(gamma),
                beta: ids.param(beta),
                running_mean: ids.state(mean),
                running_var: ids.state(var),
            }),
        }),
    }
}

/// The levels the network uses and their distinct convolution operators.
fn levels_of(config: &ModelConfig, hierarchy: &Hierarchy) -> Result<(Vec<Level>, Vec<CsrMatrix>)> {
    let n_levels = config.pool_levels() + 1;
    let (mut levels, mut operators) = (Vec::with_capacity(n_levels), Vec::new());
    for (i, level) in hierarchy.levels[..n_levels].iter().enumerate() {
        if i > 0 && hierarchy.pooling[i - 1].mode() == PoolMode::Identity {
            // Every level is the template: share its operator.
            levels.push(Level {
                vertices: level.vertex_count,
                operator: 0,
            });
            continue;
        }
        operators.push(match config.conv {
            ConvKind::Spectral => level.laplacian.clone(),
            ConvKind::Spatial => {
                neighbour_mean_matrix(&adjacency(level.vertex_count, &level.faces))?
            }
        });
        levels.push(Level {
            vertices: level.vertex_count,
            operator: operators.len() - 1,
        });
    }
    Ok((levels, operators))
}

/// The hierarchy must have the structure's pooling steps, built by the configured pooler.
fn check_hierarchy(config: &ModelConfig, h: &Hierarchy) -> Result<()> {
    h.check_shapes()
        .map_err(|what| VaeError::argument("hierarchy", what))?;
    let need = config.pool_levels();
    if h.pooling.len() < need {
        return Err(VaeError::argument(
            "hierarchy",
            format!(
                "has {} pooling steps; structure {} needs {need}",
                h.pooling.len(),
                config.structure
            ),
        ));
    }
    let pooler = config.pool;
    if let Some(op) = h.pooling[..need].iter().find(|op| op.kind != pooler) {
        return Err(VaeError::argument(
            "hierarchy",
            format!(
                "built with pooler {}; the model's pool is {pooler}",
                op.kind
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
