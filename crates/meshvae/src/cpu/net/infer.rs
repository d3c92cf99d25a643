//! Inference on the engine's buffers (z = μ where encoding, the batch norms' running
//! statistics), as candle's model computes it in eval mode: the reconstruction error, μ and σ,
//! decoding latent vectors, and reconstructions. None of them disturbs a pending training
//! step's gradients.

use super::latent::Heads;
use super::{BnStats, Inputs, Net, cpu_slice, forward_node, with_weights};
use crate::candle::model::MeshVae;
use crate::cpu::kernels as k;
use crate::cpu::{Real, f64_of};
use crate::error::{Result, VaeError};
use crate::net::config::FEATURE_CHANNELS;
use crate::net::loss_weights::LossWeights;
use candle_core::Tensor;

impl<T: Real> Net<T> {
    /// w_rec · batch mean of Σ (x − x̂)² for features x `[B, V, 9]`, in inference mode. Leaves
    /// the last training step's gradients and batch statistics alone.
    pub fn rec_error(
        &mut self,
        model: &MeshVae,
        inputs: Inputs<'_>,
        w: &LossWeights,
    ) -> Result<f64> {
        let batch = self.infer(model, inputs, Pass::Whole)?;
        let n = self.v0 * FEATURE_CHANNELS * batch;
        // The training loss's kernel; its gradient output goes to the backward work buffer,
        // which a pending step no longer needs.
        let (x_hat, x) = (&self.acts.0[self.x_hat][..n], &self.acts.0[self.x_buf][..n]);
        let sse = k::sse_grad(x_hat, x, &mut self.work[..n], 0.0);
        // Rounded to the model's precision, as candle's path reports it.
        Ok(w.rec * f64_of::<T>(crate::cpu::of(sse / batch as f64)))
    }

    /// μ and σ `[B, latent]` of features x `[B, V, 9]` (labels c `[B, L]` for a conditional
    /// model), in the model's dtype.
    pub fn encode(&mut self, model: &MeshVae, inputs: Inputs<'_>) -> Result<(Tensor, Tensor)> {
        let batch = self.infer(model, inputs, Pass::Encoder)?;
        let n = batch * self.latent;
        let tensor = |v: &[T]| -> Result<Tensor> {
            Ok(Tensor::from_slice(
                v,
                (batch, self.latent),
                inputs.x.device(),
            )?)
        };
        Ok((tensor(&self.lat.mu[..n])?, tensor(&self.lat.sigma[..n])?))
    }

    /// x̂ `[B, V, 9]` = decode(μ(x, c), c).
    pub fn reconstruct(&mut self, model: &MeshVae, inputs: Inputs<'_>) -> Result<Tensor> {
        let batch = self.infer(model, inputs, Pass::Whole)?;
        self.output(batch, inputs.x.device())
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]` (labels c `[B, L]` for a conditional
    /// model).
    pub fn decode(&mut self, model: &MeshVae, z: &Tensor, c: Option<&Tensor>) -> Result<Tensor> {
        self.check_model(model)?;
        let batch = z.dim(0)?;
        if z.dims() != [batch, self.latent] || batch == 0 || batch > self.max_batch {
            return Err(VaeError::shape(
                "Engine::decode",
                format!(
                    "latent vectors of shape {:?}; expected [1 ..= {}, {}]",
                    z.dims(),
                    self.max_batch,
                    self.latent
                ),
            ));
        }
        let kept = self.keep();
        self.load_labels(c, batch)?;
        let z = z.contiguous()?;
        {
            let (zs, zl) = z.storage_and_layout();
            let zd = cpu_slice::<T>(&zs, zl, "z")?;
            self.lat.z[..zd.len()].copy_from_slice(zd);
        }
        let (vars, names) = (self.vars.clone(), self.names.clone());
        with_weights(&vars, &names, |w| {
            self.dense_decode(w, batch);
            for node in &mut self.dec {
                forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
            }
            Ok(())
        })?;
        let out = self.output(batch, z.device());
        self.restore(kept);
        out
    }

    /// Runs the encoder (and with [`Pass::Whole`] the decoder, z = μ) on x in inference mode;
    /// returns B.
    fn infer(&mut self, model: &MeshVae, inputs: Inputs<'_>, pass: Pass) -> Result<usize> {
        self.check_model(model)?;
        // ε = 0 makes z = μ.
        let x = inputs.x;
        let eps = Tensor::zeros((x.dim(0)?, self.latent), x.dtype(), x.device())?;
        let kept = self.keep();
        let batch = self.load_inputs(inputs, &eps)?;
        let (vars, names) = (self.vars.clone(), self.names.clone());
        let done = with_weights(&vars, &names, |w| {
            for node in &mut self.enc {
                forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
            }
            let heads = match pass {
                Pass::Encoder => Heads::Both,
                // ε = 0: z = μ whatever σ is.
                Pass::Whole => Heads::MeanOnly,
            };
            self.heads_forward(w, batch, heads);
            if pass == Pass::Whole {
                self.dense_decode(w, batch);
                for node in &mut self.dec {
                    forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
                }
            }
            Ok(())
        });
        self.restore(kept);
        done.map(|()| batch)
    }

    /// What a pending training step still needs from the buffers inference overwrites: the
    /// dense weights' gradients are made from h and z when Adam runs (`Net::dense_grad_rows`).
    fn keep(&self) -> Option<(Vec<T>, Vec<T>)> {
        (self.batch > 0).then(|| (self.acts.0[self.enc_out].clone(), self.lat.z.clone()))
    }

    fn restore(&mut self, kept: Option<(Vec<T>, Vec<T>)>) {
        if let Some((h, z)) = kept {
            self.acts.put(self.enc_out, h);
            self.lat.z = z;
        }
    }

    /// The decoder's output as `[B, V, 9]` in the template's vertex order.
    fn output(&self, batch: usize, device: &candle_core::Device) -> Result<Tensor> {
        let n = self.v0 * FEATURE_CHANNELS * batch;
        let mut out = vec![crate::cpu::of::<T>(0.0); n];
        k::from_vcb(
            &self.acts.0[self.x_hat][..n],
            &mut out,
            (batch, self.v0, FEATURE_CHANNELS),
            self.order.as_deref(),
        );
        Ok(Tensor::from_vec(
            out,
            (batch, self.v0, FEATURE_CHANNELS),
            device,
        )?)
    }
}

/// How far [`Net::infer`] runs.
#[derive(Clone, Copy, PartialEq)]
enum Pass {
    Encoder,
    Whole,
}
