//! The candle layers [`MeshVae::with_dtype`](super::MeshVae::with_dtype) assembles from the
//! [`NetPlan`]: one stage per step (a convolution block on its variables, or a pooling layer
//! applied as the step's mode says).

use super::layers::{ConvBlock, Down, GraphConv, Stage, Up, Weights};
use crate::candle::batch_norm::BatchNorm;
use crate::error::Result;
use crate::net::config::ModelConfig;
use crate::net::plan::{ConvStep, ConvVars, NetPlan, PoolStep, Step};
use candle_core::{Device, Var};
use mesh_hierarchy::PoolMode;
use spectral_conv::{
    ChebConv, DePool, MaxMode, MaxPool, MeanPool, Sampling, SparseOp, SpatialConv, Workspace,
};
use std::sync::Arc;

/// The sparse operators of one of the plan's distinct convolution operators: A (L̃ for
/// spectral, D⁻¹A for spatial convolutions) and, when decoder convolutions are tied, Aᵀ.
struct Operator {
    op: SparseOp,
    op_t: Option<SparseOp>,
}

/// The encoder's and the decoder's stages, in the plan's order.
pub(super) fn stages(
    config: &ModelConfig,
    plan: &NetPlan,
    params: &[Var],
    state: &[Var],
    device: &Device,
) -> Result<(Vec<Stage>, Vec<Stage>)> {
    // One workspace for the kernels' scratch of every layer: its buffers serve the layers in
    // turn rather than each layer keeping its own.
    let ws = Arc::new(Workspace::new());
    let operators = plan
        .operators
        .iter()
        .map(|m| {
            let op = SparseOp::new(m, device)?.with_workspace(ws.clone());
            let op_t = if config.tie_decoder_convs {
                Some(op.transpose()?)
            } else {
                None
            };
            Ok(Operator { op, op_t })
        })
        .collect::<Result<Vec<_>>>()?;
    let stage = |step: &Step| -> Result<Stage> {
        Ok(match step {
            Step::Conv(c) => {
                let level = &operators[plan.levels[c.spec.level].operator];
                Stage::Conv(conv_block(config, c, level, params, state)?)
            }
            Step::Pool(p) if p.is_depool() => Stage::Up(up(p, device, &ws)?),
            Step::Pool(p) => Stage::Down(down(p, device, &ws)?),
        })
    };
    let enc = plan.encoder.iter().map(stage).collect::<Result<Vec<_>>>()?;
    let dec = plan.decoder.iter().map(stage).collect::<Result<Vec<_>>>()?;
    Ok((enc, dec))
}

/// A convolution block (convolution, batch norm) on its variables.
fn conv_block(
    config: &ModelConfig,
    step: &ConvStep,
    level: &Operator,
    params: &[Var],
    state: &[Var],
) -> Result<ConvBlock> {
    let w = |id: crate::net::vars::ParamId| params[id.0].as_tensor().clone();
    let weights = match step.weights {
        ConvVars::Cheb(id) => Weights::Own(GraphConv::Cheb(ChebConv::from_weights(
            level.op.clone(),
            config.k,
            w(id),
            None,
        )?)),
        ConvVars::Spatial { w_self, w_nb } => Weights::Own(GraphConv::Spatial(
            SpatialConv::from_weights(level.op.clone(), w(w_self), w(w_nb), None)?,
        )),
        ConvVars::Tied => Weights::Tied(level.op_t.clone().ok_or_else(|| {
            crate::error::VaeError::shape(
                "MeshVae::new",
                "internal: a tied convolution without the transposed operator",
            )
        })?),
    };
    let bn = step
        .bn
        .map(|b| {
            BatchNorm::new(
                params[b.gamma.0].clone(),
                params[b.beta.0].clone(),
                state[b.running_mean.0].clone(),
                state[b.running_var.0].clone(),
            )
        })
        .transpose()?;
    Ok(ConvBlock {
        spec: step.spec,
        weights,
        bn,
    })
}

/// Pooling from level i to level i + 1, as the step's mode applies.
fn down(step: &PoolStep, device: &Device, ws: &Arc<Workspace>) -> Result<Down> {
    let m = &step.matrix;
    Ok(match step.mode {
        PoolMode::Mean => Down::Mean(MeanPool::new(m, device)?.with_workspace(ws.clone())),
        PoolMode::SignedMax => Down::Max(MaxPool::new(m, device)?),
        // The plain max over each neighbourhood (the pooling matrix's rows).
        PoolMode::PlainMax => Down::Max(MaxPool::with_mode(m, MaxMode::PlainMax, device)?),
        PoolMode::Sampling => Down::Sampling(Sampling::new(m, device)?.with_workspace(ws.clone())),
        PoolMode::Identity => Down::Identity,
    })
}

/// De-pooling from level i + 1 back to level i: the de-pooling matrix's product (for the max
/// poolings the mean over the neighbourhoods containing each fine vertex).
fn up(step: &PoolStep, device: &Device, ws: &Arc<Workspace>) -> Result<Up> {
    let m = &step.matrix;
    let ws = ws.clone();
    Ok(match step.mode {
        PoolMode::Mean | PoolMode::SignedMax | PoolMode::PlainMax => {
            Up::DePool(DePool::new(m, device)?.with_workspace(ws))
        }
        PoolMode::Sampling => Up::Sampling(Sampling::new(m, device)?.with_workspace(ws)),
        PoolMode::Identity => Up::Identity,
    })
}
