//! [`Elementwise`]: the arithmetic the shared formulas (`latent.rs`, `batch_norm.rs`) are
//! written in, so that each is written once and evaluated by every executor: on scalars by the
//! CPU engine, on tensors (with autograd) by candle (`candle/elementwise.rs`). Each method is
//! one operation per element, in the same order in both.

use crate::numerics::real::Real;
use std::convert::Infallible;

/// The result of an element-wise operation.
pub type Out<X> = Result<X, <X as Elementwise>::Error>;

/// Element-wise arithmetic on a value or a tensor of values.
pub trait Elementwise: Sized {
    /// What can fail: nothing for scalars ([`Infallible`], so `let Ok(v) = …;` unwraps them),
    /// a tensor library's error for tensors.
    type Error;
    fn add(&self, other: &Self) -> Out<Self>;
    fn sub(&self, other: &Self) -> Out<Self>;
    /// x + c.
    fn add_scalar(&self, c: f64) -> Out<Self>;
    /// x · c.
    fn scale(&self, c: f64) -> Out<Self>;
    /// x².
    fn sqr(&self) -> Out<Self>;
    fn sqrt(&self) -> Out<Self>;
    /// 1 / x.
    fn recip(&self) -> Out<Self>;
    /// The natural logarithm.
    fn ln(&self) -> Out<Self>;
}

impl<T: Real> Elementwise for T {
    type Error = Infallible;
    fn add(&self, other: &Self) -> Out<Self> {
        Ok(*self + *other)
    }
    fn sub(&self, other: &Self) -> Out<Self> {
        Ok(*self - *other)
    }
    fn add_scalar(&self, c: f64) -> Out<Self> {
        Ok(*self + T::of(c))
    }
    fn scale(&self, c: f64) -> Out<Self> {
        Ok(*self * T::of(c))
    }
    fn sqr(&self) -> Out<Self> {
        Ok(*self * *self)
    }
    fn sqrt(&self) -> Out<Self> {
        Ok(Real::sqrt(*self))
    }
    fn recip(&self) -> Out<Self> {
        Ok(T::of(1.0) / *self)
    }
    fn ln(&self) -> Out<Self> {
        Ok(T::of(T::as_f64(*self).ln()))
    }
}
