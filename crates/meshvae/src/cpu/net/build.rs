//! Building the engine's network from a model's plan: its layer list and buffers.

use super::conv_weight::Adjoint;
use super::{
    Acts, Bn, Conv, ConvWeight, DenseVars, LabelVars, Latent, Net, Node, Pool, PoolOp, internal,
};
use crate::candle::model::MeshVae;
use crate::cpu::{Real, of};
use crate::error::{Result, VaeError};
use crate::net::config::FEATURE_CHANNELS;
use crate::net::plan::{ConvStep, ConvVars, PoolStep, Step};
use candle_core::Var;
use mesh_hierarchy::PoolMode;
use spectral_conv::{ChebKernel, MaxKernel, MaxMode, SparseKernel, Workspace};
use std::sync::Arc;

/// When level 0 is renumbered: more than this share of its neighbours lie more than
/// [`FAR_WINDOW`] positions apart. 1,024 vertex blocks (1.2 MB at B = 32, C = 9) is beyond the
/// L2 cache. In unit tests the window is 16, so that the small test meshes are renumbered and
/// the comparisons with candle cover the renumbering.
const FAR_SHARE: f64 = 0.1;
const FAR_WINDOW: usize = if cfg!(test) { 16 } else { 1024 };

impl<T: Real> Net<T> {
    /// The network of `model` with buffers for batches of up to `max_batch`.
    pub fn build(model: &MeshVae, max_batch: usize) -> Result<Self> {
        let plan = model.plan().ok_or_else(|| {
            VaeError::argument("model", "the CPU engine runs the paper's network only")
        })?;
        let (names, vars): (Vec<String>, Vec<Var>) = model.trainable_vars().into_iter().unzip();
        let state: Vec<Var> = model.state_vars().into_iter().map(|(_, v)| v).collect();
        let mut grads: Vec<Vec<T>> = vars.iter().map(|v| vec![of(0.0); v.elem_count()]).collect();
        let counts = plan.vertex_counts();
        let config = model.config();
        let mut acts = Acts(Vec::new());
        let ws = Arc::new(Workspace::new());
        let mut max_act = 0;
        let mut add = |acts: &mut Acts<T>, v: usize, c: usize| {
            max_act = max_act.max(v * c * max_batch);
            acts.add(v * c * max_batch)
        };
        let x_buf = add(&mut acts, counts[0], FEATURE_CHANNELS);
        // Where the template's own numbering scatters neighbours (elephant-gallop: 44 % of its
        // edges join vertices more than 1,024 positions apart; horse-gallop 2 %, samba 4 %), the
        // full-resolution level runs renumbered in reverse Cuthill–McKee order, so that the
        // gathers find neighbours' blocks close by (ChebConv fwd+bwd on elephant-gallop:
        // 82.6 → 69.6 ms). The input transpose applies the order and the pooling operator
        // undoes it, so nothing outside the engine sees it. Only where level 0 is left through
        // a sparse pooling operator (max pooling keeps the order; without pooling the dense
        // layer reads level 0). On horse-gallop, whose order is local, renumbering was 3 %
        // slower.
        let order = match plan.first_pool().map(|p| p.mode) {
            Some(PoolMode::Mean | PoolMode::Sampling) => {
                let level0 = ChebKernel::from_matrix(plan.operator(0), 1)?;
                (level0.far_share(FAR_WINDOW) > FAR_SHARE).then(|| level0.locality_order())
            }
            _ => None,
        };
        let at_level = |level: usize| order.as_deref().filter(|_| level == 0);

        let conv = |acts: &mut Acts<T>,
                    add: &mut dyn FnMut(&mut Acts<T>, usize, usize) -> usize,
                    step: &ConvStep,
                    input: usize,
                    need_dx: bool|
         -> Result<Node> {
            let s = step.spec;
            let v = counts[s.level];
            // The level's operator is L̃ for spectral and D⁻¹A for spatial convolutions; a tied
            // decoder convolution runs on its transpose.
            let own = |vars: ConvVars| match vars {
                ConvVars::Cheb(w) => Some((config.k, ConvWeight::Stacked(w.0))),
                ConvVars::Spatial { w_self, w_nb } => Some((
                    2,
                    ConvWeight::Pair {
                        w_self: w_self.0,
                        w_nb: w_nb.0,
                    },
                )),
                ConvVars::Tied => None,
            };
            let operator = plan.operator(s.level);
            let (weight, mut kernel) = match own(step.weights) {
                Some((k, weight)) => (weight, ChebKernel::from_matrix(operator, k)?),
                None => {
                    let mirror = plan.encoder.iter().find_map(|e| match e {
                        Step::Conv(c) if c.spec.index == s.index => own(c.weights),
                        _ => None,
                    });
                    let adjoint = match mirror {
                        Some((k, ConvWeight::Stacked(w))) => Adjoint::Cheb { w, k },
                        Some((_, ConvWeight::Pair { w_self, w_nb })) => {
                            Adjoint::Spatial { w_self, w_nb }
                        }
                        _ => return Err(internal("a tied convolution without its encoder's")),
                    };
                    let k = mirror.map_or(0, |(k, _)| k);
                    let kernel = ChebKernel::from_matrix(&operator.transpose(), k)?;
                    (ConvWeight::Adjoint(adjoint), kernel)
                }
            };
            // With tied decoder convolutions every encoder convolution's weights are shared.
            let add_grad = config.tie_decoder_convs && step.weights != ConvVars::Tied;
            if let Some(order) = at_level(s.level) {
                kernel = kernel.permuted(order)?;
            }
            let terms = acts.add(kernel.terms_len(max_batch, s.c_in));
            let pre = add(acts, v, s.c_out);
            let bn = step.bn.map(|b| Bn {
                gamma: b.gamma.0,
                beta: b.beta.0,
                running_mean: state[b.running_mean.0].clone(),
                running_var: state[b.running_var.0].clone(),
                mean: Vec::new(),
                var: Vec::new(),
                inv_std: Vec::new(),
            });
            let out = if bn.is_some() {
                add(acts, v, s.c_out)
            } else {
                pre
            };
            Ok(Node::Conv(Conv {
                kernel,
                ws: ws.clone(),
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
        };
        // A pooling step's operator: the sparse product, or the max over each row's columns
        // (recording the selection for the backward pass). At level 0 the sparse operators are
        // renumbered like the convolutions there.
        let pool = |acts: &mut Acts<T>,
                    add: &mut dyn FnMut(&mut Acts<T>, usize, usize) -> usize,
                    step: &PoolStep,
                    c: usize,
                    input: usize|
         -> Result<Node> {
            let (v_in, v_out) = (counts[step.from], counts[step.to]);
            let (rows, cols) = (at_level(step.to), at_level(step.from));
            let sparse = || -> Result<PoolOp> {
                Ok(PoolOp::Sparse(
                    SparseKernel::from_matrix(&step.matrix)?.permuted(rows, cols)?,
                ))
            };
            let max = |mode: MaxMode| -> Result<PoolOp> {
                let pool = MaxKernel::from_matrix(&step.matrix, mode)?;
                Ok(PoolOp::Max(pool, vec![0; v_out * c * max_batch]))
            };
            let op = match (step.mode, step.is_depool()) {
                (PoolMode::Identity, _) => PoolOp::Identity,
                (_, true) | (PoolMode::Mean | PoolMode::Sampling, false) => sparse()?,
                (PoolMode::SignedMax, false) => max(MaxMode::SignedMax)?,
                (PoolMode::PlainMax, false) => max(MaxMode::PlainMax)?,
            };
            let out = match op {
                PoolOp::Identity => input,
                _ => add(acts, v_out, c),
            };
            Ok(Node::Pool(Pool {
                op,
                v_in,
                v_out,
                c,
                input,
                out,
            }))
        };

        let (mut enc, mut dec) = (Vec::new(), Vec::new());
        let (mut cur, mut channels) = (x_buf, FEATURE_CHANNELS);
        for step in &plan.encoder {
            let node = match step {
                Step::Conv(c) => {
                    channels = c.spec.c_out;
                    conv(&mut acts, &mut add, c, cur, !enc.is_empty())?
                }
                Step::Pool(p) => pool(&mut acts, &mut add, p, channels, cur)?,
            };
            cur = node.out();
            enc.push(node);
        }
        let enc_out = cur;
        let coarse = counts[counts.len() - 1];
        let flat = coarse * channels;
        let dec_in = add(&mut acts, coarse, channels);
        cur = dec_in;
        for step in &plan.decoder {
            let node = match step {
                Step::Conv(c) => {
                    channels = c.spec.c_out;
                    conv(&mut acts, &mut add, c, cur, true)?
                }
                Step::Pool(p) => pool(&mut acts, &mut add, p, channels, cur)?,
            };
            cur = node.out();
            dec.push(node);
        }
        if channels != FEATURE_CHANNELS {
            return Err(internal(
                "the decoder does not end on the template's features",
            ));
        }
        let x_hat = cur;
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
        Ok(Self {
            names,
            vars,
            grads,
            max_batch,
            v0: counts[0],
            latent: l,
            flat,
            enc,
            dec,
            dense,
            acts,
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
            order,
            cond: vec![of(0.0); max_batch * config.labels.len()],
        })
    }
}
