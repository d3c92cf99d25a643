//! Inference on the engine's buffers: the reconstruction error with z = μ and the batch norms'
//! running statistics, as `MeshVae::rec_error` computes it through candle.

use super::{BnStats, Net, forward_node, with_weights};
use crate::candle::model::MeshVae;
use crate::cpu::{Scalar, f64_of};
use crate::error::Result;
use crate::net::config::FEATURE_CHANNELS;
use crate::train::loss::LossWeights;
use candle_core::Tensor;

impl<T: Scalar> Net<T> {
    /// w_rec · batch mean of Σ (x − x̂)² for features x `[B, V, 9]`, in inference mode. Leaves
    /// the last training step's gradients and batch statistics alone.
    pub fn rec_error(
        &mut self,
        model: &MeshVae,
        x: &Tensor,
        c: Option<&Tensor>,
        weights: &LossWeights,
    ) -> Result<f64> {
        self.check_model(model)?;
        // ε = 0 makes z = μ.
        let eps = Tensor::zeros((x.dim(0)?, self.latent), x.dtype(), x.device())?;
        // The dense weights' gradients are made from h and z when Adam runs
        // (`Net::dense_grad_rows`), so a pending step's h and z are put back afterwards.
        let kept =
            (self.batch > 0).then(|| (self.acts.0[self.enc_out].clone(), self.lat.z.clone()));
        let batch = self.load_inputs(x, c, &eps)?;
        let (vars, names) = (self.vars.clone(), self.names.clone());
        with_weights(&vars, &names, |w| {
            for node in &mut self.enc {
                forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
            }
            self.latent_forward(w, batch);
            for node in &mut self.dec {
                forward_node(node, &mut self.acts, w, batch, BnStats::Running)?;
            }
            Ok(())
        })?;
        if let Some((h, z)) = kept {
            self.acts.put(self.enc_out, h);
            self.lat.z = z;
        }
        let n = self.v0 * FEATURE_CHANNELS * batch;
        let (x_hat, x) = (&self.acts.0[self.x_hat][..n], &self.acts.0[self.x_buf][..n]);
        let sse: f64 = x_hat
            .iter()
            .zip(x)
            .map(|(&h, &x)| {
                let d = f64_of(h - x);
                d * d
            })
            .sum();
        // Rounded to the model's precision, as candle's path reports it.
        Ok(weights.rec * f64_of::<T>(crate::cpu::of(sse / batch as f64)))
    }
}
