//! [`MeshVae`]: the network (the paper's Fig. 2 as the authors' released code runs it).
//!
//! Encoder: the structure's convolutions and poolings on the hierarchy's levels (conv → batch
//! norm → tanh; the last convolution without batch norm and, by default, linear), flatten
//! `[B, V_L·C]` (index p·C + c), μ = hW_μ + b_μ, σ = √(2·sigmoid(hW_σ + b_σ)) ∈ (0, √2).
//! Decoder: h = zW_μᵀ + b_dec (tied to the μ head), reshape `[B, V_L, C]`, the mirrored
//! convolutions and de-poolings, all ending in tanh, so x̂ ∈ (−1, 1).
//! A conditional model (labels in its config) also feeds a one-hot label to both heads and to
//! the decoder's dense layer: see `cond.rs`.

mod build;
mod cond;
mod file;
pub(crate) mod layers;
pub(crate) mod vars;

pub(crate) use cond::{LABEL_SCALE, pick as pick_labels, unknown_label};
pub(crate) use file::{entry as tensor_entry, stamped_error};

use crate::candle::baseline::BaselineNet;
use crate::candle::batch_norm::Mode;
use crate::error::{Result, VaeError};
use crate::net::baseline::BaselinePlan;
use crate::net::config::ModelConfig;
use crate::net::latent::sigma_of_sigmoid;
use crate::net::network::Input;
use crate::net::params::ParamCount;
use crate::net::plan::NetPlan;
use crate::net::vars::VarPlan;
use crate::numerics::rng::Rng;
use candle_core::backprop::GradStore;
use candle_core::{DType, Device, Tensor, Var};
use layers::{ConvBlock, GraphConv, Stage, Weights};
use mesh_hierarchy::Hierarchy;
use std::sync::Arc;

/// The encoder's output: the posterior q(z|x) = N(μ, diag σ²), both `[B, latent]`.
#[derive(Debug, Clone)]
pub struct Encoded {
    pub mu: Tensor,
    pub sigma: Tensor,
}

/// σ = √(2·sigmoid(s)) ∈ (0, √2) of the σ head's pre-activation s (the authors' form, for every
/// VAE here).
pub(crate) fn sigma_head(s: &Tensor) -> Result<Tensor> {
    Ok(sigma_of_sigmoid(&candle_nn::ops::sigmoid(s)?)?)
}

/// The mesh VAE on one hierarchy: the paper's network, or one of the others it is compared with
/// ([`crate::Network`]; `baseline.rs`).
#[derive(Debug, Clone)]
pub struct MeshVae {
    config: ModelConfig,
    dtype: DType,
    device: Device,
    /// Vertex counts of the levels the network uses (0 ..= number of poolings).
    vertex_counts: Vec<usize>,
    /// The trained variables, by [`crate::net::vars::ParamId`].
    params: Vec<Var>,
    /// The batch norms' running statistics, by [`crate::net::vars::StateId`].
    state: Vec<Var>,
    body: Body,
}

/// The layers of the network.
#[derive(Debug, Clone)]
enum Body {
    Ours(Box<Ours>),
    Baseline(Box<BaselineNet>),
}

/// The paper's network.
#[derive(Debug, Clone)]
struct Ours {
    /// The layer list and variables every executor reads.
    plan: Arc<NetPlan>,
    /// The encoder's stages, one per step of the plan.
    enc: Vec<Stage>,
    /// The decoder's stages in the order they run.
    dec: Vec<Stage>,
    w_mu: Tensor,
    b_mu: Tensor,
    w_sigma: Tensor,
    b_sigma: Tensor,
    b_dec: Tensor,
    /// The label weights of a conditional model.
    label_weights: Option<cond::LabelWeights>,
}

