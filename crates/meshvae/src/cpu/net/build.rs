//! Building the engine's network from a model's plan: its layer list and buffers.

use super::conv_weight::Adjoint;
use super::{
    Acts, Bn, Conv, ConvWeight, DenseVars, LabelVars, Latent, Net, Node, Pool, PoolOp, internal,
};
use crate::cpu::model::EngineModel;
use crate::cpu::{Real, of};
use crate::error::{Result, VaeError};
use crate::net::config::FEATURE_CHANNELS;
use crate::net::config::ModelConfig;
use crate::net::plan::{ConvStep, ConvVars, NetPlan, PoolStep, Step};
use mesh_hierarchy::PoolMode;
use spectral_conv::{ChebKernel, MaxKernel, MaxMode, SparseKernel, Workspace};
use std::sync::Arc;

/// When level 0 is renumbered: more than this share of its neighbours lie more than
/// [`FAR_WINDOW`] positions apart. 1,024 vertex blocks (1.2 MB at B = 32, C = 9) is beyond the
/// L2 cache. In unit tests the window is 16, so that the small test meshes are renumbered and
/// the comparisons with candle cover the renumbering.
const FAR_SHARE: f64 = 0.1;
const FAR_WINDOW: usize = if cfg!(test) { 16 } else { 1024 };

/// What building the network needs at every layer: the plan's levels and operators, the
/// buffers allocated so far and the largest activation.
struct Builder<'a, T: Real> {
    plan: &'a NetPlan,
    config: &'a ModelConfig,
    counts: Vec<usize>,
    max_batch: usize,
    acts: Acts<T>,
    max_act: usize,
    ws: Arc<Workspace>,
    /// Level 0's renumbering, where it runs renumbered.
    order: Option<Vec<u32>>,
}

