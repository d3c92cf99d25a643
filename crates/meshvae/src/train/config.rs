//! [`TrainConfig`]: a run's training settings (budget, batch, rate, seed, loss weights, split
//! fractions, schedule, normalisation), saved with the model in `config.json`.

use crate::error::{Result, VaeError};
use crate::net::network::{Network, RecLoss};
use crate::optim::adam::AdamConfig;
use crate::train::loss::LossWeights;
use crate::train::schedule::Schedule;
use serde::{Deserialize, Serialize};

/// Training settings (saved with the model).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Epoch budget (used when `steps` is `None`); a resumed run may change it.
    pub epochs: usize,
    /// Budget in optimizer steps (rounded up to whole epochs), so that small and large sets get
    /// the same number of updates; overrides `epochs`. Models saved before it read as `None`.
    #[serde(default)]
    pub steps: Option<usize>,
    /// Meshes per step (the authors: 50); the last batch of an epoch may be smaller.
    pub batch: usize,
    /// Adam's initial (or, with a warm-up, peak) learning rate (1e-2; the authors' 1e-3 took
    /// more than 8,000 steps to reach what 1e-2 reaches in 1,500, see docs/convergence.md
    /// "Convergence"; 3e-2 diverges).
    pub lr: f64,
    /// Seeds the split, the initial weights, the shuffles and the sampling noise.
    pub seed: u64,
    pub loss: LossWeights,
    /// Fraction of the set held out for testing when no lists are given (0.5).
    pub test_fraction: f64,
    /// Fraction of the training meshes moved to the validation set that chooses the best
    /// checkpoint (0.1; at least one mesh, two from ten on). 0 chooses on the training loss. Models saved before
    /// validation sets existed read as 0.
    #[serde(default)]
    pub val_fraction: f64,
    /// Draw the random test set by shape, not by mesh: meshes with the same vertex positions (a
    /// cycle stored twice, as horse-gallop's 48 meshes are) always land on the same side, so
    /// no test shape has a copy among the training meshes. A set without repeats splits
    /// exactly as by mesh. Models saved before this option read as false. (The validation set
    /// is drawn by shape either way, so that its loss measures poses the network has not seen.)
    #[serde(default)]
    pub split_by_shape: bool,
    /// Learning-rate schedule and early stop. Models saved before schedules existed read as
    /// [`Schedule::constant`] (a constant rate for the whole budget).
    #[serde(default = "Schedule::constant")]
    pub schedule: Schedule,
    /// Fit the feature normalisation on every mesh, test meshes included (the authors' code),
    /// instead of the training meshes only. For comparisons: it lets the test meshes shape the
    /// model's inputs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub normalize_on_all: bool,
    /// Fit each feature group's range between the quantiles q and 1 − q and clamp the
    /// outliers (0: between min and max, as the authors). Models saved before the option read
    /// as 0; new ones default to [`DEFAULT_NORMALIZE_QUANTILE`].
    #[serde(default, skip_serializing_if = "is_zero")]
    pub normalize_quantile: f64,
    /// Adam's β₂, the decay of its squared-gradient average. Models saved before the option
    /// read as TF's and the authors' 0.999.
    #[serde(default = "tf_beta2")]
    pub adam_beta2: f64,
    /// The dense heads' weights (W_μ and W_σ, `enc.mu.weight` and `enc.sigma.weight`) train at
    /// this fraction of the rate. Adam moves every weight by about the rate, so a unit summing
    /// tens of thousands of inputs moves that many times further per step than a convolution
    /// summing 27. Models saved before the option read as 1.
    #[serde(default = "one")]
    pub head_lr_scale: f64,
    /// Clip each step's gradient to this many times the running mean of the recent gradient
    /// norms (0: never; see [`crate::GradClip`]). Models saved before the option read as 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub grad_clip: f64,
}

fn one() -> f64 {
    1.0
}

