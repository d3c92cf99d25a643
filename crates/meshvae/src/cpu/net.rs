//! The engine's network: its layer list, buffers, forward and backward passes (see `mod.rs`).

use super::kernels as k;
use super::{Real, StepLoss, f64_of, of};
use crate::candle::model::MeshVae;
use crate::error::{Result, VaeError};
use crate::net::batch_norm as bn;
use crate::net::config::FEATURE_CHANNELS;
use crate::net::loss_weights::LossWeights;
use crate::optim::adam::{Adam, GradSource};
use candle_core::{Layout, Storage, Tensor, Var};
use spectral_conv::{ChebKernel, MaxKernel, SparseKernel, Workspace};
use std::sync::Arc;

mod build;
mod conv_weight;
mod infer;
mod latent;
mod node;

use conv_weight::ConvWeight;
use node::{BnStats, backward_node, forward_node};

/// A batch norm's variables (indices into the trainable list) and its last batch statistics.
#[derive(Debug)]
struct Bn {
    gamma: usize,
    beta: usize,
    running_mean: Var,
    running_var: Var,
    mean: Vec<f64>,
    var: Vec<f64>,
    inv_std: Vec<f64>,
}

impl Bn {
    /// The running mean and variance, as inference normalises with them.
    fn running_stats(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        let read = |v: &Var| -> Result<Vec<f64>> {
            Ok(v.as_tensor().to_dtype(candle_core::DType::F64)?.to_vec1()?)
        };
        Ok((read(&self.running_mean)?, read(&self.running_var)?))
    }
}

/// conv → [batch norm] → [tanh]. Buffers are indices into [`Acts`]; `pre` (the convolution's
/// output) equals `out` without batch norm (tanh then runs in place).
#[derive(Debug)]
struct Conv {
    kernel: ChebKernel,
    /// The kernels' staging buffers: one workspace for all of the network's convolutions.
    ws: Arc<Workspace>,
    v: usize,
    ci: usize,
    co: usize,
    weight: ConvWeight,
    /// Add the weight gradient to the variables' (an encoder convolution a tied decoder
    /// convolution shares) instead of writing it.
    add_grad: bool,
    bn: Option<Bn>,
    tanh: bool,
    input: usize,
    terms: usize,
    pre: usize,
    out: usize,
    /// The gradient at the input is wanted (not for the network's input data).
    need_dx: bool,
}

#[derive(Debug)]
enum PoolOp {
    Sparse(SparseKernel),
    Max(MaxKernel, Vec<u32>),
    Identity,
}

/// A pooling or de-pooling step `[v_in, c, B]` → `[v_out, c, B]`.
#[derive(Debug)]
struct Pool {
    op: PoolOp,
    v_in: usize,
    v_out: usize,
    c: usize,
    input: usize,
    out: usize,
}

#[derive(Debug)]
enum Node {
    Conv(Conv),
    Pool(Pool),
}

impl Node {
    fn out(&self) -> usize {
        match self {
            Node::Conv(c) => c.out,
            Node::Pool(p) => p.out,
        }
    }
}

/// The dense layers' variables (indices into the trainable list).
#[derive(Debug)]
struct DenseVars {
    w_mu: usize,
    b_mu: usize,
    w_sigma: usize,
    b_sigma: usize,
    b_dec: usize,
    /// A conditional model's label weights.
    labels: Option<LabelVars>,
}

/// A conditional model's label weights (indices into the trainable list): `[L, latent]` into
/// μ and into σ's pre-activation, `[L, V_L·C]` into the decoder's dense layer.
#[derive(Debug, Clone, Copy)]
struct LabelVars {
    mu: usize,
    sigma: usize,
    dec: usize,
    /// L, the number of labels.
    count: usize,
}

/// One batch handed to the network: features x `[B, V, 9]` and, exactly when the model is
/// conditional, one-hot labels c `[B, L]`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Inputs<'a> {
    pub x: &'a Tensor,
    pub c: Option<&'a Tensor>,
}

/// Activation buffers, each sized for the largest batch.
#[derive(Debug)]
struct Acts<T>(Vec<Vec<T>>);

impl<T: Real> Acts<T> {
    fn add(&mut self, len: usize) -> usize {
        self.0.push(vec![of(0.0); len]);
        self.0.len() - 1
    }

    /// Buffer `i` moved out (put it back with [`Self::put`]), so that others can be borrowed.
    fn take(&mut self, i: usize) -> Vec<T> {
        std::mem::take(&mut self.0[i])
    }

