//! [`Elementwise`] on candle tensors: the shared formulas (`net/latent.rs`, `net/batch_norm.rs`)
//! as candle ops, so that autograd differentiates them. `x + c` and `x · c` are candle's
//! affine op, as `tensor + f64` and `tensor * f64` are.

use crate::net::elementwise::{Elementwise, Out};
use candle_core::Tensor;

impl Elementwise for Tensor {
    type Error = candle_core::Error;
    fn add(&self, other: &Self) -> Out<Self> {
        Tensor::add(self, other)
    }
    fn sub(&self, other: &Self) -> Out<Self> {
        Tensor::sub(self, other)
    }
    fn add_scalar(&self, c: f64) -> Out<Self> {
        self.affine(1.0, c)
    }
    fn scale(&self, c: f64) -> Out<Self> {
        self.affine(c, 0.0)
    }
    fn sqr(&self) -> Out<Self> {
        Tensor::sqr(self)
    }
    fn sqrt(&self) -> Out<Self> {
        Tensor::sqrt(self)
    }
    fn recip(&self) -> Out<Self> {
        Tensor::recip(self)
    }
    fn ln(&self) -> Out<Self> {
        self.log()
    }
}

#[cfg(test)]
mod tests {
    use crate::net::batch_norm::{inv_std, running_update};
    use crate::net::latent::{kl_unit, sigma_of_sigmoid};
    use candle_core::{Device, Tensor};

    /// The shared formulas on f64 tensors give the scalars' bits.
    #[test]
    fn tensors_and_scalars_agree_to_the_bit() {
        let a = [0.3f64, -1.7, 2.5, 1e-5];
        let b = [0.9f64, 0.01, 3.0, 1e-9];
        let t = |v: &[f64]| Tensor::new(v, &Device::Cpu).unwrap();
        let (ta, tb) = (t(&a), t(&b));
        let get = |x: Tensor| x.to_vec1::<f64>().unwrap();
        let kl = get(kl_unit(&ta, &tb).unwrap());
        let sigma = get(sigma_of_sigmoid(&tb).unwrap());
        let running = get(running_update(&ta, &tb).unwrap());
        let factor = get(inv_std(&tb).unwrap());
        for i in 0..a.len() {
            assert_eq!(kl[i], kl_unit(&a[i], &b[i]).unwrap(), "kl {i}");
            assert_eq!(sigma[i], sigma_of_sigmoid(&b[i]).unwrap(), "sigma {i}");
            assert_eq!(
                running[i],
                running_update(&a[i], &b[i]).unwrap(),
                "running {i}"
            );
            assert_eq!(factor[i], inv_std(&b[i]).unwrap(), "inv_std {i}");
        }
    }
}
