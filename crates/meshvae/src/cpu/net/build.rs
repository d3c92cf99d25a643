//! Building the engine's network from a model: its layer list and buffers.

use super::{Acts, Bn, Conv, ConvWeight, DenseVars, Latent, Net, Node, Pool, PoolOp, internal};
use crate::candle::model::MeshVae;
use crate::candle::model::layers::{ConvBlock, Down, Up};
use crate::candle::model::vars;
use crate::cpu::{Scalar, of};
use crate::error::Result;
use crate::net::config::{ConvKind, FEATURE_CHANNELS};
use crate::net::structure::Layer;
use candle_core::Var;
use spectral_conv::{ChebKernel, SparseKernel};

/// When level 0 is renumbered: more than this share of its neighbours lie more than
/// [`FAR_WINDOW`] positions apart. 1,024 vertex blocks (1.2 MB at B = 32, C = 9) is beyond the
/// L2 cache. In unit tests the window is 16, so that the small test meshes are renumbered and
/// the comparisons with candle cover the renumbering.
const FAR_SHARE: f64 = 0.1;
const FAR_WINDOW: usize = if cfg!(test) { 16 } else { 1024 };

impl<T: Scalar> Net<T> {
    /// The network of `model` with buffers for batches of up to `max_batch`.
    pub fn build(model: &MeshVae, max_batch: usize) -> Result<Self> {
        let (names, vars): (Vec<String>, Vec<Var>) = model.trainable_vars().into_iter().unzip();
        let index = |name: &str| -> Result<usize> {
            names
                .iter()
                .position(|n| n == name)
                .ok_or_else(|| internal(format!("no variable {name}")))
        };
        let state = model.state_vars();
        let state_var = |name: &str| -> Result<Var> {
            state
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, v)| v.clone())
                .ok_or_else(|| internal(format!("no state variable {name}")))
        };
        let mut grads: Vec<Vec<T>> = vars.iter().map(|v| vec![of(0.0); v.elem_count()]).collect();
        let counts = model.vertex_counts().to_vec();
        let config = model.config();
        let mut acts = Acts(Vec::new());
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
        let order = match (model.down.first(), model.up.first()) {
            (Some(Down::Mean(_) | Down::Sampling(_)), Some(Up::DePool(_) | Up::Sampling(_))) => {
                let level0 = ChebKernel::new(&model.levels[0].op, 1)?;
                (level0.far_share(FAR_WINDOW) > FAR_SHARE).then(|| level0.locality_order())
            }
            _ => None,
        };
        let at_level = |level: usize| order.as_deref().filter(|_| level == 0);

        let conv = |acts: &mut Acts<T>,
                    add: &mut dyn FnMut(&mut Acts<T>, usize, usize) -> usize,
                    side: &str,
                    block: &ConvBlock,
                    input: usize,
                    need_dx: bool|
         -> Result<Node> {
            let s = block.spec;
            let v = counts[s.level];
            // The level's operator is L̃ for spectral and D⁻¹A for spatial convolutions. The
            // variables' names come from the model's own naming (`vars`), never spelled here.
            let names = vars::conv_weight_names(side, config.conv, s.index);
            let (kernel_k, weight) = match config.conv {
                ConvKind::Spectral => (config.k, ConvWeight::Stacked(index(&names[0])?)),
                ConvKind::Spatial => (
                    2,
                    ConvWeight::Pair {
                        w_self: index(&names[0])?,
                        w_nb: index(&names[1])?,
                    },
                ),
            };
            let mut kernel = ChebKernel::new(&model.levels[s.level].op, kernel_k)?;
            if let Some(order) = at_level(s.level) {
                kernel = kernel.permuted(order)?;
            }
            let terms = acts.add(kernel.terms_len(max_batch, s.c_in));
            let pre = add(acts, v, s.c_out);
            let bn = if s.batch_norm {
                let [gamma, beta, running_mean, running_var] = vars::bn_names(side, s.index);
                Some(Bn {
                    gamma: index(&gamma)?,
                    beta: index(&beta)?,
                    running_mean: state_var(&running_mean)?,
                    running_var: state_var(&running_var)?,
                    mean: Vec::new(),
                    var: Vec::new(),
                    inv_std: Vec::new(),
                })
            } else {
                None
            };
            let out = if bn.is_some() {
                add(acts, v, s.c_out)
            } else {
                pre
            };
            Ok(Node::Conv(Conv {
                kernel,
                v,
                ci: s.c_in,
                co: s.c_out,
                weight,
                bn,
                tanh: s.tanh,
                input,
                terms,
                pre,
                out,
                need_dx,
            }))
        };

        let layers = config.structure.layers();
        let (mut enc, mut dec) = (Vec::new(), Vec::new());
        let (mut level, mut cur, mut channels) = (0, x_buf, FEATURE_CHANNELS);
        let mut blocks = model.enc.iter();
        for layer in layers.iter() {
            match layer {
                Layer::Conv => {
                    let block = blocks.next().ok_or_else(|| internal("encoder plan"))?;
                    let node = conv(&mut acts, &mut add, "enc", block, cur, !enc.is_empty())?;
                    channels = block.spec.c_out;
                    cur = node.out();
                    enc.push(node);
                }
                Layer::Pool => {
                    let (v_in, v_out) = (counts[level], counts[level + 1]);
                    let fine = at_level(level);
                    let (op, out) = match &model.down[level] {
                        Down::Identity => (PoolOp::Identity, cur),
                        Down::Mean(p) => (
                            PoolOp::Sparse(SparseKernel::new(p.op()).permuted(None, fine)?),
                            add(&mut acts, v_out, channels),
                        ),
                        Down::Sampling(p) => (
                            PoolOp::Sparse(SparseKernel::new(p.op()).permuted(None, fine)?),
                            add(&mut acts, v_out, channels),
                        ),
                        Down::Max(p) => (
                            PoolOp::Max(p.clone(), vec![0; v_out * channels * max_batch]),
                            add(&mut acts, v_out, channels),
                        ),
                    };
                    enc.push(Node::Pool(Pool {
                        op,
                        v_in,
                        v_out,
                        c: channels,
                        input: cur,
                        out,
                    }));
                    cur = out;
                    level += 1;
                }
            }
        }
        let enc_out = cur;
        let coarse = counts[level];
        let flat = coarse * channels;
        let dec_in = add(&mut acts, coarse, channels);
        cur = dec_in;
        let mut blocks = model.dec.iter();
        for layer in layers.iter().rev() {
            match layer {
                Layer::Conv => {
                    let block = blocks.next().ok_or_else(|| internal("decoder plan"))?;
                    let node = conv(&mut acts, &mut add, "dec", block, cur, true)?;
                    channels = block.spec.c_out;
                    cur = node.out();
                    dec.push(node);
                }
                Layer::Pool => {
                    level -= 1;
                    let (v_in, v_out) = (counts[level + 1], counts[level]);
                    let fine = at_level(level);
                    let (op, out) = match &model.up[level] {
                        Up::Identity => (PoolOp::Identity, cur),
                        Up::DePool(p) => (
                            PoolOp::Sparse(SparseKernel::new(p.op()).permuted(fine, None)?),
                            add(&mut acts, v_out, channels),
                        ),
                        Up::Sampling(p) => (
                            PoolOp::Sparse(SparseKernel::new(p.op()).permuted(fine, None)?),
                            add(&mut acts, v_out, channels),
                        ),
                    };
                    dec.push(Node::Pool(Pool {
                        op,
                        v_in,
                        v_out,
                        c: channels,
                        input: cur,
                        out,
                    }));
                    cur = out;
                }
            }
        }
        if channels != FEATURE_CHANNELS || level != 0 {
            return Err(internal(
                "the decoder does not end on the template's features",
            ));
        }
        let x_hat = cur;
        let l = config.latent;
        let lat_buf = || vec![of(0.0); max_batch * l];
        let dense = DenseVars {
            w_mu: index("enc.mu.weight")?,
            b_mu: index("enc.mu.bias")?,
            w_sigma: index("enc.sigma.weight")?,
            b_sigma: index("enc.sigma.bias")?,
            b_dec: index("dec.fc.bias")?,
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
            work: vec![of(0.0); max_act],
            batch: 0,
            order,
        })
    }
}
