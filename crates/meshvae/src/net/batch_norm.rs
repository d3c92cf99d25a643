//! Batch norm's statistics, the one place every executor takes them from (the authors'
//! values): ε, the running averages' decay and update, and the normalising factor, written on
//! [`Elementwise`] values (scalars in the engine, tensors in candle). The batch's own moments
//! (mean and biased variance per channel over the batch and vertex axes, summed in f64) are
//! taken in each executor's layout: `cpu/kernels.rs` over `[V, C, B]`, candle over `[B·V, C]`.

use super::elementwise::{Elementwise, Out};

/// ε added to the variance.
pub const EPS: f64 = 1e-5;
/// Decay of the running statistics: r ← DECAY·r + (1 − DECAY)·batch.
pub const DECAY: f64 = 0.9;

/// A running statistic after a training batch: DECAY·r + (1 − DECAY)·batch.
#[inline]
pub fn running_update<X: Elementwise>(running: &X, batch: &X) -> Out<X> {
    running.scale(DECAY)?.add(&batch.scale(1.0 - DECAY)?)
}

/// 1 / √(var + ε): what a channel of variance `var` is multiplied by.
#[inline]
pub fn inv_std<X: Elementwise>(var: &X) -> Out<X> {
    var.add_scalar(EPS)?.sqrt()?.recip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_statistics_move_a_tenth_of_the_way() {
        let next: f64 = running_update(&1.0, &3.0).unwrap();
        assert!((next - 1.2).abs() < 1e-15, "{next}");
        let factor: f64 = inv_std(&(4.0 - EPS)).unwrap();
        assert!((factor - 0.5).abs() < 1e-15, "{factor}");
    }
}