impl<T: Real> Builder<'_, T> {
    /// A new activation buffer of `v` vertices × `c` channels × the batch.
    fn add(&mut self, v: usize, c: usize) -> usize {
        self.max_act = self.max_act.max(v * c * self.max_batch);
        self.acts.add(v * c * self.max_batch)
    }

    /// Level 0's order where `level` is 0 and it runs renumbered.
    fn order_at(&self, level: usize) -> Option<&[u32]> {
        self.order.as_deref().filter(|_| level == 0)
    }

    /// The orders K and the weight layout of a convolution with its own weights.
    fn own(&self, vars: ConvVars) -> Option<(usize, ConvWeight)> {
        match vars {
            ConvVars::Cheb(w) => Some((self.config.k, ConvWeight::Stacked(w.0))),
            ConvVars::Spatial { w_self, w_nb } => Some((
                2,
                ConvWeight::Pair {
                    w_self: w_self.0,
                    w_nb: w_nb.0,
                },
            )),
            ConvVars::Tied => None,
        }
    }

    /// A convolution's weights and kernel: the level's operator (L̃ for spectral, D⁻¹A for
    /// spatial convolutions), or for a tied decoder convolution its transpose with the adjoint
    /// of the mirror encoder convolution's weights.
    fn conv_kernel(&self, step: &ConvStep) -> Result<(ConvWeight, ChebKernel)> {
        let s = step.spec;
        let operator = self.plan.operator(s.level);
        if let Some((k, weight)) = self.own(step.weights) {
            return Ok((weight, ChebKernel::from_matrix(operator, k)?));
        }
        let mirror = self.plan.encoder.iter().find_map(|e| match e {
            Step::Conv(c) if c.spec.index == s.index => self.own(c.weights),
            _ => None,
        });
        let adjoint = match mirror {
            Some((k, ConvWeight::Stacked(w))) => Adjoint::Cheb { w, k },
            Some((_, ConvWeight::Pair { w_self, w_nb })) => Adjoint::Spatial { w_self, w_nb },
            _ => return Err(internal("a tied convolution without its encoder's")),
        };
        let k = mirror.map_or(0, |(k, _)| k);
        let kernel = ChebKernel::from_matrix(&operator.transpose(), k)?;
        Ok((ConvWeight::Adjoint(adjoint), kernel))
    }

    /// A convolution node (with its batch norm) reading buffer `input`.
    fn conv(&mut self, step: &ConvStep, input: usize, need_dx: bool) -> Result<Node> {
        let s = step.spec;
        let v = self.counts[s.level];
        let (weight, mut kernel) = self.conv_kernel(step)?;
        // With tied decoder convolutions every encoder convolution's weights are shared.
        let add_grad = self.config.tie_decoder_convs && step.weights != ConvVars::Tied;
        if let Some(order) = self.order_at(s.level) {
            kernel = kernel.permuted(order)?;
        }
        let terms = self.acts.add(kernel.terms_len(self.max_batch, s.c_in));
        let pre = self.add(v, s.c_out);
        let bn = step.bn.map(|b| Bn {
            gamma: b.gamma.0,
            beta: b.beta.0,
            running_mean: b.running_mean.0,
            running_var: b.running_var.0,
            mean: Vec::new(),
            var: Vec::new(),
            inv_std: Vec::new(),
            running: (Vec::new(), Vec::new()),
        });
        let out = if bn.is_some() {
            self.add(v, s.c_out)
        } else {
            pre
        };
        Ok(Node::Conv(Conv {
            kernel,
            ws: self.ws.clone(),
            v,
            ci: s.c_in,
            co: s.c_out,
            weight,
            add_grad,
            bn,
            tanh: s.tanh,
            input,
            terms,
            pre,
            out,
            need_dx,
        }))
    }

    /// A pooling step's node: the sparse product, or the max over each row's columns
    /// (recording the selection for the backward pass). At level 0 the sparse operators are
    /// renumbered like the convolutions there.
    fn pool(&mut self, step: &PoolStep, c: usize, input: usize) -> Result<Node> {
        let (v_in, v_out) = (self.counts[step.from], self.counts[step.to]);
        let (rows, cols) = (self.order_at(step.to), self.order_at(step.from));
        let max = |mode: MaxMode| -> Result<PoolOp> {
            let pool = MaxKernel::from_matrix(&step.matrix, mode)?;
            Ok(PoolOp::Max(pool, vec![0; v_out * c * self.max_batch]))
        };
        let op = match (step.mode, step.is_depool()) {
            (PoolMode::Identity, _) => PoolOp::Identity,
            (_, true) | (PoolMode::Mean | PoolMode::Sampling, false) => {
                PoolOp::Sparse(SparseKernel::from_matrix(&step.matrix)?.permuted(rows, cols)?)
            }
            (PoolMode::SignedMax, false) => max(MaxMode::SignedMax)?,
            (PoolMode::PlainMax, false) => max(MaxMode::PlainMax)?,
        };
        let out = match op {
            PoolOp::Identity => input,
            _ => self.add(v_out, c),
        };
        Ok(Node::Pool(Pool {
            op,
            v_in,
            v_out,
            c,
            input,
            out,
        }))
    }

    /// The nodes of `steps` from buffer `input` of `channels` channels; the first convolution
    /// needs no input gradient where `first_needs_dx` is false (the encoder's, on the data).
    fn nodes(
        &mut self,
        steps: &[Step],
        mut input: usize,
        mut channels: usize,
        first_needs_dx: bool,
    ) -> Result<(Vec<Node>, usize, usize)> {
        let mut nodes: Vec<Node> = Vec::new();
        for step in steps {
            let node = match step {
                Step::Conv(c) => {
                    channels = c.spec.c_out;
                    let need_dx = first_needs_dx || !nodes.is_empty();
                    self.conv(c, input, need_dx)?
                }
                Step::Pool(p) => self.pool(p, channels, input)?,
            };
            input = node.out();
            nodes.push(node);
        }
        Ok((nodes, input, channels))
    }
}

