//! Gradient clipping against the gradient's own recent size: a step whose gradient norm is
//! more than `factor` times the running mean of the last norms is scaled down to that size.
//!
//! Why relative: the loss of a mesh set sums squared errors over every vertex, so its
//! gradient's norm ranges over orders of magnitude from set to set and over a run (1e6 at the
//! start of a horse-gallop run, 1e5 later); no fixed threshold fits. A blow-up starts with a
//! gradient several times the recent ones (8× in one step on horse-gallop at a rate of 1e-2);
//! scaled down, it moves Adam's moments by no more than an ordinary step does.

use crate::error::{Result, VaeError};
use crate::numerics::host::{HostSlice, with_cpu_values};
use candle_core::{DType, Tensor};

/// The mean's decay per step (about the last 50 steps).
const DECAY: f64 = 0.98;
/// Steps before the first clip: the mean of fewer norms is too young to judge by.
const WARM_STEPS: u64 = 20;

/// The clipping rule and its running mean (kept in the checkpoint: a resumed run clips as the
/// uninterrupted one does).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradClip {
    /// Clip at this many times the running mean (0: never clip).
    pub factor: f64,
    /// The running mean of the norms as clipped, without its bias correction.
    sum: f64,
    /// Norms seen, and how many of them were clipped.
    seen: u64,
    clipped: u64,
}

impl GradClip {
    /// A rule that clips at `factor` times the running mean (0: never).
    pub fn new(factor: f64) -> Self {
        Self {
            factor,
            sum: 0.0,
            seen: 0,
            clipped: 0,
        }
    }

    /// Checks a factor: 0 (off) or a finite factor ≥ 1 (below 1 every step would be clipped).
    /// The error names the setting, `grad_clip`.
    pub fn check_factor(factor: f64) -> Result<()> {
        if factor == 0.0 || (factor.is_finite() && factor >= 1.0) {
            Ok(())
        } else {
            Err(VaeError::argument(
                "grad_clip",
                format!("{factor} is neither 0 (off) nor a factor ≥ 1"),
            ))
        }
    }

    /// Steps clipped so far.
    pub fn clipped(&self) -> u64 {
        self.clipped
    }

    pub fn is_on(&self) -> bool {
        self.factor > 0.0
    }

    /// The running mean of the norms seen (0 before any).
    pub fn mean(&self) -> f64 {
        match self.seen {
            0 => 0.0,
            n => self.sum / (1.0 - DECAY.powi(i32::try_from(n).unwrap_or(i32::MAX))),
        }
    }

    /// The factor to scale this step's gradient by (1 unless it is clipped), given its norm;
    /// counts the norm (as clipped) into the mean. A non-finite norm scales by 0.
    pub fn scale(&mut self, norm: f64) -> f64 {
        if !self.is_on() {
            return 1.0;
        }
        if !norm.is_finite() {
            return 0.0;
        }
        let limit = self.factor * self.mean();
        let scale = if self.seen >= WARM_STEPS && norm > limit {
            limit / norm
        } else {
            1.0
        };
        self.sum = DECAY * self.sum + (1.0 - DECAY) * norm * scale;
        self.seen += 1;
        self.clipped += u64::from(scale < 1.0);
        scale
    }

    /// The state as three numbers, for a checkpoint.
    pub fn state(&self) -> [f64; 3] {
        [self.sum, self.seen as f64, self.clipped as f64]
    }

    /// Restores [`Self::state`]; `None` if it is not a state.
    pub fn with_state(self, state: &[f64]) -> Option<Self> {
        let count = |x: f64| (x >= 0.0 && x.fract() == 0.0).then_some(x as u64);
        match *state {
            [sum, seen, clipped] if sum.is_finite() && sum >= 0.0 => Some(Self {
                sum,
                seen: count(seen)?,
                clipped: count(clipped)?,
                ..self
            }),
            _ => None,
        }
    }
}