impl MeshVae {
    /// An f32 model for `config` on `hierarchy` (built with `config.pool` and
    /// `config.pool_levels()` pooling steps), every weight drawn from `Rng::new(seed)`.
    pub fn new(
        config: &ModelConfig,
        hierarchy: &Hierarchy,
        device: &Device,
        seed: u64,
    ) -> Result<Self> {
        Self::with_dtype(config, hierarchy, device, DType::F32, seed)
    }

    /// As [`Self::new`] with f32 or f64 weights (f64 for gradient checks).
    pub fn with_dtype(
        config: &ModelConfig,
        hierarchy: &Hierarchy,
        device: &Device,
        dtype: DType,
        seed: u64,
    ) -> Result<Self> {
        config.validate()?;
        if !matches!(dtype, DType::F32 | DType::F64) {
            return Err(VaeError::argument(
                "dtype",
                format!("{dtype:?}; the model runs in f32 or f64"),
            ));
        }
        let mut rng = Rng::new(seed);
        if !config.net.is_ours() {
            let counts = hierarchy.vertex_counts();
            let levels = counts.len().min(config.pool_levels() + 1);
            let plan = BaselinePlan::new(config.net, config.latent, &counts[..levels])?;
            let params = vars::create(&plan.params, config.init_std, dtype, device, &mut rng)?;
            let net = BaselineNet::new(plan, hierarchy, &params, device)?;
            return Ok(Self {
                config: config.clone(),
                dtype,
                device: device.clone(),
                vertex_counts: net.plan.vertex_counts.clone(),
                params,
                state: Vec::new(),
                body: Body::Baseline(Box::new(net)),
            });
        }
        let plan = NetPlan::new(config, hierarchy)?;
        let params = vars::create(&plan.params, config.init_std, dtype, device, &mut rng)?;
        let state = vars::create(&plan.state, config.init_std, dtype, device, &mut rng)?;
        let (enc, dec) = build::stages(config, &plan, &params, &state, device)?;
        let t = |id: crate::net::vars::ParamId| params[id.0].as_tensor().clone();
        let heads = plan.heads;
        let label_weights = heads.labels.map(|l| cond::LabelWeights {
            mu: t(l.mu),
            sigma: t(l.sigma),
            dec: t(l.dec),
        });
        let ours = Ours {
            label_weights,
            w_mu: t(heads.w_mu),
            b_mu: t(heads.b_mu),
            w_sigma: t(heads.w_sigma),
            b_sigma: t(heads.b_sigma),
            b_dec: t(heads.b_dec),
            plan: Arc::new(plan),
            enc,
            dec,
        };
        Ok(Self {
            config: config.clone(),
            dtype,
            device: device.clone(),
            vertex_counts: ours.plan.vertex_counts(),
            params,
            state,
            body: Body::Ours(Box::new(ours)),
        })
    }

    /// The layer list and variables the model was built from (what the CPU engine reads).
    /// `None` for the other networks, which the engine does not run.
    pub(crate) fn plan(&self) -> Option<&NetPlan> {
        match &self.body {
            Body::Ours(o) => Some(&o.plan),
            Body::Baseline(_) => None,
        }
    }

    /// The network's trained and state variables as planned (names, shapes, starts).
    fn var_plans(&self) -> (&[VarPlan], &[VarPlan]) {
        match &self.body {
            Body::Ours(o) => (&o.plan.params, &o.plan.state),
            Body::Baseline(b) => (&b.plan.params, &[]),
        }
    }

    /// The paper's network's layers, or an error naming `op` for the others.
    fn ours(&self, op: &'static str) -> Result<&Ours> {
        match &self.body {
            Body::Ours(o) => Ok(o),
            Body::Baseline(_) => Err(VaeError::argument(
                "net",
                format!("{op} is defined for ours only, not {}", self.config.net),
            )),
        }
    }

    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// Vertices of the template (the input's V).
    pub fn vertex_count(&self) -> usize {
        self.vertex_counts[0]
    }

    /// Vertices of every level the network uses, template first.
    pub fn vertex_counts(&self) -> &[usize] {
        &self.vertex_counts
    }

