//! The learning-rate schedule and the stopping rule. By default a linear warm-up, then a half
//! cosine down to 1/32 of the rate, and training stops — *converged* — once the validation loss
//! has gone `patience` optimizer steps without a new best after the decay. Without a decay the
//! rate is cut whenever the validation loss has not reached a new best for a while (reduce on
//! plateau), and the run stops `patience` steps after its best.
//!
//! Every length is in optimizer steps, not epochs, so that a set of 20 meshes (one step per
//! epoch) and one of 2,000 get the same number of updates. A new best must be lower than the
//! previous best by the fraction `min_improvement`, so that noise in the last digits does not
//! keep a finished run going.

use crate::error::{Result, VaeError};
use serde::{Deserialize, Serialize};
use std::fmt;

/// How the learning rate changes and when training stops on its own (saved with the model).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// The rate rises linearly from a tenth of `lr` to `lr` over this many steps (0: none).
    pub warmup_steps: usize,
    /// Multiply the rate by `lr_factor` after this many steps without a new best (0: the rate
    /// stays constant after the warm-up).
    pub lr_patience: usize,
    pub lr_factor: f64,
    /// The rate never falls below `lr · min_lr_ratio`.
    pub min_lr_ratio: f64,
    /// Stop after this many steps without a new best validation loss (0: never; the run uses
    /// its whole budget).
    pub patience: usize,
    /// A new best must lie below the previous best by this fraction of it.
    pub min_improvement: f64,
    /// The cuts and the stop look at an exponential moving average of the validation loss over
    /// about this many steps instead of the loss itself (0: the loss itself). A loss as noisy
    /// as that of two validation meshes otherwise keeps reaching "new bests" by chance on a
    /// plateau, and the rate stays too high for too long. (The checkpoint is still the one
    /// with the lowest loss itself.)
    #[serde(default)]
    pub smoothing_steps: usize,
    /// After the warm-up the rate falls along a half cosine from `lr` to `lr · min_lr_ratio`
    /// over this many steps, then stays there (0: no decay; the rate is cut on plateaus
    /// instead). With a decay the plateau cuts are off and the run cannot stop before the
    /// decay ends: it then stops, converged, once `patience` steps pass without a new best.
    /// Models saved before it read as 0.
    #[serde(default)]
    pub decay_steps: usize,
    /// Measure the validation loss after an epoch only once this many optimizer steps have
    /// passed since it was last measured (and after the last epoch); 0 or 1: after every
    /// epoch. Where an epoch is one step (a set of 20 meshes), the validation pass and the
    /// bookkeeping it triggers (the finite-weight check, the copy of a new best) cost a
    /// quarter of the step; every length above counts steps, so looking every 10 steps
    /// changes when the run notices a best by at most 10 steps. A split without validation
    /// meshes looks at the training loss after every epoch. Models saved before it read as 0.
    #[serde(default)]
    pub validate_every_steps: usize,
}

impl Default for Schedule {
    /// [`Schedule::cosine`].
    fn default() -> Self {
        Self::cosine()
    }
}

impl Schedule {
    /// Reduce on plateau, the default until the cosine schedule replaced it: the rate is
    /// halved after 400 steps without a new best (at most five times), and a run stops 1,500
    /// steps after its best (`meshvae train --warmup 0 --decay 0 --lr-patience 400 --patience
    /// 1500 --min-improvement 0.001 --validate-every 1`). On horse-gallop it took 4,500–6,500
    /// steps, about a third of them after the best.
    pub fn plateau() -> Self {
        Self {
            warmup_steps: 0,
            lr_patience: 400,
            lr_factor: 0.5,
            min_lr_ratio: 1.0 / 32.0,
            patience: 1500,
            min_improvement: 1e-3,
            smoothing_steps: 0,
            decay_steps: 0,
            validate_every_steps: 0,
        }
    }

    /// The default, measured in docs/convergence.md ("Training schedule"): a 300-step warm-up
    /// (shorter ones met loss spikes at the peak rate sooner), a half cosine to 1/32 of the
    /// rate over 1,200 steps, then a stop once 200 steps pass without a best 1 % below the
    /// last; the validation loss is looked at every 10 steps. horse-gallop and samba converge
    /// in 1,500–1,900 steps.
    pub fn cosine() -> Self {
        Self {
            warmup_steps: 300,
            lr_patience: 0,
            patience: 200,
            min_improvement: 0.01,
            decay_steps: 1200,
            validate_every_steps: 10,
            ..Self::plateau()
        }
    }
}