fn tf_beta2() -> f64 {
    AdamConfig::default().beta2
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The default [`TrainConfig::normalize_quantile`]: a handful of vertices around nearly
/// collapsed edges hold stretch features 10–20× the rest, and a min–max range fitted to them
/// squeezes 99 % of the entries into 7 % of the network's output range. Fitting between the
/// 0.1 % and 99.9 % quantiles (and clamping the 0.2 % beyond) converged horse-gallop to a lower
/// error in fewer steps (docs/convergence.md).
pub const DEFAULT_NORMALIZE_QUANTILE: f64 = 0.001;

/// The step budget of a run given no budget: long enough for every set measured to converge
/// first (horse-gallop, samba and the synthetic set stop on their own in fewer steps), so it
/// only ends a run that keeps improving.
pub const DEFAULT_MAX_STEPS: usize = 20_000;

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 100,
            steps: None,
            batch: 50,
            lr: 1e-2,
            seed: 1,
            loss: LossWeights::default(),
            test_fraction: 0.5,
            val_fraction: 0.1,
            split_by_shape: true,
            schedule: Schedule::default(),
            normalize_on_all: false,
            normalize_quantile: DEFAULT_NORMALIZE_QUANTILE,
            adam_beta2: DEFAULT_BETA2,
            head_lr_scale: DEFAULT_HEAD_LR_SCALE,
            grad_clip: DEFAULT_GRAD_CLIP,
        }
    }
}

impl TrainConfig {
    /// The defaults for `net`: ours as [`Self::default`]; the others at their authors' rate
    /// (Adam's 1e-3, under the same warm-up, decay and early stop) with their loss. The mesh VAE
    /// keeps ours (40 / 3 / 1 on the same features: the weights its lab's code uses); CoMA and
    /// SpiralNet++ take their L1 reconstruction alone (w_rec 1, no KL term, no L2 term:
    /// SpiralNet++ has no weight decay; CoMA's 5e-4 on its two dense layers only is not
    /// applied).
    pub fn for_network(net: Network) -> Self {
        let base = Self::default();
        Self {
            lr: net.default_lr().unwrap_or(base.lr),
            loss: match net.rec_loss() {
                RecLoss::SumOfSquares => base.loss,
                RecLoss::MeanAbsolute => LossWeights {
                    rec: 1.0,
                    kl: 0.0,
                    l2: 0.0,
                },
            },
            ..base
        }
    }
}

/// The default [`TrainConfig::adam_beta2`]. TF's 0.999 (the authors') averages squared
/// gradients over about 1,000 steps, so the average lags behind a gradient whose size changes
/// within a run's warm-up and decay. With 0.95 (about 20 steps) none of horse-gallop's seeds
/// 1–3 and neither synthetic run (the demo, the spike test) spiked at a peak rate of 1e-2,
/// where 0.99 spiked on one seed of each schedule tried; alone it left one 3.1× spike in
/// samba's three seeds, which [`DEFAULT_GRAD_CLIP`] removes (docs/convergence.md, "Training
/// schedule").
pub const DEFAULT_BETA2: f64 = 0.95;

/// The default [`TrainConfig::head_lr_scale`]. Adam moves every weight by about the rate, so
/// the dense heads, which sum tens of thousands of inputs per latent unit, move their outputs
/// hundreds of times further per step than a convolution does; the loss spikes began in them.
/// A third of the rate kept their learning speed (a tenth slowed it) and, with β₂ 0.95,
/// removed the spikes (docs/convergence.md, "Training schedule").
pub const DEFAULT_HEAD_LR_SCALE: f64 = 0.3;

/// The default [`TrainConfig::grad_clip`]: a step's gradient is scaled down to 3× the running
/// mean of the recent norms. With β₂ 0.95 it touches 1–3 steps of a 1,500–1,900-step run, and
/// those are the first steps of a spike: it removed the one 3.1× spike left in samba's seeds
/// 1–3 at the same mean error (0.01023 against 0.01020), and horse-gallop's seeds 1–3 ended at
/// 0.0198 against 0.0184 without it, within their seed-to-seed spread. A tighter bound costs
/// error: `--clip 2` clipped 20 steps a run and averaged 0.0202 (docs/convergence.md,
/// "Training schedule").
pub const DEFAULT_GRAD_CLIP: f64 = 3.0;

impl TrainConfig {
    /// Adam's settings for this run (at the initial rate; the schedule sets it step by step).
    pub fn adam(&self) -> AdamConfig {
        AdamConfig {
            lr: self.lr,
            beta2: self.adam_beta2,
            ..AdamConfig::default()
        }
    }

