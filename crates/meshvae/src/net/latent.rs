//! The latent layer's formulas, the one place every executor takes them from: the authors' σ
//! head, the KL term of a unit against N(0, I) and its derivative in σ, with the ε the authors
//! add to σ² inside the log. Written on [`Elementwise`] values: the engine evaluates them on
//! scalars, candle on tensors (its autograd derives their gradients; the engine's backward pass
//! uses [`kl_unit_dsigma`]).

use super::elementwise::{Elementwise, Out};

/// ε in log(ε + σ²) (the authors' 1e-8): keeps the log finite where σ underflows.
pub const KL_VAR_EPS: f64 = 1e-8;

/// The logistic function 1 / (1 + e⁻ˢ), in f64 (the engine's; candle uses its own kernel).
#[inline]
pub fn sigmoid(s: f64) -> f64 {
    1.0 / (1.0 + (-s).exp())
}

/// σ = √(2·sigmoid(s)) ∈ (0, √2) from sigmoid(s) of the σ head's pre-activation s (the
/// authors' form, for every VAE here).
#[inline]
pub fn sigma_of_sigmoid<X: Elementwise>(sig: &X) -> Out<X> {
    sig.scale(2.0)?.sqrt()
}

/// Twice the KL divergence of N(μ, σ²) from N(0, 1), with `var` = σ²: μ² + σ² − log(ε + σ²) − 1.
#[inline]
pub fn kl_unit<X: Elementwise>(mu: &X, var: &X) -> Out<X> {
    mu.sqr()?
        .add(var)?
        .sub(&var.add_scalar(KL_VAR_EPS)?.ln()?)?
        .add_scalar(-1.0)
}

/// ½ ∂[`kl_unit`]/∂σ = σ − σ / (σ² + ε).
#[inline]
pub fn kl_unit_dsigma(sigma: f64) -> f64 {
    sigma - sigma / (sigma * sigma + KL_VAR_EPS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_derivative_matches_finite_differences() {
        for sigma in [0.3, 1.0, 1.3] {
            let h = 1e-6;
            let f = |s: f64| kl_unit(&0.7, &(s * s)).unwrap();
            let fd = (f(sigma + h) - f(sigma - h)) / (2.0 * h);
            assert!((0.5 * fd - kl_unit_dsigma(sigma)).abs() < 1e-8, "{sigma}");
        }
        // At μ = 0, σ = 1 the posterior is the prior: no divergence (up to ε).
        assert!(kl_unit(&0.0f64, &1.0).unwrap().abs() < 1e-7);
        assert_eq!(sigma_of_sigmoid(&sigmoid(0.0)).unwrap(), 1.0f64);
    }
}