impl Schedule {
    /// A constant rate and no early stop: how every model trained before schedules existed
    /// (its folder reads as this).
    pub fn constant() -> Self {
        Self {
            warmup_steps: 0,
            lr_patience: 0,
            lr_factor: 1.0,
            min_lr_ratio: 1.0,
            patience: 0,
            min_improvement: 0.0,
            smoothing_steps: 0,
            decay_steps: 0,
            validate_every_steps: 0,
        }
    }

    /// Whether the validation loss is due after an epoch that took the step count from
    /// `before` to `after` (see [`Schedule::validate_every_steps`]).
    pub fn validation_due(&self, before: u64, after: u64) -> bool {
        let every = self.validate_every_steps.max(1) as u64;
        after / every > before / every
    }

    /// The step after which the run may stop: the end of the warm-up and the decay.
    pub fn annealed_at(&self) -> u64 {
        match self.decay_steps {
            0 => 0,
            d => (self.warmup_steps + d) as u64,
        }
    }

    /// The decay's factor at optimizer step `step` (1 without a decay).
    fn decay(&self, step: u64) -> f64 {
        if self.decay_steps == 0 {
            return 1.0;
        }
        let t = step.saturating_sub(self.warmup_steps as u64) as f64 / self.decay_steps as f64;
        let floor = self.min_lr_ratio;
        floor + (1.0 - floor) * 0.5 * (1.0 + (std::f64::consts::PI * t.min(1.0)).cos())
    }

    /// Whether the run may stop before its budget.
    pub fn stops_early(&self) -> bool {
        self.patience > 0
    }

    pub fn validate(&self) -> Result<()> {
        let fraction = |name: &'static str, x: f64, lo: f64, hi: f64| {
            if x.is_finite() && (lo..=hi).contains(&x) {
                Ok(())
            } else {
                Err(VaeError::argument(
                    name,
                    format!("{x} is not in [{lo}, {hi}]"),
                ))
            }
        };
        fraction("lr_factor", self.lr_factor, f64::MIN_POSITIVE, 1.0)?;
        fraction("min_lr_ratio", self.min_lr_ratio, f64::MIN_POSITIVE, 1.0)?;
        fraction("min_improvement", self.min_improvement, 0.0, 0.5)
    }
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StopReason {
    /// The validation loss stopped improving (the schedule's patience ran out).
    Converged,
    /// The step or epoch budget was used up first.
    Budget,
    /// The process ended before either (killed, or a crash): `--resume` continues it.
    Interrupted,
}

impl StopReason {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Converged => "converged",
            Self::Budget => "budget",
            Self::Interrupted => "interrupted",
        }
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The schedule's state between epochs (kept in the checkpoint, so a resumed run continues the
/// same schedule).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduleState {
    /// The current rate is `lr · scale` (before the warm-up factor).
    pub scale: f64,
    /// Best validation loss by the schedule's rule (a fraction `min_improvement` below the
    /// previous best to count).
    pub best: f64,
    /// Steps since that best, and since the last rate cut (or the best, whichever is later).
    pub since_best: usize,
    pub since_cut: usize,
    /// Rate cuts so far (rollbacks included).
    pub cuts: usize,
    /// Times the run diverged and went back to its best weights ([`Self::rollback`]).
    pub rollbacks: usize,
    /// The moving average of the loss ([`Schedule::smoothing_steps`]; infinite before the
    /// first finite loss).
    pub smoothed: f64,
    /// The optimizer step of the last rollback (0: none); the rate warms up again after it.
    pub rewarm_from: u64,
}

/// After a rollback the rate rises linearly from 1/`REWARM_STEPS` of its value over this many
/// steps. Adam restarts with empty moments, and its first steps then move every weight by about
/// the full rate whatever its gradient, a jolt to weights that have just been restored.
pub const REWARM_STEPS: u64 = 100;

impl Default for ScheduleState {
    fn default() -> Self {
        Self {
            scale: 1.0,
            best: f64::INFINITY,
            since_best: 0,
            since_cut: 0,
            cuts: 0,
            rollbacks: 0,
            smoothed: f64::INFINITY,
            rewarm_from: 0,
        }
    }
}

/// What the schedule decided after an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    Continue,
    /// The rate was cut; training goes on.
    CutRate,
    /// Patience ran out: the run has converged.
    Stop,
}