/// Where the template's own numbering scatters neighbours (elephant-gallop: 44 % of its edges
/// join vertices more than 1,024 positions apart; horse-gallop 2 %, samba 4 %), the
/// full-resolution level runs renumbered in reverse Cuthill–McKee order, so that the gathers
/// find neighbours' blocks close by (ChebConv fwd+bwd on elephant-gallop: 82.6 → 69.6 ms). The
/// input transpose applies the order and the pooling operator undoes it, so nothing outside the
/// engine sees it. Only where level 0 is left through a sparse pooling operator (max pooling
/// keeps the order; without pooling the dense layer reads level 0). On horse-gallop, whose
/// order is local, renumbering was 3 % slower.
fn level0_order(plan: &NetPlan) -> Result<Option<Vec<u32>>> {
    Ok(match plan.first_pool().map(|p| p.mode) {
        Some(PoolMode::Mean | PoolMode::Sampling) => {
            let level0 = ChebKernel::from_matrix(plan.operator(0), 1)?;
            (level0.far_share(FAR_WINDOW) > FAR_SHARE).then(|| level0.locality_order())
        }
        _ => None,
    })
}

impl<T: Real> Net<T> {
    /// The network of `model` with buffers for batches of up to `max_batch`.
    pub fn build(model: &dyn EngineModel, max_batch: usize) -> Result<Self> {
        let plan = model.plan().ok_or_else(|| {
            VaeError::argument("model", "the CPU engine runs the paper's network only")
        })?;
        let (names, lens): (Vec<String>, Vec<usize>) = model.trainable().into_iter().unzip();
        let mut grads: Vec<Vec<T>> = lens.iter().map(|&n| vec![of(0.0); n]).collect();
        let config = model.config();
        let mut b = Builder {
            plan,
            config,
            counts: plan.vertex_counts(),
            max_batch,
            acts: Acts(Vec::new()),
            max_act: 0,
            ws: Arc::new(Workspace::new()),
            order: level0_order(plan)?,
        };
        let counts = b.counts.clone();
        let x_buf = b.add(counts[0], FEATURE_CHANNELS);
        let (enc, enc_out, channels) = b.nodes(&plan.encoder, x_buf, FEATURE_CHANNELS, false)?;
        let coarse = counts[counts.len() - 1];
        let flat = coarse * channels;
        let dec_in = b.add(coarse, channels);
        let (dec, x_hat, channels) = b.nodes(&plan.decoder, dec_in, channels, true)?;
        if channels != FEATURE_CHANNELS {
            return Err(internal(
                "the decoder does not end on the template's features",
            ));
        }
        let work_len = (enc.iter().chain(&dec))
            .filter_map(|node| match node {
                Node::Conv(c) => Some(c.kernel.work_len(max_batch, c.ci)),
                Node::Pool(_) => None,
            })
            .max()
            .unwrap_or(0);
        let l = config.latent;
        let lat_buf = || vec![of(0.0); max_batch * l];
        let heads = plan.heads;
        let dense = DenseVars {
            w_mu: heads.w_mu.0,
            b_mu: heads.b_mu.0,
            w_sigma: heads.w_sigma.0,
            b_sigma: heads.b_sigma.0,
            b_dec: heads.b_dec.0,
            labels: heads.labels.map(|ids| LabelVars {
                mu: ids.mu.0,
                sigma: ids.sigma.0,
                dec: ids.dec.0,
                count: config.labels.len(),
            }),
        };
        // The dense weights' gradients are made block by block inside Adam's pass
        // (`Net::dense_grad_rows`), never whole.
        grads[dense.w_mu] = Vec::new();
        grads[dense.w_sigma] = Vec::new();
        let max_act = b.max_act;
        Ok(Self {
            names,
            var_ids: model.var_ids(),
            lens,
            grads,
            max_batch,
            v0: counts[0],
            latent: l,
            flat,
            enc,
            dec,
            dense,
            acts: b.acts,
            x_buf,
            enc_out,
            dec_in,
            x_hat,
            lat: Latent {
                mu: lat_buf(),
                sig: lat_buf(),
                sigma: lat_buf(),
                z: lat_buf(),
                eps: lat_buf(),
                dz: lat_buf(),
                dmu: lat_buf(),
                ds: lat_buf(),
            },
            dec_grad: vec![of(0.0); flat * max_batch],
            ga: vec![of(0.0); max_act],
            gb: vec![of(0.0); max_act],
            // The convolutions' Clenshaw buffers (K − 2 blocks), or an activation's size.
            work: vec![of(0.0); work_len.max(max_act)],
            batch: 0,
            order: b.order,
            cond: vec![of(0.0); max_batch * config.labels.len()],
        })
    }
}
