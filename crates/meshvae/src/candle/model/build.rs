//! The parts [`MeshVae::with_dtype`](super::MeshVae::with_dtype) assembles: each level's
//! convolution operator, the encoder and decoder blocks on their variables, and the pooling
//! layers between levels, from the hierarchy's operators (each says how it applies).

use super::layers::{ConvBlock, Down, GraphConv, LevelOps, Up, Weights};
use super::vars;
use crate::candle::batch_norm::BatchNorm;
use crate::error::{Result, VaeError};
use crate::net::config::{ConvKind, ConvSpec, ModelConfig};
use candle_core::{Device, Tensor, Var};
use mesh_hierarchy::{Hierarchy, PoolMode, adjacency};
use spectral_conv::{
    ChebConv, DePool, MaxMode, MaxPool, MeanPool, Sampling, SparseOp, SpatialConv,
    neighbour_mean_matrix,
};
use std::collections::BTreeMap;

pub(super) fn var<'a>(map: &'a BTreeMap<String, Var>, name: &str) -> Result<&'a Var> {
    map.get(name)
        .ok_or_else(|| VaeError::shape("MeshVae::new", format!("variable {name} was not created")))
}

/// Per level the network uses: its convolution operator (and the transpose for tied decoder
/// convolutions).
pub(super) fn level_ops(
    config: &ModelConfig,
    hierarchy: &Hierarchy,
    n_levels: usize,
    device: &Device,
) -> Result<Vec<LevelOps>> {
    let mut levels: Vec<LevelOps> = Vec::with_capacity(n_levels);
    for (i, level) in hierarchy.levels[..n_levels].iter().enumerate() {
        if i > 0 && hierarchy.pooling[i - 1].mode() == PoolMode::Identity {
            // Every level is the template: share its operators.
            levels.push(levels[0].clone());
            continue;
        }
        let op = match config.conv {
            ConvKind::Spectral => SparseOp::new(&level.laplacian, device)?,
            ConvKind::Spatial => {
                let adj = adjacency(level.vertex_count, &level.faces);
                SparseOp::new(&neighbour_mean_matrix(&adj)?, device)?
            }
        };
        let op_t = if config.tie_decoder_convs {
            Some(op.transpose()?)
        } else {
            None
        };
        levels.push(LevelOps { op, op_t });
    }
    Ok(levels)
}

/// The encoder's and the decoder's blocks (convolution, batch norm) on their variables.
pub(super) fn conv_blocks(
    config: &ModelConfig,
    levels: &[LevelOps],
    trainable: &BTreeMap<String, Var>,
    state: &BTreeMap<String, Var>,
) -> Result<(Vec<ConvBlock>, Vec<ConvBlock>)> {
    let block = |side: &str, spec: ConvSpec, own: bool| -> Result<ConvBlock> {
        let weights = if own {
            let names = vars::conv_weight_names(side, config.conv, spec.index);
            let op = levels[spec.level].op.clone();
            let w =
                |i: usize| -> Result<Tensor> { Ok(var(trainable, &names[i])?.as_tensor().clone()) };
            Weights::Own(match config.conv {
                ConvKind::Spectral => {
                    GraphConv::Cheb(ChebConv::from_weights(op, config.k, w(0)?, None)?)
                }
                ConvKind::Spatial => {
                    GraphConv::Spatial(SpatialConv::from_weights(op, w(0)?, w(1)?, None)?)
                }
            })
        } else {
            Weights::Tied
        };
        let bn = if spec.batch_norm {
            let [g, b, m, v] = vars::bn_names(side, spec.index);
            Some(BatchNorm::new(
                var(trainable, &g)?.clone(),
                var(trainable, &b)?.clone(),
                var(state, &m)?.clone(),
                var(state, &v)?.clone(),
            )?)
        } else {
            None
        };
        Ok(ConvBlock { spec, weights, bn })
    };
    let enc = config
        .encoder_convs()
        .into_iter()
        .map(|s| block("enc", s, true))
        .collect::<Result<Vec<_>>>()?;
    let dec = config
        .decoder_convs()
        .into_iter()
        .map(|s| block("dec", s, !config.tie_decoder_convs))
        .collect::<Result<Vec<_>>>()?;
    Ok((enc, dec))
}

/// The pooling (level i → i + 1) and de-pooling (i + 1 → i) layers, as each operator says it
/// applies.
pub(super) fn pooling(
    hierarchy: &Hierarchy,
    n_levels: usize,
    device: &Device,
) -> Result<(Vec<Down>, Vec<Up>)> {
    let (mut down, mut up) = (Vec::new(), Vec::new());
    for op in &hierarchy.pooling[..n_levels - 1] {
        let (d, u) = match op.mode() {
            PoolMode::Mean => (
                Down::Mean(MeanPool::new(&op.pool, device)?),
                Up::DePool(DePool::new(&op.depool, device)?),
            ),
            PoolMode::SignedMax => (
                Down::Max(MaxPool::new(&op.pool, device)?),
                Up::DePool(DePool::new(&op.depool, device)?),
            ),
            // The plain max over each neighbourhood (the pooling matrix's rows), then the
            // mean over the neighbourhoods containing each fine vertex.
            PoolMode::Max => (
                Down::Max(MaxPool::with_mode(&op.pool, MaxMode::Plain, device)?),
                Up::DePool(DePool::new(&op.depool, device)?),
            ),
            PoolMode::Sampling => (
                Down::Sampling(Sampling::new(&op.pool, device)?),
                Up::Sampling(Sampling::new(&op.depool, device)?),
            ),
            PoolMode::Identity => (Down::Identity, Up::Identity),
        };
        down.push(d);
        up.push(u);
    }
    Ok((down, up))
}

/// The hierarchy must have the structure's pooling steps, built by the configured pooler.
pub(super) fn check_hierarchy(config: &ModelConfig, h: &Hierarchy) -> Result<()> {
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