    /// The run's length in epochs when an epoch takes `steps_per_epoch` steps.
    pub fn epoch_budget(&self, steps_per_epoch: usize) -> usize {
        match self.steps {
            Some(steps) => steps.div_ceil(steps_per_epoch.max(1)),
            None => self.epochs,
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.epochs == 0 {
            return Err(VaeError::argument("epochs", "must be at least 1"));
        }
        if self.steps == Some(0) {
            return Err(VaeError::argument("steps", "must be at least 1"));
        }
        self.schedule.validate()?;
        if !(0.0..0.5).contains(&self.normalize_quantile) {
            return Err(VaeError::argument(
                "normalize_quantile",
                format!("{} is not in [0, 0.5)", self.normalize_quantile),
            ));
        }
        if !(0.0..1.0).contains(&self.adam_beta2) {
            return Err(VaeError::argument(
                "adam_beta2",
                format!("{} is not in [0, 1)", self.adam_beta2),
            ));
        }
        if !(self.head_lr_scale.is_finite() && self.head_lr_scale > 0.0) {
            return Err(VaeError::argument(
                "head_lr_scale",
                format!("{} is not positive", self.head_lr_scale),
            ));
        }
        crate::GradClip::check_factor(self.grad_clip)?;
        if self.batch == 0 {
            return Err(VaeError::argument("batch", "must be at least 1"));
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err(VaeError::argument(
                "lr",
                format!("{} is not positive", self.lr),
            ));
        }
        if !(0.0..1.0).contains(&self.val_fraction) {
            return Err(VaeError::argument(
                "val_fraction",
                format!("{} is not in [0, 1)", self.val_fraction),
            ));
        }
        let w = self.loss;
        if ![w.rec, w.kl, w.l2]
            .iter()
            .all(|x| x.is_finite() && *x >= 0.0)
        {
            return Err(VaeError::argument(
                "loss weights",
                "must be finite and non-negative",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_saved_before_the_decay_and_beta2_read_as_they_trained() {
        // A config.json of a model trained with the plateau schedule and TF's β₂: neither
        // field was written then.
        let mut value = serde_json::to_value(TrainConfig::default()).unwrap();
        let map = value.as_object_mut().unwrap();
        map.remove("adam_beta2");
        map.remove("head_lr_scale");
        map.remove("grad_clip");
        let schedule = map["schedule"].as_object_mut().unwrap();
        schedule.remove("decay_steps");
        schedule.remove("validate_every_steps");
        let old: TrainConfig = serde_json::from_value(value).unwrap();
        assert_eq!((old.adam_beta2, old.head_lr_scale), (0.999, 1.0));
        assert_eq!(old.grad_clip, 0.0);
        assert_eq!(old.schedule.decay_steps, 0);
        assert_eq!(old.schedule.validate_every_steps, 0);
        assert_eq!(old.adam().beta2, 0.999);
        // Today's defaults survive a round trip, and β₂ reaches Adam.
        let new = TrainConfig::default();
        let text = serde_json::to_string(&new).unwrap();
        assert_eq!(serde_json::from_str::<TrainConfig>(&text).unwrap(), new);
        assert_eq!((new.adam().beta2, new.adam().lr), (DEFAULT_BETA2, new.lr));
    }

    #[test]
    fn a_beta2_outside_zero_to_one_or_a_head_scale_not_above_zero_is_refused() {
        for bad in [1.0, -0.1, f64::NAN] {
            let config = TrainConfig {
                adam_beta2: bad,
                ..TrainConfig::default()
            };
            let err = config.validate().unwrap_err().to_string();
            assert!(err.contains("adam_beta2"), "{err}");
            let config = TrainConfig {
                head_lr_scale: bad - 1.0,
                ..TrainConfig::default()
            };
            let err = config.validate().unwrap_err().to_string();
            assert!(err.contains("head_lr_scale"), "{err}");
        }
        for bad in [0.5, -1.0, f64::NAN, f64::INFINITY] {
            let config = TrainConfig {
                grad_clip: bad,
                ..TrainConfig::default()
            };
            let err = config.validate().unwrap_err().to_string();
            assert!(err.contains("grad_clip"), "{err}");
        }
        assert!(TrainConfig::default().validate().is_ok());
    }
}