impl ScheduleState {
    /// The rate of optimizer step `step` (1-based, counted over the whole run).
    pub fn lr(&self, schedule: &Schedule, base_lr: f64, step: u64) -> f64 {
        let warm = if schedule.warmup_steps > 0 && (step as usize) < schedule.warmup_steps {
            0.1 + 0.9 * step as f64 / schedule.warmup_steps as f64
        } else {
            1.0
        };
        let rewarm = if self.rewarm_from > 0 && step > self.rewarm_from {
            ((step - self.rewarm_from) as f64 / REWARM_STEPS as f64).min(1.0)
        } else {
            1.0
        };
        base_lr * self.scale * warm * rewarm * schedule.decay(step)
    }

    /// Takes an epoch of `steps` steps that ended with validation loss `loss`, after `done`
    /// optimizer steps in all.
    pub fn update(&mut self, schedule: &Schedule, loss: f64, steps: usize, done: u64) -> Decision {
        let loss = if schedule.smoothing_steps == 0 || !loss.is_finite() {
            loss
        } else if !self.smoothed.is_finite() {
            self.smoothed = loss;
            loss
        } else {
            let weight = (steps as f64 / schedule.smoothing_steps as f64).min(1.0);
            self.smoothed += weight * (loss - self.smoothed);
            self.smoothed
        };
        if loss.is_finite() && loss < self.best * (1.0 - schedule.min_improvement) {
            self.best = loss;
            self.since_best = 0;
            self.since_cut = 0;
            return Decision::Continue;
        }
        self.since_best += steps;
        self.since_cut += steps;
        let annealed = done >= schedule.annealed_at();
        if schedule.stops_early() && annealed && self.since_best >= schedule.patience {
            return Decision::Stop;
        }
        let floor = schedule.min_lr_ratio;
        let cuts = schedule.lr_patience > 0 && schedule.decay_steps == 0;
        if cuts && self.since_cut >= schedule.lr_patience && self.scale > floor {
            self.scale = (self.scale * schedule.lr_factor).max(floor);
            self.since_cut = 0;
            self.cuts += 1;
            return Decision::CutRate;
        }
        Decision::Continue
    }

    /// After a divergence (a non-finite loss), when the weights go back to those of the best
    /// epoch: the rate is halved whatever the schedule (a step of that size just failed), and
    /// the counts since the best start again, since the weights are the best's. `step` is the
    /// optimizer's step count at the rollback: the rate warms up again after it
    /// ([`REWARM_STEPS`]).
    pub fn rollback(&mut self, step: u64) {
        self.rewarm_from = step;
        self.scale *= 0.5;
        self.cuts += 1;
        self.rollbacks += 1;
        self.since_best = 0;
        self.since_cut = 0;
        // The average took in the losses of the blow-up.
        self.smoothed = f64::INFINITY;
    }

    /// Whether the loss was still reaching new bests recently: within the last `patience`
    /// steps (or, without early stopping, the last tenth of `steps_done`).
    pub fn still_improving(&self, schedule: &Schedule, steps_done: usize) -> bool {
        let window = if schedule.stops_early() {
            schedule.patience
        } else {
            (steps_done / 10).max(1)
        };
        self.since_best < window
    }

    /// Packed for the checkpoint.
    pub fn to_vec(&self) -> Vec<f64> {
        vec![
            self.scale,
            self.best,
            self.since_best as f64,
            self.since_cut as f64,
            self.cuts as f64,
            self.rollbacks as f64,
            self.smoothed,
            self.rewarm_from as f64,
        ]
    }

