//! The latent side of the engine's network: the μ and σ heads, z = μ + σ ε and the KL term,
//! the decoder's dense layer (tied to the μ head; labels for a conditional model), and their
//! backward pass, whose dense weights' gradients are made row block by row block inside Adam's
//! pass.

use super::Net;
use crate::cpu::gemm::{Mat, matmul, matmul_serial};
use crate::cpu::kernels as k;
use crate::cpu::{Real, f64_of, of};
use crate::net::latent::{kl_unit, kl_unit_dsigma, sigma_of_sigmoid, sigmoid};
use crate::net::loss_weights::LossWeights;

/// Which dense heads [`Net::heads_forward`] evaluates.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum Heads {
    Both,
    MeanOnly,
}

impl<T: Real> Net<T> {
    /// μ, σ, z and the decoder's dense layer; returns the batch mean of the KL divergence.
    pub(super) fn latent_forward(&mut self, w: &[&[T]], batch: usize) -> f64 {
        let kl = self.heads_forward(w, batch, Heads::Both);
        self.dense_decode(w, batch);
        kl
    }

    /// μ, σ and z = μ + σ ε from the encoder's output; returns the batch mean of the KL
    /// divergence. With [`Heads::MeanOnly`] (inference with ε = 0, where z = μ) the σ head is
    /// skipped and σ = 1: a third of the dense weights' traffic in a validation pass.
    pub(super) fn heads_forward(&mut self, w: &[&[T]], batch: usize, heads: Heads) -> f64 {
        let (l, kf) = (self.latent, self.flat);
        let d = &self.dense;
        let h = &self.acts.0[self.enc_out][..kf * batch];
        let lat = &mut self.lat;
        let h_rows = Mat::col_major(h, batch);
        let (wm, ws) = (
            Mat::row_major(w[d.w_mu], l),
            Mat::row_major(w[d.w_sigma], l),
        );
        matmul(&mut lat.mu, (l, 1), h_rows, wm, (batch, l, kf), false);
        // The pre-activation of σ goes into `sig` first.
        match heads {
            Heads::Both => matmul(&mut lat.sig, (l, 1), h_rows, ws, (batch, l, kf), false),
            Heads::MeanOnly => lat.sig[..batch * l].fill(of(0.0)),
        }
        // A conditional model adds c·W_c to both pre-activations.
        if let Some(labels) = d.labels {
            let c = Mat::row_major(&self.cond[..batch * labels.count], labels.count);
            let dims = (batch, l, labels.count);
            matmul(
                &mut lat.mu,
                (l, 1),
                c,
                Mat::row_major(w[labels.mu], l),
                dims,
                true,
            );
            if heads == Heads::Both {
                matmul(
                    &mut lat.sig,
                    (l, 1),
                    c,
                    Mat::row_major(w[labels.sigma], l),
                    dims,
                    true,
                );
            }
        }
        let mut kl = 0.0;
        for i in 0..batch * l {
            let j = i % l;
            let mu = lat.mu[i] + w[d.b_mu][j];
            let s = match heads {
                Heads::Both => f64_of(lat.sig[i] + w[d.b_sigma][j]),
                // sigmoid(s) = 1/2: σ = 1.
                Heads::MeanOnly => 0.0,
            };
            let sig: T = of(sigmoid(s));
            let Ok(sigma) = sigma_of_sigmoid(&sig);
            lat.mu[i] = mu;
            lat.sig[i] = sig;
            lat.sigma[i] = sigma;
            lat.z[i] = mu + sigma * lat.eps[i];
            let (m, sg) = (f64_of(mu), f64_of(sigma));
            let Ok(unit) = kl_unit(&m, &(sg * sg));
            kl += unit;
        }
        0.5 * kl / batch as f64
    }

