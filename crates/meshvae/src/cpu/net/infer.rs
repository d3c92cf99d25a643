//! Inference on the engine's buffers (z = μ where encoding, the batch norms' running
//! statistics), as candle's model computes it in eval mode: the reconstruction error, μ and σ,
//! decoding latent vectors, and reconstructions. None of them disturbs a pending training
//! step's gradients.

use super::latent::Heads;
use super::{BnStats, Inputs, Net, forward_node, host, with_weights};
use crate::cpu::kernels as k;
use crate::cpu::model::EngineModel;
use crate::cpu::{Real, f64_of};
use crate::error::{Result, VaeError};
use crate::net::config::FEATURE_CHANNELS;
use crate::net::loss_weights::LossWeights;
use crate::numerics::host::{HostArray, HostTensor};

impl<T: Real> Net<T> {
    /// w_rec · batch mean of Σ (x − x̂)² for features x `[B, V, 9]`, in inference mode. Leaves
    /// the last training step's gradients and batch statistics alone.
    pub fn rec_error(
        &mut self,
        model: &dyn EngineModel,
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
    pub fn encode(
        &mut self,
        model: &dyn EngineModel,
        inputs: Inputs<'_>,
    ) -> Result<(HostTensor, HostTensor)> {
        let batch = self.infer(model, inputs, Pass::Encoder)?;
        let n = batch * self.latent;
        let tensor = |v: &[T]| HostTensor {
            data: T::host_vec(v.to_vec()),
            dims: vec![batch, self.latent],
        };
        Ok((tensor(&self.lat.mu[..n]), tensor(&self.lat.sigma[..n])))
    }

    /// x̂ `[B, V, 9]` = decode(μ(x, c), c).
    pub fn reconstruct(
        &mut self,
        model: &dyn EngineModel,
        inputs: Inputs<'_>,
    ) -> Result<HostTensor> {
        let batch = self.infer(model, inputs, Pass::Whole)?;
        Ok(self.output(batch))
    }

    /// x̂ `[B, V, 9]` from latent vectors z `[B, latent]` (labels c `[B, L]` for a conditional
    /// model).
    pub fn decode(
        &mut self,
        model: &dyn EngineModel,
        z: HostArray<'_>,
        c: Option<HostArray<'_>>,
    ) -> Result<HostTensor> {
        self.check_model(model)?;
        let batch = z.dims.first().copied().unwrap_or(0);
        let zd = host::<T>(z.data, "z")?;
        if z.dims != [batch, self.latent]
            || batch == 0
            || batch > self.max_batch
            || zd.len() != batch * self.latent
        {
            return Err(VaeError::shape(
                "Engine::decode",
                format!(
                    "latent vectors of shape {:?}; expected [1 ..= {}, {}]",
                    z.dims, self.max_batch, self.latent
                ),
            ));
        }
        self.load_running_stats(model)?;
        let kept = self.keep();
        self.load_labels(c, batch)?;
        self.lat.z[..zd.len()].copy_from_slice(zd);
        with_weights(model, |w| {
            self.dense_decode(w, batch);
            for node in &mut self.dec {
                forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
            }
            Ok(())
        })?;
        let out = self.output(batch);
        self.restore(kept);
        Ok(out)
    }

    /// Runs the encoder (and with [`Pass::Whole`] the decoder, z = μ) on x in inference mode;
    /// returns B.
    fn infer(&mut self, model: &dyn EngineModel, inputs: Inputs<'_>, pass: Pass) -> Result<usize> {
        self.check_model(model)?;
        self.load_running_stats(model)?;
        let kept = self.keep();
        // ε = 0 makes z = μ.
        let batch = self.load_inputs(inputs, None)?;
        let done = with_weights(model, |w| {
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
    fn output(&self, batch: usize) -> HostTensor {
        let n = self.v0 * FEATURE_CHANNELS * batch;
        let mut out = vec![crate::cpu::of::<T>(0.0); n];
        k::from_vcb(
            &self.acts.0[self.x_hat][..n],
            &mut out,
            (batch, self.v0, FEATURE_CHANNELS),
            self.order.as_deref(),
        );
        HostTensor {
            data: T::host_vec(out),
            dims: vec![batch, self.v0, FEATURE_CHANNELS],
        }
    }
}

/// How far [`Net::infer`] runs.
#[derive(Clone, Copy, PartialEq)]
enum Pass {
    Encoder,
    Whole,
}