    /// Unpacks [`Self::to_vec`] (checkpoints written before rollbacks and smoothing existed
    /// have five numbers).
    pub fn from_slice(v: &[f64]) -> Option<Self> {
        let (&[scale, best, since_best, since_cut, cuts], rollbacks) = (v.get(..5)?, v.get(5))
        else {
            return None;
        };
        if v.len() > 8 {
            return None;
        }
        Some(Self {
            scale,
            best,
            since_best: since_best as usize,
            since_cut: since_cut as usize,
            cuts: cuts as usize,
            rollbacks: rollbacks.map_or(0, |&r| r as usize),
            smoothed: v.get(6).copied().unwrap_or(f64::INFINITY),
            rewarm_from: v.get(7).map_or(0, |&s| s as u64),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule() -> Schedule {
        Schedule {
            warmup_steps: 10,
            lr_patience: 4,
            lr_factor: 0.5,
            min_lr_ratio: 0.5,
            patience: 12,
            min_improvement: 0.01,
            smoothing_steps: 0,
            decay_steps: 0,
            validate_every_steps: 0,
        }
    }

    #[test]
    fn validation_is_due_when_an_epoch_crosses_a_multiple_of_its_steps() {
        let every = |n| Schedule {
            validate_every_steps: n,
            ..schedule()
        };
        // 0 and 1: every epoch that took a step.
        for s in [every(0), every(1)] {
            assert!(s.validation_due(0, 1) && s.validation_due(7, 9));
            assert!(!s.validation_due(5, 5));
        }
        let s = every(10);
        assert!(!s.validation_due(0, 9));
        assert!(s.validation_due(9, 10) && s.validation_due(8, 12));
        assert!(!s.validation_due(10, 19));
        // Epochs of 3 steps: at 12, 21 and 30, never twice for one multiple.
        let due: Vec<u64> = (1..=10u64)
            .filter(|k| s.validation_due(3 * k - 3, 3 * k))
            .map(|k| 3 * k)
            .collect();
        assert_eq!(due, [12, 21, 30]);
        // Epochs longer than 10 steps: every one.
        assert!((1..20u64).all(|k| s.validation_due(15 * k - 15, 15 * k)));
    }

    #[test]
    fn warm_up_rises_linearly_to_the_rate() {
        let s = schedule();
        let state = ScheduleState::default();
        assert!((state.lr(&s, 1.0, 0) - 0.1).abs() < 1e-12);
        assert!((state.lr(&s, 1.0, 5) - 0.55).abs() < 1e-12);
        assert_eq!(state.lr(&s, 1.0, 10), 1.0);
        assert_eq!(state.lr(&Schedule::constant(), 2.0, 0), 2.0);
    }

    #[test]
    fn plateaus_cut_the_rate_down_to_the_floor_then_stop() {
        let s = schedule();
        let mut st = ScheduleState::default();
        assert_eq!(st.update(&s, 10.0, 2, 0), Decision::Continue);
        // Improvements smaller than 1 % do not count.
        assert_eq!(st.update(&s, 9.95, 2, 0), Decision::Continue);
        assert_eq!(st.since_best, 2);
        assert_eq!(st.update(&s, 9.95, 2, 0), Decision::CutRate);
        assert_eq!((st.scale, st.cuts, st.since_cut), (0.5, 1, 0));
        // At the floor: no more cuts, and 12 steps without a best stop the run.
        for _ in 0..3 {
            assert_eq!(st.update(&s, 9.99, 2, 0), Decision::Continue);
        }
        assert_eq!(st.update(&s, 9.99, 2, 0), Decision::Stop);
        assert!(!st.still_improving(&s, 100));
        // A real improvement resets both counters but keeps the rate.
        assert_eq!(st.update(&s, 5.0, 2, 0), Decision::Continue);
        assert_eq!((st.since_best, st.since_cut, st.scale), (0, 0, 0.5));
        assert!(st.still_improving(&s, 100));
        assert_eq!(st.lr(&s, 1.0, 100), 0.5);
    }

    #[test]
    fn a_smoothed_loss_sees_the_plateau_that_lucky_dips_hide() {
        // A plateau at 100 with a dip every third epoch, each a little deeper than the last:
        // the raw loss reaches a new best every three epochs and the rate is never cut.
        let loss = |k: usize| {
            if k % 3 == 2 {
                50.0 - 0.02 * k as f64
            } else {
                100.0
            }
        };
        let raw = Schedule {
            patience: 0,
            min_improvement: 1e-3,
            ..schedule()
        };
        let smooth = Schedule {
            smoothing_steps: 20,
            ..raw
        };
        let (mut a, mut b) = (ScheduleState::default(), ScheduleState::default());
        for k in 0..200 {
            a.update(&raw, loss(k), 1, 0);
            b.update(&smooth, loss(k), 1, 0);
        }
        assert_eq!(a.cuts, 0);
        assert!(b.cuts >= 1, "{b:?}");
        assert!((b.smoothed - (200.0 + 50.0) / 3.0).abs() < 5.0, "{b:?}");
        let packed = b.to_vec();
        assert_eq!(ScheduleState::from_slice(&packed), Some(b));
    }

    #[test]
    fn a_rollback_halves_the_rate_even_when_constant_and_restarts_the_counts() {
        let s = Schedule::constant();
        let mut st = ScheduleState::default();
        st.update(&s, 10.0, 1, 0);
        st.update(&s, 11.0, 7, 0);
        assert_eq!(st.since_best, 7);
        st.rollback(10);
        st.rollback(20);
        assert_eq!((st.scale, st.cuts, st.rollbacks), (0.25, 2, 2));
        // The rate warms up again from the last rollback, linearly over REWARM_STEPS.
        let c = Schedule::constant();
        assert_eq!(st.lr(&c, 1.0, 20), 0.25);
        assert!((st.lr(&c, 1.0, 21) - 0.25 / REWARM_STEPS as f64).abs() < 1e-15);
        let half = 20 + REWARM_STEPS / 2;
        assert!((st.lr(&c, 1.0, half) - 0.125).abs() < 1e-15);
        assert_eq!(st.lr(&c, 1.0, 20 + REWARM_STEPS), 0.25);
        assert_eq!(st.lr(&c, 1.0, 1_000), 0.25);
        assert_eq!(ScheduleState::from_slice(&st.to_vec()), Some(st));
        assert_eq!((st.since_best, st.since_cut, st.best), (0, 0, 10.0));
        assert_eq!(st.lr(&s, 1e-2, 1_000), 2.5e-3);
        let packed = st.to_vec();
        assert_eq!(ScheduleState::from_slice(&packed), Some(st));
        // A checkpoint from before rollbacks existed: five numbers.
        let old = ScheduleState::from_slice(&packed[..5]).unwrap();
        assert_eq!((old.rollbacks, old.cuts), (0, 2));
        assert_eq!(
            ScheduleState::from_slice(&[packed.clone(), vec![0.0]].concat()),
            None
        );
    }

    #[test]
    fn without_patience_nothing_stops_and_nan_is_no_improvement() {
        let s = Schedule::constant();
        let mut st = ScheduleState::default();
        for _ in 0..100 {
            assert_eq!(st.update(&s, f64::NAN, 50, 0), Decision::Continue);
        }
        assert_eq!(st.scale, 1.0);
        assert!(!st.still_improving(&s, 5000));
        let packed = st.to_vec();
        assert_eq!(ScheduleState::from_slice(&packed), Some(st));
        assert_eq!(ScheduleState::from_slice(&packed[..3]), None);
        assert!(s.validate().is_ok() && Schedule::default().validate().is_ok());
        let bad = Schedule {
            lr_factor: 0.0,
            ..Schedule::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("lr_factor")
        );
    }

    #[test]
    fn a_cosine_decay_falls_to_the_floor_and_holds_the_stop_until_it_ends() {
        let s = Schedule {
            warmup_steps: 10,
            lr_patience: 4,
            lr_factor: 0.5,
            min_lr_ratio: 0.01,
            patience: 5,
            min_improvement: 0.0,
            smoothing_steps: 0,
            decay_steps: 100,
            validate_every_steps: 0,
        };
        let st = ScheduleState::default();
        assert!((st.lr(&s, 1.0, 10) - 1.0).abs() < 1e-12);
        // Half way down the cosine: the mean of the peak and the floor.
        assert!((st.lr(&s, 1.0, 60) - 0.505).abs() < 1e-12);
        assert!((st.lr(&s, 1.0, 110) - 0.01).abs() < 1e-12);
        assert!((st.lr(&s, 1.0, 5_000) - 0.01).abs() < 1e-12);
        // The rate falls monotonically after the warm-up.
        let rates: Vec<f64> = (10..=120).map(|k| st.lr(&s, 1.0, k)).collect();
        assert!(rates.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(s.annealed_at(), 110);
        // No plateau cuts during the decay, and no stop before it ends.
        let mut st = ScheduleState::default();
        assert_eq!(st.update(&s, 1.0, 1, 1), Decision::Continue);
        for done in 2..110 {
            assert_eq!(st.update(&s, 2.0, 1, done), Decision::Continue, "{done}");
        }
        assert_eq!((st.cuts, st.scale), (0, 1.0));
        assert_eq!(st.update(&s, 2.0, 1, 110), Decision::Stop);
        // A rollback still halves the rate on top of the decay.
        st.rollback(500);
        assert!((st.lr(&s, 1.0, 500 + REWARM_STEPS) - 0.005).abs() < 1e-12);
    }
}