    fn put(&mut self, i: usize, v: Vec<T>) {
        self.0[i] = v;
    }
}

/// The latent side, `[B, latent]` row-major each.
#[derive(Debug)]
struct Latent<T> {
    mu: Vec<T>,
    sig: Vec<T>,
    sigma: Vec<T>,
    z: Vec<T>,
    eps: Vec<T>,
    dz: Vec<T>,
    dmu: Vec<T>,
    ds: Vec<T>,
}

/// The network for one float type.
#[derive(Debug)]
pub(super) struct Net<T> {
    names: Vec<String>,
    vars: Vec<Var>,
    grads: Vec<Vec<T>>,
    max_batch: usize,
    v0: usize,
    latent: usize,
    /// V_L · C: the flattened coarse features.
    flat: usize,
    enc: Vec<Node>,
    dec: Vec<Node>,
    dense: DenseVars,
    acts: Acts<T>,
    x_buf: usize,
    enc_out: usize,
    dec_in: usize,
    x_hat: usize,
    lat: Latent<T>,
    /// ∂L/∂(the decoder's dense output) `[V_L·C, B]`, kept for the dense weights' gradient.
    dec_grad: Vec<T>,
    /// Gradient ping-pong buffers and the convolutions' backward work buffer.
    ga: Vec<T>,
    gb: Vec<T>,
    work: Vec<T>,
    /// Batch size of the last step (0: no step yet).
    batch: usize,
    /// The full-resolution vertices' order in the engine's buffers (`order[p]`: the template
    /// vertex at position p), when they are renumbered for locality (see `build.rs`).
    order: Option<Vec<u32>>,
    /// The batch's one-hot labels `[B, L]` (conditional models).
    cond: Vec<T>,
}

fn internal(what: impl Into<String>) -> VaeError {
    VaeError::shape("Engine", what.into())
}

/// The contiguous data of a CPU storage of type `T`.
fn cpu_slice<'a, T: Real>(s: &'a Storage, l: &Layout, what: &str) -> Result<&'a [T]> {
    let Storage::Cpu(cpu) = s else {
        return Err(internal(format!("{what} is not on the CPU")));
    };
    let data = T::cpu(cpu).ok_or_else(|| internal(format!("{what} has another dtype")))?;
    let (lo, hi) = l
        .contiguous_offsets()
        .ok_or_else(|| internal(format!("{what} is not contiguous")))?;
    Ok(&data[lo..hi])
}

/// Runs `f` on the CPU data of the model's variables (read-locked meanwhile).
fn with_weights<T: Real, R>(
    vars: &[Var],
    names: &[String],
    f: impl FnOnce(&[&[T]]) -> Result<R>,
) -> Result<R> {
    let guards: Vec<_> = vars
        .iter()
        .map(|v| v.as_tensor().storage_and_layout())
        .collect();
    let w: Vec<&[T]> = guards
        .iter()
        .zip(names)
        .map(|((s, l), name)| cpu_slice::<T>(s, l, name))
        .collect::<Result<_>>()?;
    f(&w)
}