    /// The decoder's dense layer from z: [K, B] = W_μ zᵀ + b_dec (+ W_dcᵀ cᵀ).
    pub(super) fn dense_decode(&mut self, w: &[&[T]], batch: usize) {
        let (l, kf) = (self.latent, self.flat);
        let d = &self.dense;
        let lat = &self.lat;
        let wm = Mat::row_major(w[d.w_mu], l);
        let dec = &mut self.acts.0[self.dec_in][..kf * batch];
        let zt = Mat::col_major(&lat.z[..batch * l], l);
        matmul(dec, (batch, 1), wm, zt, (kf, batch, l), false);
        if let Some(labels) = d.labels {
            // + W_dcᵀ cᵀ: [K, L] · [L, B].
            let n = labels.count;
            let w_dc = Mat::col_major(w[labels.dec], kf);
            let ct = Mat::col_major(&self.cond[..batch * n], n);
            matmul(dec, (batch, 1), w_dc, ct, (kf, batch, n), true);
        }
        k::add_row_bias(dec, w[d.b_dec], batch);
    }

    /// From ∂L/∂(dense output) in `ga` to the dense biases' gradients and ∂L/∂h in `gb`. The
    /// dense weights' gradients are left to [`Self::dense_grad_rows`]: what they need (h, the
    /// decoder's output gradient, z, ∂L/∂μ, ∂L/∂s) stays in the buffers.
    pub(super) fn latent_backward(&mut self, w: &[&[T]], batch: usize, weights: &LossWeights) {
        let (l, kf) = (self.latent, self.flat);
        let d = &self.dense;
        let g = &self.ga[..kf * batch];
        k::row_sums(g, batch, &mut self.grads[d.b_dec]);
        self.dec_grad[..kf * batch].copy_from_slice(g);
        let lat = &mut self.lat;
        let (wm, ws) = (
            Mat::row_major(w[d.w_mu], l),
            Mat::row_major(w[d.w_sigma], l),
        );
        // dz = g W_μ (the tied use).
        matmul(
            &mut lat.dz,
            (l, 1),
            Mat::col_major(g, batch),
            wm,
            (batch, l, kf),
            false,
        );
        // Through z = μ + σ ε, the KL term and σ = √(2·sigmoid(s)).
        let c = weights.kl / batch as f64;
        for i in 0..batch * l {
            let (mu, sigma, sig) = (f64_of(lat.mu[i]), f64_of(lat.sigma[i]), f64_of(lat.sig[i]));
            let dz = f64_of(lat.dz[i]);
            let dmu = dz + c * mu;
            let dsigma = dz * f64_of(lat.eps[i]) + c * kl_unit_dsigma(sigma);
            lat.dmu[i] = of(dmu);
            lat.ds[i] = of(dsigma / sigma * sig * (1.0 - sig));
        }
        for (bias, src) in [(d.b_mu, &lat.dmu), (d.b_sigma, &lat.ds)] {
            for j in 0..l {
                let s: f64 = (0..batch).map(|b| f64_of(src[b * l + j])).sum();
                self.grads[bias][j] = of(s);
            }
        }
        let (dmu, ds) = (&lat.dmu[..batch * l], &lat.ds[..batch * l]);
        if let Some(labels) = d.labels {
            // dW_c = cᵀ (∂L/∂μ), cᵀ (∂L/∂s); dW_dc = cᵀ gᵀ.
            let n = labels.count;
            let ct = Mat::col_major(&self.cond[..batch * n], n);
            let dims = (n, l, batch);
            let grads = &mut self.grads;
            for (var, grad) in [(labels.mu, dmu), (labels.sigma, ds)] {
                let grad = Mat::row_major(grad, l);
                matmul(&mut grads[var], (l, 1), ct, grad, dims, false);
            }
            let gt = Mat::col_major(g, batch);
            matmul(
                &mut grads[labels.dec],
                (kf, 1),
                ct,
                gt,
                (n, kf, batch),
                false,
            );
        }
        let gb = &mut self.gb[..kf * batch];
        let (dmu_cols, ds_cols) = (Mat::col_major(dmu, l), Mat::col_major(ds, l));
        matmul(gb, (batch, 1), wm, dmu_cols, (kf, batch, l), false);
        matmul(gb, (batch, 1), ws, ds_cols, (kf, batch, l), true);
    }

