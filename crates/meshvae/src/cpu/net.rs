//! The engine's network: its layer list, buffers, forward and backward passes (see `mod.rs`).

use super::kernels as k;
use super::model::EngineModel;
use super::{Real, StepLoss, f64_of, of};
use crate::error::{Result, VaeError};
use crate::net::batch_norm as bn;
use crate::net::config::FEATURE_CHANNELS;
use crate::net::loss_weights::LossWeights;
use crate::numerics::host::{HostArray, HostSlice};
use crate::optim::adam::{Adam, GradSource};
use spectral_conv::{ChebKernel, MaxKernel, SparseKernel, Workspace};
use std::sync::Arc;

mod build;
mod conv_weight;
mod infer;
mod latent;
mod node;

use conv_weight::ConvWeight;
use node::{BnStats, backward_node, forward_node};

/// A batch norm's variables (indices into the trainable and the state lists), its last batch
/// statistics and, for inference, the running ones read from the model.
#[derive(Debug)]
struct Bn {
    gamma: usize,
    beta: usize,
    running_mean: usize,
    running_var: usize,
    mean: Vec<f64>,
    var: Vec<f64>,
    inv_std: Vec<f64>,
    /// The running mean and variance as of the last inference pass.
    running: (Vec<f64>, Vec<f64>),
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
pub(crate) struct Inputs<'a> {
    pub x: HostArray<'a>,
    pub c: Option<HostArray<'a>>,
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
    /// The trainable variables' identities (see [`EngineModel::var_ids`]).
    var_ids: Vec<u64>,
    /// The trainable variables' element counts.
    lens: Vec<usize>,
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

/// The values of `data` as `T` (the engine's own float type).
fn host<'a, T: Real>(data: HostSlice<'a>, what: &str) -> Result<&'a [T]> {
    T::host(data).ok_or_else(|| internal(format!("{what} has another float type")))
}

/// Runs `f` on the model's trainable variables, read in place.
fn with_weights<T: Real, R>(
    model: &dyn EngineModel,
    f: impl FnOnce(&[&[T]]) -> Result<R>,
) -> Result<R> {
    let mut f = Some(f);
    let mut out = None;
    model.with_weights(&mut |slices| {
        let w: Vec<&[T]> = (slices.iter())
            .map(|&s| host::<T>(s, "a weight"))
            .collect::<Result<_>>()?;
        if let Some(f) = f.take() {
            out = Some(f(&w)?);
        }
        Ok(())
    })?;
    out.ok_or_else(|| internal("the model did not lend its weights"))
}

impl<T: Real> Net<T> {
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }

    fn check_model(&self, model: &dyn EngineModel) -> Result<()> {
        // The same variables, not only the same shapes: the engine reads them in place.
        if model.vertex_count() != self.v0 || model.var_ids() != self.var_ids {
            return Err(internal(
                "the model is not the one the engine was built for",
            ));
        }
        Ok(())
    }

    /// Checks the inputs' shapes and copies them into the engine's buffers (ε = 0 where not
    /// given: z = μ); returns B.
    fn load_inputs(
        &mut self,
        Inputs { x, c }: Inputs<'_>,
        eps: Option<HostArray<'_>>,
    ) -> Result<usize> {
        let dims = x.dims;
        let batch = match *dims {
            [b, v, c] if b >= 1 && v == self.v0 && c == FEATURE_CHANNELS => b,
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
        let expected = [batch, self.latent];
        let eps_dims: &[usize] = eps.map_or(&expected, |e| e.dims);
        if batch > self.max_batch || eps_dims != [batch, self.latent] {
            return Err(VaeError::shape(
                "Engine::forward_backward",
                format!(
                    "batch of {batch} (at most {}), ε of shape {eps_dims:?} (expected [{batch}, {}])",
                    self.max_batch, self.latent
                ),
            ));
        }
        let xd = host::<T>(x.data, "the features")?;
        let n = self.v0 * FEATURE_CHANNELS * batch;
        if xd.len() != n {
            return Err(internal("the features' values do not fill their shape"));
        }
        k::to_vcb(
            xd,
            &mut self.acts.0[self.x_buf][..n],
            (batch, self.v0, FEATURE_CHANNELS),
            self.order.as_deref(),
        );
        let eps_len = batch * self.latent;
        match eps {
            Some(e) => {
                let ed = host::<T>(e.data, "ε")?;
                if ed.len() != eps_len {
                    return Err(internal("ε's values do not fill its shape"));
                }
                self.lat.eps[..eps_len].copy_from_slice(ed);
            }
            None => self.lat.eps[..eps_len].fill(of(0.0)),
        }
        self.load_labels(c, batch)?;
        Ok(batch)
    }

    /// Copies the one-hot labels `[B, L]`, given exactly when the model is conditional.
    fn load_labels(&mut self, c: Option<HostArray<'_>>, batch: usize) -> Result<()> {
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
                if c.dims != [batch, labels.count] {
                    return Err(VaeError::shape(
                        OP,
                        format!(
                            "labels of shape {:?}; expected [{batch}, {}]",
                            c.dims, labels.count
                        ),
                    ));
                }
                let cd = host::<T>(c.data, "the labels")?;
                if cd.len() != batch * labels.count {
                    return Err(internal("the labels' values do not fill their shape"));
                }
                self.cond[..cd.len()].copy_from_slice(cd);
                Ok(())
            }
        }
    }

    pub fn step(
        &mut self,
        model: &dyn EngineModel,
        inputs: Inputs<'_>,
        (eps, weights): (HostArray<'_>, &LossWeights),
    ) -> Result<StepLoss> {
        self.check_model(model)?;
        let batch = self.load_inputs(inputs, Some(eps))?;
        let loss = with_weights(model, |w| {
            let loss = self.forward(w, batch, weights)?;
            self.backward(w, batch, weights)?;
            Ok(loss)
        })?;
        self.batch = batch;
        self.update_running_stats(model)?;
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
    fn update_running_stats(&self, model: &dyn EngineModel) -> Result<()> {
        for node in self.enc.iter().chain(&self.dec) {
            let Node::Conv(Conv { bn: Some(bn), .. }) = node else {
                continue;
            };
            for (running, batch) in [(bn.running_mean, &bn.mean), (bn.running_var, &bn.var)] {
                let next: Vec<f64> = (model.state(running)?.iter().zip(batch))
                    .map(|(r, b)| {
                        let Ok(next) = bn::running_update(r, b);
                        next
                    })
                    .collect();
                model.set_state(running, &next)?;
            }
        }
        Ok(())
    }

    /// Reads every batch norm's running statistics from the model, for inference.
    fn load_running_stats(&mut self, model: &dyn EngineModel) -> Result<()> {
        for node in self.enc.iter_mut().chain(&mut self.dec) {
            if let Node::Conv(Conv { bn: Some(bn), .. }) = node {
                bn.running = (model.state(bn.running_mean)?, model.state(bn.running_var)?);
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

    /// The last step's gradients in f64, by variable name.
    pub fn gradients(&self) -> Vec<(String, Vec<f64>)> {
        (self.names.iter().zip(&self.lens).zip(&self.grads))
            .enumerate()
            .map(|(i, ((n, &len), g))| {
                let dense = [self.dense.w_mu, self.dense.w_sigma].contains(&i);
                let values = if dense {
                    let mut all = vec![of::<T>(0.0); len];
                    if self.batch > 0 {
                        self.dense_grad_rows(i, 0, &mut all);
                    }
                    all.iter().map(|&x| f64_of(x)).collect()
                } else {
                    g.iter().map(|&x| f64_of(x)).collect()
                };
                (n.clone(), values)
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