impl<T: Real> Net<T> {
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }

    fn check_model(&self, model: &MeshVae) -> Result<()> {
        // The same variables, not only the same shapes: the engine reads them in place.
        let vars = model.trainable_vars();
        let same = vars.len() == self.vars.len()
            && (vars.iter().zip(&self.vars))
                .all(|((_, a), b)| a.as_tensor().id() == b.as_tensor().id());
        if model.vertex_count() != self.v0 || !same {
            return Err(internal(
                "the model is not the one the engine was built for",
            ));
        }
        Ok(())
    }

    /// Checks the inputs' shapes and copies them into the engine's buffers; returns B.
    fn load_inputs(&mut self, Inputs { x, c }: Inputs<'_>, eps: &Tensor) -> Result<usize> {
        let dims = x.dims();
        let batch = match dims {
            &[b, v, c] if b >= 1 && v == self.v0 && c == FEATURE_CHANNELS => b,
            _ => {
                return Err(VaeError::shape(
                    "Engine::forward_backward",
                    format!(
                        "features of shape {dims:?}; expected [B ≥ 1, {}, {FEATURE_CHANNELS}]",
                        self.v0
                    ),
                ));
            }
        };
        if batch > self.max_batch || eps.dims() != [batch, self.latent] {
            return Err(VaeError::shape(
                "Engine::forward_backward",
                format!(
                    "batch of {batch} (at most {}), ε of shape {:?} (expected [{batch}, {}])",
                    self.max_batch,
                    eps.dims(),
                    self.latent
                ),
            ));
        }
        let (x, eps) = (x.contiguous()?, eps.contiguous()?);
        let (xs, xl) = x.storage_and_layout();
        let xd = cpu_slice::<T>(&xs, xl, "the features")?;
        let n = self.v0 * FEATURE_CHANNELS * batch;
        k::to_vcb(
            xd,
            &mut self.acts.0[self.x_buf][..n],
            (batch, self.v0, FEATURE_CHANNELS),
            self.order.as_deref(),
        );
        let (es, el) = eps.storage_and_layout();
        let ed = cpu_slice::<T>(&es, el, "ε")?;
        self.lat.eps[..ed.len()].copy_from_slice(ed);
        self.load_labels(c, batch)?;
        Ok(batch)
    }

    /// Copies the one-hot labels `[B, L]`, given exactly when the model is conditional.
    fn load_labels(&mut self, c: Option<&Tensor>, batch: usize) -> Result<()> {
        const OP: &str = "Engine::forward_backward";
        match (c, self.dense.labels) {
            (None, None) => Ok(()),
            (Some(_), None) => Err(VaeError::argument(
                "label",
                format!("{OP}: the model is not conditional"),
            )),
            (None, Some(_)) => Err(VaeError::argument(
                "label",
                format!("{OP}: the model is conditional; give each mesh's label"),
            )),
            (Some(c), Some(labels)) => {
                if c.dims() != [batch, labels.count] {
                    return Err(VaeError::shape(
                        OP,
                        format!(
                            "labels of shape {:?}; expected [{batch}, {}]",
                            c.dims(),
                            labels.count
                        ),
                    ));
                }
                let c = c.contiguous()?;
                let (cs, cl) = c.storage_and_layout();
                let cd = cpu_slice::<T>(&cs, cl, "the labels")?;
                self.cond[..cd.len()].copy_from_slice(cd);
                Ok(())
            }
        }
    }

    pub fn step(
        &mut self,
        model: &MeshVae,
        inputs: Inputs<'_>,
        (eps, weights): (&Tensor, &LossWeights),
    ) -> Result<StepLoss> {
        self.check_model(model)?;
        let batch = self.load_inputs(inputs, eps)?;
        let (vars, names) = (self.vars.clone(), self.names.clone());
        let loss = with_weights(&vars, &names, |w| {
            let loss = self.forward(w, batch, weights)?;
            self.backward(w, batch, weights)?;
            Ok(loss)
        })?;
        self.batch = batch;
        self.update_running_stats()?;
        Ok(loss)
    }

    fn forward(&mut self, w: &[&[T]], batch: usize, weights: &LossWeights) -> Result<StepLoss> {
        for node in &mut self.enc {
            forward_node(node, &mut self.acts, w, batch, BnStats::Batch)?;
        }
        let kl = self.latent_forward(w, batch);
        for node in &mut self.dec {
            forward_node(node, &mut self.acts, w, batch, BnStats::Batch)?;
        }
        let n = self.v0 * FEATURE_CHANNELS * batch;
        let coeff = 2.0 * weights.rec / batch as f64;
        let sse = k::sse_grad(
            &self.acts.0[self.x_hat][..n],
            &self.acts.0[self.x_buf][..n],
            &mut self.ga[..n],
            coeff,
        );
        // Rounded to the model's precision, as candle's path reports them: a term that
        // overflows f32 is infinite there too (and stops training before Adam runs).
        let round = |v: f64| f64_of::<T>(of(v));
        Ok(StepLoss {
            rec: round(weights.rec * sse / batch as f64),
            kl: round(weights.kl * kl),
        })
    }

    /// Back-propagates `ga` through one chain of nodes, last node first, leaving the gradient
    /// with respect to the chain's input in `ga`.
    fn backward_chain(&mut self, chain: Chain, w: &[&[T]], batch: usize) -> Result<()> {
        let nodes = match chain {
            Chain::Encoder => &mut self.enc,
            Chain::Decoder => &mut self.dec,
        };
        for node in nodes.iter_mut().rev() {
            let swap = backward_node(
                node,
                &self.acts,
                w,
                batch,
                &mut self.grads,
                [&mut self.ga, &mut self.gb, &mut self.work],
            )?;
            if swap {
                std::mem::swap(&mut self.ga, &mut self.gb);
            }
        }
        Ok(())
    }

    fn backward(&mut self, w: &[&[T]], batch: usize, weights: &LossWeights) -> Result<()> {
        // `ga` holds ∂L/∂x̂ (written with the loss).
        self.backward_chain(Chain::Decoder, w, batch)?;
        self.latent_backward(w, batch, weights);
        std::mem::swap(&mut self.ga, &mut self.gb);
        self.backward_chain(Chain::Encoder, w, batch)?;
        Ok(())
    }

    /// r ← 0.9·r + 0.1·batch for every batch norm (as candle's batch norm in train mode).
    fn update_running_stats(&self) -> Result<()> {
        for node in self.enc.iter().chain(&self.dec) {
            let Node::Conv(Conv { bn: Some(bn), .. }) = node else {
                continue;
            };
            for (running, batch) in [(&bn.running_mean, &bn.mean), (&bn.running_var, &bn.var)] {
                let old: Vec<f64> = running
                    .as_tensor()
                    .to_dtype(candle_core::DType::F64)?
                    .to_vec1()?;
                let next: Vec<f64> = old
                    .iter()
                    .zip(batch)
                    .map(|(r, b)| bn::DECAY * r + (1.0 - bn::DECAY) * b)
                    .collect();
                let t = Tensor::from_vec(next, old.len(), running.device())?;
                running.set(&t.to_dtype(running.dtype())?)?;
            }
        }
        Ok(())
    }

    /// Whether the full-resolution vertices run in another order than the template's.
    #[cfg(test)]
    pub fn renumbered(&self) -> bool {
        self.order
            .as_ref()
            .is_some_and(|o| o.iter().enumerate().any(|(p, &v)| p != v as usize))
    }

    pub fn apply_adam(&self, adam: &mut Adam, l2: f64) -> Result<f64> {
        if self.batch == 0 {
            return Err(internal("apply_adam before any forward_backward"));
        }
        if !adam.names().eq(self.names.iter().map(String::as_str)) {
            return Err(VaeError::argument(
                "adam",
                "its variables are not the model's trainable variables in order",
            ));
        }
        let fill =
            |var: usize| move |first: usize, out: &mut [T]| self.dense_grad_rows(var, first, out);
        let (fill_mu, fill_sigma) = (fill(self.dense.w_mu), fill(self.dense.w_sigma));
        let grads: Vec<GradSource<T>> = (0..self.grads.len())
            .map(|i| match i {
                i if i == self.dense.w_mu => GradSource::Rows {
                    row_len: self.latent,
                    fill: &fill_mu,
                },
                i if i == self.dense.w_sigma => GradSource::Rows {
                    row_len: self.latent,
                    fill: &fill_sigma,
                },
                i => GradSource::Slice(&self.grads[i]),
            })
            .collect();
        let grad_scale = match adam.grad_clip().is_on() {
            true => adam.clip_scale(self.grad_norm()),
            false => 1.0,
        };
        adam.step_with_sources(&grads, l2, grad_scale)
    }

    /// The norm of the last step's gradient over every trainable variable (the L2 term's
    /// gradient left out, as Adam adds it).
    pub fn grad_norm(&self) -> f64 {
        let dense = [self.dense.w_mu, self.dense.w_sigma];
        let rest: f64 = (self.grads.iter().enumerate())
            .filter(|(i, _)| !dense.contains(i))
            .flat_map(|(_, g)| g.iter())
            .map(|&x| f64_of(x) * f64_of(x))
            .sum();
        (rest + self.dense_grad_sq()).sqrt()
    }

    pub fn gradients(&self) -> Result<Vec<(String, Tensor)>> {
        self.names
            .iter()
            .zip(&self.vars)
            .zip(&self.grads)
            .enumerate()
            .map(|(i, ((n, v), g))| {
                let dense = [self.dense.w_mu, self.dense.w_sigma].contains(&i);
                let made;
                let g = if dense {
                    let mut all = vec![of(0.0); v.elem_count()];
                    if self.batch > 0 {
                        self.dense_grad_rows(i, 0, &mut all);
                    }
                    made = all;
                    &made
                } else {
                    g
                };
                let values: Vec<f64> = g.iter().map(|&x| f64_of(x)).collect();
                let t = Tensor::from_vec(values, v.shape(), v.device())?.to_dtype(v.dtype())?;
                Ok((n.clone(), t))
            })
            .collect()
    }
}

/// Which node chain [`Net::backward_chain`] walks.
#[derive(Clone, Copy)]
enum Chain {
    Encoder,
    Decoder,
}