    /// ‖dW_μ‖² + ‖dW_σ‖² of the last step without forming them. Both are sums over the batch
    /// of outer products p_b q_bᵀ, so ‖Σ_b p_b q_bᵀ‖² = Σ_{b,b'} (p_b·p_b')(q_b·q_b'): batch ×
    /// batch Gram matrices of g, h (over V_L·C rows) and of z, ∂L/∂μ, ∂L/∂s (over the latent
    /// units), a few MFLOP where forming the gradients takes about 1 GFLOP.
    pub(super) fn dense_grad_sq(&self) -> f64 {
        let (l, batch, kf) = (self.latent, self.batch, self.flat);
        let lat = &self.lat;
        let h = &self.acts.0[self.enc_out][..kf * batch];
        let g = &self.dec_grad[..kf * batch];
        // [B, V_L·C] · [V_L·C, B] from the row-major [V_L·C, B] buffers.
        let gram = |a: &[T], b: &[T]| {
            let mut out = vec![of(0.0); batch * batch];
            let (at, b) = (Mat::col_major(a, batch), Mat::row_major(b, batch));
            matmul(&mut out, (batch, 1), at, b, (batch, batch, kf), false);
            out
        };
        let (hh, gg, gh) = (gram(h, h), gram(g, g), gram(g, h));
        // The same over the latent units of the row-major [B, L] buffers, in f64.
        let latent_gram = |a: &[T], b: &[T]| {
            let mut out = vec![0.0f64; batch * batch];
            for (i, o) in out.iter_mut().enumerate() {
                let (x, y) = (&a[(i / batch) * l..][..l], &b[(i % batch) * l..][..l]);
                *o = x.iter().zip(y).map(|(&p, &q)| f64_of(p) * f64_of(q)).sum();
            }
            out
        };
        let (z, dmu, ds) = (
            &lat.z[..batch * l],
            &lat.dmu[..batch * l],
            &lat.ds[..batch * l],
        );
        let (zz, mm, ss, zm) = (
            latent_gram(z, z),
            latent_gram(dmu, dmu),
            latent_gram(ds, ds),
            latent_gram(z, dmu),
        );
        let dot =
            |p: &[T], q: &[f64]| -> f64 { p.iter().zip(q).map(|(&a, &b)| f64_of(a) * b).sum() };
        // dW_μ = g zᵀ + h (∂L/∂μ)ᵀ: both squares and twice the cross term; dW_σ = h (∂L/∂s)ᵀ.
        dot(&gg, &zz) + dot(&hh, &mm) + 2.0 * dot(&gh, &zm) + dot(&hh, &ss)
    }

    /// Rows `first..` of the last step's gradient of the dense weight `var` (`w_mu` or
    /// `w_sigma`, row-major `[V_L·C, latent]`) into `out` (whole rows), on this thread:
    /// dW_μ = g zᵀ + h (∂L/∂μ)ᵀ (the decoder's tied use, then the encoder's), dW_σ = h (∂L/∂s)ᵀ.
    pub(super) fn dense_grad_rows(&self, var: usize, first: usize, out: &mut [T]) {
        let (l, batch) = (self.latent, self.batch);
        let rows = out.len() / l;
        let lat = &self.lat;
        let span = first * batch..(first + rows) * batch;
        fn block<T>(buf: &[T], span: std::ops::Range<usize>, batch: usize) -> Mat<'_, T> {
            Mat::row_major(&buf[span], batch)
        }
        let h = block(&self.acts.0[self.enc_out], span.clone(), batch);
        let dims = (rows, l, batch);
        let (dmu, ds) = (&lat.dmu[..batch * l], &lat.ds[..batch * l]);
        if var == self.dense.w_mu {
            let z = Mat::row_major(&lat.z[..batch * l], l);
            matmul_serial(
                out,
                (l, 1),
                block(&self.dec_grad, span, batch),
                z,
                dims,
                false,
            );
            matmul_serial(out, (l, 1), h, Mat::row_major(dmu, l), dims, true);
        } else {
            matmul_serial(out, (l, 1), h, Mat::row_major(ds, l), dims, false);
        }
    }
}
