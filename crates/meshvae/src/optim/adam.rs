//! [`Adam`]: bias-corrected Adam without weight decay (Kingma & Ba; TF's defaults, as the
//! authors). candle-nn's `AdamW` with weight decay 0 computes the same update, but its moments
//! are private, so a checkpoint could not restore it; this one exports its whole state
//! ([`Adam::state_tensors`], [`Adam::load_state`]) so that a resumed run continues bit-exactly.
//!
//! Update, per variable θ with gradient g at step t:
//! m ← β₁m + (1−β₁)g, v ← β₂v + (1−β₂)g², θ ← θ − lr · (m/(1−β₁ᵗ)) / (√(v/(1−β₂ᵗ)) + ε).

mod clip;
mod kernels;

pub use clip::GradClip;
use clip::square_sum_f64;
pub(crate) use kernels::GradSource;

use crate::error::{Result, VaeError};
use crate::numerics::real::Real;
use candle_core::backprop::GradStore;
use candle_core::{DType, Tensor, Var};
use kernels::{FusedUpdate, update_slot};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Adam's hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

impl Default for AdamConfig {
    /// lr 1e-3, β₁ 0.9, β₂ 0.999, ε 1e-8.
    fn default() -> Self {
        Self {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// One optimised variable and its moments.
#[derive(Debug)]
pub(super) struct Slot {
    name: String,
    var: Var,
    m: Var,
    v: Var,
    /// This variable's rate is the optimiser's times this ([`Adam::scale_lr`]).
    lr_scale: f64,
}

/// The optimiser over a model's named variables.
#[derive(Debug)]
pub struct Adam {
    config: AdamConfig,
    slots: Vec<Slot>,
    step: u64,
    /// The step of the last [`Adam::restart`]: the bias correction counts from it.
    restarted_at: u64,
    /// Clipping of the gradient's norm ([`Adam::set_grad_clip`]; off by default).
    clip: GradClip,
}

/// Name of the step counter in [`Adam::state_tensors`].
const STEP: &str = "adam.step";
/// Name of the step of the last restart (written only after one, so older states still load).
const RESTARTED_AT: &str = "adam.restarted_at";
/// Name of the clipping rule's running mean (written only when clipping is on).
const CLIP: &str = "adam.clip";

impl Adam {
    /// An optimiser at step 0 over `vars` (e.g. `MeshVae::trainable_vars()`) with learning rate
    /// `lr` and the other settings of [`AdamConfig::default`].
    pub fn new(vars: Vec<(String, Var)>, lr: f64) -> Result<Self> {
        Self::with_config(
            vars,
            AdamConfig {
                lr,
                ..AdamConfig::default()
            },
        )
    }

    /// An optimiser at step 0 (zero moments) over `vars` with any settings.
    pub fn with_config(vars: Vec<(String, Var)>, config: AdamConfig) -> Result<Self> {
        let ok = config.lr.is_finite()
            && config.lr > 0.0
            && (0.0..1.0).contains(&config.beta1)
            && (0.0..1.0).contains(&config.beta2)
            && config.eps.is_finite()
            && config.eps > 0.0;
        if !ok {
            return Err(VaeError::argument(
                "adam",
                format!("{config:?}: needs lr > 0, β₁ and β₂ in [0, 1), ε > 0"),
            ));
        }
        let slots = vars
            .into_iter()
            .map(|(name, var)| {
                let zeros = || Var::zeros(var.shape(), var.dtype(), var.device());
                Ok(Slot {
                    lr_scale: 1.0,
                    m: zeros()?,
                    v: zeros()?,
                    name,
                    var,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            config,
            slots,
            step: 0,
            restarted_at: 0,
            clip: GradClip::new(0.0),
        })
    }

    /// Clips every step's gradient (the loss's, before the L2 term's is added) to `factor`
    /// times the running mean of the recent gradient norms ([`GradClip`]); 0 turns it off.
    pub fn set_grad_clip(&mut self, factor: f64) -> Result<()> {
        GradClip::check_factor(factor)?;
        self.clip = GradClip::new(factor);
        Ok(())
    }

    /// The clipping rule and its running mean.
    pub fn grad_clip(&self) -> &GradClip {
        &self.clip
    }

    /// The factor this step's gradient is scaled by, given its norm (1 without clipping).
    pub(crate) fn clip_scale(&mut self, norm: f64) -> f64 {
        self.clip.scale(norm)
    }

    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// Changes the learning rate of the next steps (a schedule's); the moments are kept.
    pub fn set_lr(&mut self, lr: f64) -> Result<()> {
        if !(lr.is_finite() && lr > 0.0) {
            return Err(VaeError::argument("lr", format!("{lr} is not positive")));
        }
        self.config.lr = lr;
        Ok(())
    }

    /// Gives the variable `name` its own rate, `scale` times the optimiser's (1 by default).
    /// Adam moves every weight by about the rate whatever its gradient's size, so a layer that
    /// sums many inputs changes its outputs far more per step than a layer that sums few;
    /// scaling its rate down evens that out.
    pub fn scale_lr(&mut self, name: &str, scale: f64) -> Result<()> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(VaeError::argument(
                "lr scale",
                format!("{scale} is not positive"),
            ));
        }
        let slot = self
            .slots
            .iter_mut()
            .find(|s| s.name == name)
            .ok_or_else(|| VaeError::argument("lr scale", format!("no variable named {name}")))?;
        slot.lr_scale = scale;
        Ok(())
    }

    /// Steps taken so far.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// Forgets the moments, as a fresh optimiser would, but keeps counting steps: after the
    /// weights were put back to an earlier state (a diverged run), moments gathered on the way
    /// out would steer the first steps. The bias correction starts again from here.
    pub fn restart(&mut self) -> Result<()> {
        for s in &self.slots {
            s.m.set(&s.m.as_tensor().zeros_like()?)?;
            s.v.set(&s.v.as_tensor().zeros_like()?)?;
        }
        self.restarted_at = self.step;
        Ok(())
    }

    /// Counts a step and returns its update: the rate, the moments' decays and their bias
    /// corrections, and the L2 weight.
    fn next_update(&mut self, l2: f64, grad_scale: f64) -> FusedUpdate {
        self.step += 1;
        let AdamConfig {
            lr,
            beta1,
            beta2,
            eps,
        } = self.config;
        let t = self.bias_steps();
        FusedUpdate {
            beta1,
            beta2,
            scale_m: 1.0 / (1.0 - beta1.powi(t)),
            scale_v: 1.0 / (1.0 - beta2.powi(t)),
            lr,
            eps,
            l2,
            grad_scale,
        }
    }

    /// The exponent of the bias correction of the step being taken.
    fn bias_steps(&self) -> i32 {
        i32::try_from(self.step - self.restarted_at).unwrap_or(i32::MAX)
    }

    /// One update from `grads`; variables without a gradient are left alone (moments too).
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.step_with_l2(grads, 0.0)
    }

    /// One update from `grads` plus the gradient `l2 · θ` of an L2 term `l2 · ½‖θ‖²` that was
    /// left out of the autograd graph (see `MeshVae::training_loss`): the same step as
    /// [`Self::step`] on the full loss, without autograd holding a parameter-sized L2 gradient
    /// (and its sum with the others) for every variable at once.
    pub fn step_with_l2(&mut self, grads: &GradStore, l2: f64) -> Result<()> {
        let mut grad_scale = 1.0;
        if self.clip.is_on() {
            let mut sq = 0.0;
            for slot in &self.slots {
                if let Some(g) = grads.get(&slot.var) {
                    sq += square_sum_f64(g)?;
                }
            }
            grad_scale = self.clip.scale(sq.sqrt());
        }
        let update = self.next_update(l2, grad_scale);
        let FusedUpdate {
            beta1,
            beta2,
            scale_m,
            scale_v,
            lr,
            eps,
            ..
        } = update;
        for slot in &self.slots {
            let Some(g) = grads.get(&slot.var) else {
                continue;
            };
            let update = update.scaled(slot.lr_scale);
            let lr = lr * slot.lr_scale;
            if crate::numerics::real::fusable(g) && g.dtype() == slot.var.dtype() {
                // The CPU path: the engine's one-pass update (L2 gradient added inside).
                let g = g.contiguous()?;
                match g.dtype() {
                    DType::F32 => update_slot::<f32>(slot, &g, &update)?,
                    _ => update_slot::<f64>(slot, &g, &update)?,
                }
                continue;
            }
            // Other devices and dtypes: the same arithmetic as candle ops.
            let scaled;
            let g = if grad_scale != 1.0 {
                scaled = g.affine(grad_scale, 0.0)?;
                &scaled
            } else {
                g
            };
            let with_l2;
            let g = if l2 != 0.0 {
                with_l2 = (g + slot.var.as_tensor().affine(l2, 0.0)?)?;
                &with_l2
            } else {
                g
            };
            let m = ((slot.m.as_tensor() * beta1)? + (g * (1.0 - beta1))?)?;
            let v = ((slot.v.as_tensor() * beta2)? + (g.sqr()? * (1.0 - beta2))?)?;
            let m_hat = (&m * scale_m)?;
            let v_hat = (&v * scale_v)?;
            let update = ((m_hat / (v_hat.sqrt()? + eps)?)? * lr)?;
            let theta = (slot.var.as_tensor() - update)?;
            slot.m.set(&m)?;
            slot.v.set(&v)?;
            slot.var.set(&theta)?;
        }
        Ok(())
    }

    /// The optimised variables' names, in the order of [`Self::step_with_slices`]'s gradients.
    pub(crate) fn names(&self) -> impl Iterator<Item = &str> {
        self.slots.iter().map(|s| s.name.as_str())
    }

    /// One update from gradient slices, one per variable in the optimiser's order (f32/f64 CPU
    /// variables of type `T`), plus the gradient `l2 · θ` of the L2 term as
    /// [`Self::step_with_l2`]. One fused pass per variable over θ, m, v and g, which also
    /// returns Σ ½‖θ‖² of the weights before the update (the L2 term's value, unweighted).
    #[cfg(test)]
    pub(crate) fn step_with_slices<T: Real>(&mut self, grads: &[&[T]], l2: f64) -> Result<f64> {
        let sources: Vec<GradSource<'_, T>> = grads.iter().map(|g| GradSource::Slice(g)).collect();
        self.step_with_sources(&sources, l2, 1.0)
    }

    /// [`Self::step_with_slices`] where a gradient may also be made row block by row block
    /// as the pass reaches it ([`GradSource::Rows`]), never written out whole, and every
    /// gradient is scaled by `grad_scale` first ([`Self::clip_scale`]).
    pub(crate) fn step_with_sources<T: Real>(
        &mut self,
        grads: &[GradSource<'_, T>],
        l2: f64,
        grad_scale: f64,
    ) -> Result<f64> {
        if grads.len() != self.slots.len() {
            return Err(VaeError::argument(
                "adam gradients",
                format!("{} slices for {} variables", grads.len(), self.slots.len()),
            ));
        }
        for (s, g) in self.slots.iter().zip(grads) {
            let n = s.var.elem_count();
            let what = match *g {
                GradSource::Slice(g) if g.len() != n => format!("{} values", g.len()),
                GradSource::Rows { row_len, .. } if row_len == 0 || n % row_len != 0 => {
                    format!("rows of {row_len}")
                }
                _ if s.var.dtype() != T::DTYPE_OF => "values".to_string(),
                _ => continue,
            };
            return Err(VaeError::argument(
                "adam gradients",
                format!(
                    "{what} of {:?} for {} ({n} of {:?})",
                    T::DTYPE_OF,
                    s.name,
                    s.var.dtype()
                ),
            ));
        }
        let update = self.next_update(l2, grad_scale);
        let mut half_sq = 0.0;
        for (s, g) in self.slots.iter().zip(grads) {
            half_sq += update.scaled(s.lr_scale).run_on(s, g)?;
        }
        Ok(half_sq)
    }

    /// Copies of the whole state: `adam.m.<var>`, `adam.v.<var>` and `adam.step` (i64 `[1]`).
    pub fn state_tensors(&self) -> Result<Vec<(String, Tensor)>> {
        self.state(true)
    }

    /// [`Self::state_tensors`] without copying the moments: the tensors change with the next
    /// step, so they are only for writing out at once (a large model's moments are not
    /// duplicated in memory to be saved).
    pub fn state_shared(&self) -> Result<Vec<(String, Tensor)>> {
        self.state(false)
    }

    fn state(&self, copy: bool) -> Result<Vec<(String, Tensor)>> {
        let take = |t: &Tensor| if copy { t.copy() } else { Ok(t.clone()) };
        let device = self
            .slots
            .first()
            .map(|s| s.var.device().clone())
            .unwrap_or(candle_core::Device::Cpu);
        let mut out = vec![(STEP.to_owned(), Tensor::new(&[self.step as i64], &device)?)];
        if self.restarted_at > 0 {
            out.push((
                RESTARTED_AT.to_owned(),
                Tensor::new(&[self.restarted_at as i64], &device)?,
            ));
        }
        if self.clip.is_on() {
            out.push((CLIP.to_owned(), Tensor::new(&self.clip.state(), &device)?));
        }
        for s in &self.slots {
            out.push((format!("adam.m.{}", s.name), take(s.m.as_tensor())?));
            out.push((format!("adam.v.{}", s.name), take(s.v.as_tensor())?));
        }
        Ok(out)
    }

    /// Restores a state from [`Self::state_tensors`]. Every name and shape is checked before
    /// anything changes; extra tensors not named `adam.*` are ignored (so a checkpoint can hold
    /// the model's tensors too).
    pub fn load_state(&mut self, tensors: &HashMap<String, Tensor>) -> Result<()> {
        let count = |name: &str| -> Result<Option<u64>> {
            let Some(t) = tensors.get(name) else {
                return Ok(None);
            };
            t.flatten_all()?
                .to_dtype(DType::I64)?
                .to_vec1::<i64>()?
                .first()
                .copied()
                .filter(|&s| s >= 0)
                .map(|s| Some(s as u64))
                .ok_or_else(|| VaeError::argument("adam state", format!("{name} is not a count")))
        };
        let step =
            count(STEP)?.ok_or_else(|| VaeError::argument("adam state", format!("no {STEP}")))?;
        let restarted_at = count(RESTARTED_AT)?;
        if restarted_at.is_some_and(|r| r > step) {
            return Err(VaeError::argument(
                "adam state",
                format!("{RESTARTED_AT} lies after {STEP}"),
            ));
        }
        let mut moments = Vec::with_capacity(self.slots.len());
        for s in &self.slots {
            let get = |kind: &str| -> Result<&Tensor> {
                let name = format!("adam.{kind}.{}", s.name);
                match tensors.get(&name) {
                    Some(t) if t.dims() == s.var.dims() => Ok(t),
                    Some(t) => Err(VaeError::argument(
                        "adam state",
                        format!(
                            "{name} has shape {:?}, the variable {:?}",
                            t.dims(),
                            s.var.dims()
                        ),
                    )),
                    None => Err(VaeError::argument("adam state", format!("no {name}"))),
                }
            };
            moments.push((get("m")?, get("v")?));
        }
        // A state saved with clipping off (or before it existed) starts the mean afresh.
        let clip = match tensors.get(CLIP) {
            Some(t) => {
                let state = t.flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
                Some(self.clip.with_state(&state).ok_or_else(|| {
                    VaeError::argument("adam state", format!("{CLIP} is not a clipping state"))
                })?)
            }
            None => None,
        };
        let known = 1
            + 2 * self.slots.len()
            + usize::from(restarted_at.is_some())
            + usize::from(clip.is_some());
        let ours = tensors.keys().filter(|k| k.starts_with("adam.")).count();
        if ours != known {
            return Err(VaeError::argument(
                "adam state",
                format!("{ours} adam.* tensors for {known} expected (another model's state?)"),
            ));
        }
        for (s, (m, v)) in self.slots.iter().zip(moments) {
            s.m.set(&m.to_dtype(s.var.dtype())?)?;
            s.v.set(&v.to_dtype(s.var.dtype())?)?;
        }
        self.step = step;
        self.restarted_at = restarted_at.unwrap_or(0);
        self.clip = clip.unwrap_or(GradClip::new(self.clip.factor));
        Ok(())
    }
}

#[cfg(test)]
mod tests;