    pub fn latent(&self) -> usize {
        self.config.latent
    }

    pub fn dtype(&self) -> DType {
        self.dtype
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The trained variables, sorted by name (the order the optimiser and the L2 term use).
    pub fn trainable_vars(&self) -> Vec<(String, Var)> {
        (self.var_plans().0.iter().zip(&self.params))
            .map(|(p, v)| (p.name.clone(), v.clone()))
            .collect()
    }

    /// The batch norms' running means and variances, sorted by name.
    pub fn state_vars(&self) -> Vec<(String, Var)> {
        (self.var_plans().1.iter().zip(&self.state))
            .map(|(p, v)| (p.name.clone(), v.clone()))
            .collect()
    }

    /// Every variable, trained then state, with its name.
    pub(crate) fn named_vars(&self) -> impl Iterator<Item = (&String, &Var)> {
        let (params, state) = self.var_plans();
        let trained = params.iter().zip(&self.params);
        let state = state.iter().zip(&self.state);
        trained.chain(state).map(|(p, v)| (&p.name, v))
    }

    /// The trained variables by name (tests).
    #[cfg(test)]
    pub(crate) fn trainable(&self) -> std::collections::BTreeMap<String, Var> {
        self.trainable_vars().into_iter().collect()
    }

    /// Weights and biases (BN γ, β count as biases) actually created.
    pub fn param_count(&self) -> ParamCount {
        crate::net::params::count_of(self.var_plans().0)
    }

    /// The labels of a conditional model, in one-hot order (empty for an unconditional one).
    pub fn labels(&self) -> &[String] {
        &self.config.labels
    }

    pub fn is_conditional(&self) -> bool {
        self.config.is_conditional()
    }

    /// One-hot rows `[B, L]` (the model's dtype and device) for `labels`, the active entry
    /// being the label scale (8; see `cond.rs`).
    ///
    /// Errors: a label the model does not know (naming it and listing the known ones), or any
    /// label for an unconditional model.
    pub fn one_hot<S: AsRef<str>>(&self, labels: &[S]) -> Result<Tensor> {
        cond::one_hot(self.labels(), labels, self.dtype, &self.device)
    }

    /// μ and σ `[B, latent]` of features x `[B, V, 9]` with labels c `[B, L]` (one-hot rows;
    /// `Some` exactly when the model is conditional).
    pub fn encode(&self, x: &Tensor, c: Option<&Tensor>, mode: Mode) -> Result<Encoded> {
        self.check_input("MeshVae::encode", x)?;
        let label = self.check_labels("MeshVae::encode", c, x.dim(0)?)?;
        let o = match &self.body {
            Body::Ours(o) => o,
            Body::Baseline(b) => {
                let (mu, sigma) = b.encode(x)?;
                // A plain auto-encoder's posterior is the point μ.
                let sigma = sigma.map_or_else(|| mu.zeros_like(), Ok)?;
                return Ok(Encoded { mu, sigma });
            }
        };
        let batch = x.dim(0)?;
        // Vertex-major inside the network: see `spectral_conv`'s layouts.
        let mut h = x.transpose(0, 1)?.contiguous()?;
        for stage in &o.enc {
            h = self.run(stage, &h, mode)?;
        }
        let flat = h
            .transpose(0, 1)?
            .contiguous()?
            .reshape((batch, self.flat_width()))?;
        let mut mu = flat.matmul(&o.w_mu)?.broadcast_add(&o.b_mu)?;
        let mut s = flat.matmul(&o.w_sigma)?.broadcast_add(&o.b_sigma)?;
        if let Some((c, w)) = label {
            mu = (mu + c.matmul(&w.mu)?)?;
            s = (s + c.matmul(&w.sigma)?)?;
        }
        Ok(Encoded {
            mu,
            sigma: sigma_head(&s)?,
        })
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]` and labels c `[B, L]` (`Some` exactly
    /// when the model is conditional).
    pub fn decode(&self, z: &Tensor, c: Option<&Tensor>, mode: Mode) -> Result<Tensor> {
        let batch = self.check_latent("MeshVae::decode", z, None)?;
        let o = match &self.body {
            Body::Ours(o) => o,
            Body::Baseline(b) => {
                self.check_labels("MeshVae::decode", c, batch)?;
                return b.decode(z);
            }
        };
        let coarse = self.vertex_counts[self.vertex_counts.len() - 1];
        let mut h = self
            .decoder_fc(z, c)?
            .reshape((batch, coarse, self.config.channels))?
            .transpose(0, 1)?
            .contiguous()?;
        for stage in &o.dec {
            h = self.run(stage, &h, mode)?;
        }
        Ok(h.transpose(0, 1)?.contiguous()?)
    }

    /// x̂ and the posterior for features x `[B, V, 9]` and noise ε `[B, latent]`:
    /// z = μ + σ ⊙ ε (labels c `[B, L]`, for both the encoder and the decoder, exactly for a
    /// conditional model).
    pub fn forward(
        &self,
        x: &Tensor,
        c: Option<&Tensor>,
        eps: &Tensor,
        mode: Mode,
    ) -> Result<(Tensor, Encoded)> {
        let encoded = self.encode(x, c, mode)?;
        self.check_latent("MeshVae::forward (eps)", eps, Some(encoded.mu.dim(0)?))?;
        let z = (&encoded.mu + (&encoded.sigma * eps)?)?;
        Ok((self.decode(&z, c, mode)?, encoded))
    }

    /// decode(μ(x, c), c) in eval mode.
    pub fn reconstruct(&self, x: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        let encoded = self.encode(x, c, Mode::Eval)?;
        self.decode(&encoded.mu, c, Mode::Eval)
    }

    /// The decoder's dense layer: zW_μᵀ + b_dec (+ c·W_dc for a conditional model).
    pub(crate) fn decoder_fc(&self, z: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        let label = self.check_labels("MeshVae::decode", c, z.dim(0)?)?;
        let o = self.ours("the decoder's dense layer")?;
        let h = z.matmul(&o.w_mu.t()?)?.broadcast_add(&o.b_dec)?;
        Ok(match label {
            Some((c, w)) => (h + c.matmul(&w.dec)?)?,
            None => h,
        })
    }

    /// Checks that labels come exactly with a conditional model, as `[batch, L]` of the model's
    /// kind, and pairs them with the label weights.
    fn check_labels<'a>(
        &'a self,
        op: &'static str,
        c: Option<&'a Tensor>,
        batch: usize,
    ) -> Result<Option<(&'a Tensor, &'a cond::LabelWeights)>> {
        let label_weights = match &self.body {
            Body::Ours(o) => &o.label_weights,
            Body::Baseline(_) => &None,
        };
        match (c, label_weights) {
            (None, None) => Ok(None),
            (Some(_), None) => Err(VaeError::argument(
                "label",
                format!("{op}: the model is not conditional (it was trained without labels)"),
            )),
            (None, Some(_)) => Err(VaeError::argument(
                "label",
                format!(
                    "{op}: the model is conditional on the labels {}; give each mesh's label",
                    self.labels().join(", ")
                ),
            )),
            (Some(c), Some(w)) => {
                let l = self.labels().len();
                if c.dims() != [batch, l] {
                    return Err(VaeError::shape(
                        op,
                        format!("labels of shape {:?}; expected [{batch}, {l}]", c.dims()),
                    ));
                }
                self.check_kind(op, c)?;
                Ok(Some((c, w)))
            }
        }
    }

    /// Gradients of `loss` (a scalar computed by this model) for every variable.
    pub fn backward(&self, loss: &Tensor) -> Result<GradStore> {
        Ok(loss.backward()?)
    }

    /// One stage on h `[V, B, C]`.
    fn run(&self, stage: &Stage, h: &Tensor, mode: Mode) -> Result<Tensor> {
        match stage {
            Stage::Conv(block) => {
                let tied = self.tied_conv(block)?;
                block.forward(h, mode, tied.as_ref())
            }
            Stage::Down(d) => d.forward(h),
            Stage::Up(u) => u.forward(h),
        }
    }

    /// The encoder's convolution blocks, in order (index = `spec.index`).
    pub(crate) fn encoder_blocks(&self) -> impl Iterator<Item = &ConvBlock> {
        let enc = self.plan_stages().0;
        enc.iter().filter_map(|s| match s {
            Stage::Conv(b) => Some(b),
            _ => None,
        })
    }

    /// The decoder's convolution blocks, in the order they run.
    #[cfg(test)]
    pub(crate) fn decoder_blocks(&self) -> impl Iterator<Item = &ConvBlock> {
        let dec = self.plan_stages().1;
        dec.iter().filter_map(|s| match s {
            Stage::Conv(b) => Some(b),
            _ => None,
        })
    }

    /// The adjoint of the mirror encoder convolution, for a tied decoder block.
    fn tied_conv(&self, block: &ConvBlock) -> Result<Option<GraphConv>> {
        let Weights::Tied(op_t) = &block.weights else {
            return Ok(None);
        };
        let mirror = self.encoder_blocks().nth(block.spec.index);
        let Some(Weights::Own(conv)) = mirror.map(|b| &b.weights) else {
            return Err(VaeError::shape(
                "MeshVae",
                format!(
                    "internal: tied convolution {} has no encoder convolution",
                    block.spec.index
                ),
            ));
        };
        Ok(Some(conv.adjoint(op_t)?))
    }

    fn flat_width(&self) -> usize {
        match &self.body {
            Body::Ours(o) => o.plan.flat_width(),
            Body::Baseline(b) => b.plan.flat_width(),
        }
    }

    /// The paper's network's encoder and decoder stages (none for the others).
    fn plan_stages(&self) -> (&[Stage], &[Stage]) {
        match &self.body {
            Body::Ours(o) => (&o.enc, &o.dec),
            Body::Baseline(_) => (&[], &[]),
        }
    }

    fn check_input(&self, op: &'static str, x: &Tensor) -> Result<()> {
        let v = self.vertex_count();
        let channels = self.config.net.input().channels();
        let ok_shape = matches!(x.dims(), &[b, xv, c] if b > 0 && xv == v && c == channels);
        if !ok_shape {
            let what = match self.config.net.input() {
                Input::Features => "features",
                Input::Positions => "positions",
            };
            return Err(VaeError::shape(
                op,
                format!(
                    "{what} of shape {:?}; the model expects [B ≥ 1, {v}, {channels}]",
                    x.dims()
                ),
            ));
        }
        self.check_kind(op, x)
    }

    /// Checks z (or ε) is `[B, latent]` (with B = `batch` if given) and returns B.
    fn check_latent(&self, op: &'static str, z: &Tensor, batch: Option<usize>) -> Result<usize> {
        let latent = self.config.latent;
        match z.dims() {
            &[b, l] if b > 0 && l == latent && batch.is_none_or(|want| want == b) => {
                self.check_kind(op, z)?;
                Ok(b)
            }
            dims => Err(VaeError::shape(
                op,
                format!(
                    "shape {dims:?}; expected [{}, {latent}]",
                    batch.map_or("B ≥ 1".to_owned(), |b| b.to_string())
                ),
            )),
        }
    }

    fn check_kind(&self, op: &'static str, t: &Tensor) -> Result<()> {
        if t.dtype() != self.dtype || !t.device().same_device(&self.device) {
            return Err(VaeError::shape(
                op,
                format!(
                    "tensor of {:?} on {:?}; the model is {:?} on {:?}",
                    t.dtype(),
                    t.device().location(),
                    self.dtype,
                    self.device.location()
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
