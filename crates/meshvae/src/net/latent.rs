//! The latent layer's formulas, the one place every executor takes them from: the KL term of a
//! unit against N(0, I) and its derivative in σ, with the ε the authors add to σ² inside the
//! log. (σ itself is √(2·sigmoid(s)), the authors' σ head, computed where each executor keeps
//! its activations.)

/// ε in log(ε + σ²) (the authors' 1e-8): keeps the log finite where σ underflows.
pub const KL_VAR_EPS: f64 = 1e-8;

/// Twice the KL divergence of N(μ, σ²) from N(0, 1), with `var` = σ²: μ² + σ² − log(ε + σ²) − 1.
#[inline]
pub fn kl_unit(mu: f64, var: f64) -> f64 {
    mu * mu + var - (var + KL_VAR_EPS).ln() - 1.0
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
            let f = |s: f64| kl_unit(0.7, s * s);
            let fd = (f(sigma + h) - f(sigma - h)) / (2.0 * h);
            assert!((0.5 * fd - kl_unit_dsigma(sigma)).abs() < 1e-8, "{sigma}");
        }
        // At μ = 0, σ = 1 the posterior is the prior: no divergence (up to ε).
        assert!(kl_unit(0.0, 1.0).abs() < 1e-7);
    }
}