/// Σg² of one gradient in f64, for its norm: g widened, squared and summed serially, as
/// candle's `to_dtype(F64)`, `sqr`, `sum_all`, so the same bits; a CPU gradient is read in
/// place, without the widened and squared copies (1.9 GB a step for the mesh VAE's weights).
pub(crate) fn square_sum_f64(g: &Tensor) -> Result<f64> {
    let direct = with_cpu_values(g, |values| match values {
        HostSlice::F32(x) => x.iter().fold(0.0, |s, &a| s + f64::from(a) * f64::from(a)),
        HostSlice::F64(x) => x.iter().fold(0.0, |s, &a| s + a * a),
    });
    match direct {
        Some(sum) => Ok(sum),
        None => Ok(g
            .to_dtype(DType::F64)?
            .sqr()?
            .sum_all()?
            .to_scalar::<f64>()?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_sum_read_in_place_has_candles_bits() {
        // Magnitudes over twelve orders, so that any other summation order shows in the bits.
        let values: Vec<f64> = (0..100_002)
            .map(|i| (i as f64 * 0.7548).sin() * 10f64.powi(i % 13 - 6))
            .collect();
        for dtype in [DType::F32, DType::F64] {
            let g = Tensor::new(values.as_slice(), &candle_core::Device::Cpu)
                .unwrap()
                .to_dtype(dtype)
                .unwrap()
                .reshape((7, 14_286))
                .unwrap();
            let by_candle = |g: &Tensor| {
                let sq = g.to_dtype(DType::F64).unwrap().sqr().unwrap();
                sq.sum_all().unwrap().to_scalar::<f64>().unwrap().to_bits()
            };
            assert_eq!(square_sum_f64(&g).unwrap().to_bits(), by_candle(&g));
            // A strided view takes candle's path.
            let t = g.t().unwrap();
            assert_eq!(square_sum_f64(&t).unwrap().to_bits(), by_candle(&t));
        }
    }

    #[test]
    fn clips_to_the_factor_times_the_running_mean_after_the_warm_up() {
        let mut c = GradClip::new(2.0);
        // A large norm during the warm-up passes.
        for k in 0..WARM_STEPS {
            let norm = if k == 5 { 50.0 } else { 10.0 };
            assert_eq!(c.scale(norm), 1.0);
        }
        // The mean, bias-corrected, against a plain f64 replay of the same rule.
        let mut sum = 0.0;
        for k in 0..WARM_STEPS {
            sum = DECAY * sum + (1.0 - DECAY) * if k == 5 { 50.0 } else { 10.0 };
        }
        let mean = sum / (1.0 - DECAY.powi(WARM_STEPS as i32));
        assert!((c.mean() - mean).abs() < 1e-12 * mean);
        // Below the limit: untouched; above: scaled to the limit, and the mean takes in the
        // clipped norm.
        assert_eq!(c.scale(1.9 * mean), 1.0);
        let before = c.mean();
        let limit = 2.0 * before;
        let s = c.scale(8.0 * before);
        assert!((s * 8.0 * before - limit).abs() < 1e-12 * limit, "{s}");
        let sum = c.state()[0];
        let seen = c.state()[1] as i32;
        assert!((c.mean() - sum / (1.0 - DECAY.powi(seen))).abs() < 1e-12);
        assert!(c.mean() < 1.2 * before, "the spike entered the mean whole");
        assert_eq!(c.clipped(), 1);
        // A non-finite norm is not stepped on; off, nothing is scaled.
        assert_eq!(c.scale(f64::INFINITY), 0.0);
        let mut off = GradClip::new(0.0);
        assert_eq!(off.scale(1e30), 1.0);
    }

    #[test]
    fn its_state_round_trips_and_malformed_ones_are_refused() {
        let mut c = GradClip::new(3.0);
        for k in 0..30 {
            c.scale(1.0 + k as f64);
        }
        let back = GradClip::new(3.0).with_state(&c.state()).unwrap();
        assert_eq!(back, c);
        assert!(GradClip::new(3.0).with_state(&[1.0, 2.0]).is_none());
        assert!(
            GradClip::new(3.0)
                .with_state(&[f64::NAN, 2.0, 0.0])
                .is_none()
        );
        assert!(GradClip::new(3.0).with_state(&[1.0, 2.5, 0.0]).is_none());
    }
}
