//! Where a run's time goes, phase by phase (`run.json`'s `phases`), so that a slow run can be
//! told from a slow step without a profiler.

use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Seconds spent in each phase of the epochs this process trained (a resumed run counts from
/// its resume).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseSeconds {
    /// Gathering each batch's features and drawing its noise.
    pub batches: f64,
    /// Forward pass, loss and backward pass of the training steps.
    pub forward_backward: f64,
    /// Adam's updates (on the engine this includes forming the dense heads' weight gradients,
    /// which it never stores whole).
    pub adam: f64,
    /// The validation loss after every epoch.
    pub validation: f64,
    /// The test loss, measured every few steps.
    pub test: f64,
    /// Checking the weights are finite, keeping the best ones, and writing the log, the
    /// checkpoint and `run.json`.
    pub bookkeeping: f64,
}

impl PhaseSeconds {
    /// Runs `f`, adding its wall time to the phase `slot` selects.
    pub(crate) fn time<T>(&mut self, slot: fn(&mut Self) -> &mut f64, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        *slot(self) += t.elapsed().as_secs_f64();
        out
    }

    pub fn total(&self) -> f64 {
        self.batches
            + self.forward_backward
            + self.adam
            + self.validation
            + self.test
            + self.bookkeeping
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_adds_to_the_chosen_phase_only() {
        let mut p = PhaseSeconds::default();
        let v = p.time(
            |p| &mut p.adam,
            || {
                std::thread::sleep(std::time::Duration::from_millis(5));
                7
            },
        );
        assert_eq!(v, 7);
        assert!(p.adam >= 0.005, "{p:?}");
        assert_eq!(p.total(), p.adam);
        p.time(|p| &mut p.test, || ());
        assert!(p.total() >= p.adam && p.batches == 0.0);
    }
}
