//! Whether a trained model's outputs deserve trust: its test error against the trivial
//! predictor (the mean training shape), and whether its training stopped while still learning.
//! `eval`, `reconstruct`, `generate` and `interpolate` print these before anything else, so that
//! a model that learned nothing is not reported as a success.

use crate::apps::eval::{error_report, mean_shape};
use crate::apps::reconstruct::EvalReport;
use crate::error::Result;
use crate::train::RunStatus;
use crate::train::schedule::StopReason;
use crate::trained::TrainedModel;
use candle_core::Device;
use mesh_io::{MeshSet, Point};
use std::fmt;

/// A test RMS above this fraction of the mean training shape's is "not clearly below" it: the
/// model has learned less than half of what separates the test meshes from the average pose.
/// Converged models sit far under it (horse-gallop 0.31, samba 0.16 of the mean shape's); a
/// 30-epoch horse-gallop model sat 35× above the mean shape's error.
pub const MEAN_SHAPE_FRACTION: f64 = 0.5;

/// A reason not to trust a model, with what to do about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum QualityWarning {
    /// The test error is not clearly below the mean training shape's. `converged`: the run
    /// ended converged, so more training would not help; its `train_meshes` are too few, or
    /// too unlike the test meshes, to generalise from.
    NoBetterThanMeanShape {
        test_rms: f64,
        mean_shape_rms: f64,
        converged: bool,
        train_meshes: usize,
    },
    /// Training ended at its budget while the validation loss was still improving.
    StoppedWhileImproving { steps: u64 },
}

impl QualityWarning {
    /// A short name for machine-readable output.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::NoBetterThanMeanShape { .. } => "no_better_than_mean_shape",
            Self::StoppedWhileImproving { .. } => "stopped_while_improving",
        }
    }
}

impl fmt::Display for QualityWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NoBetterThanMeanShape {
                test_rms,
                mean_shape_rms,
                converged,
                train_meshes,
            } => {
                write!(
                    f,
                    "the test error (RMS {test_rms:.4}) is not clearly below the mean training \
                     shape's ({mean_shape_rms:.4}, {:.0} %): this model has learned little that \
                     holds on meshes it did not train on, and its meshes are not to be trusted; ",
                    100.0 * test_rms / mean_shape_rms
                )?;
                if converged {
                    write!(
                        f,
                        "its training converged, so training longer will not help: its \
                         {train_meshes} training meshes are too few, or too unlike the test \
                         meshes, to generalise from (train on more meshes of the shapes to \
                         model; --train-list and --test-list choose the split)"
                    )
                } else {
                    f.write_str(
                        "train longer (`meshvae train … --resume` with a larger --steps, or \
                         without budget flags to train until converged)",
                    )
                }
            }
            Self::StoppedWhileImproving { steps } => write!(
                f,
                "training stopped at its budget after {steps} steps while the validation loss \
                 was still improving: the model has not finished learning; continue with \
                 `meshvae train … --resume --steps N` (N > {steps})"
            ),
        }
    }
}

/// The warnings an evaluation and a run's `run.json` (if any) give.
pub fn quality_warnings(report: &EvalReport, status: Option<&RunStatus>) -> Vec<QualityWarning> {
    let mut warnings = Vec::new();
    let errors = Errors {
        test_meshes: report.test.meshes,
        test_rms: report.test.rms,
        mean_shape_rms: report.mean_shape.rms,
        train_meshes: report.train.meshes,
    };
    warnings.extend(mean_shape_warning(&errors, status));
    warnings.extend(status.and_then(improving_warning));
    warnings
}

/// What [`mean_shape_warning`] compares.
struct Errors {
    test_meshes: usize,
    test_rms: f64,
    mean_shape_rms: f64,
    train_meshes: usize,
}

fn mean_shape_warning(errors: &Errors, status: Option<&RunStatus>) -> Option<QualityWarning> {
    // A NaN error (a broken model) compares false, so it is caught by the negation.
    let clearly_below = errors.test_rms <= MEAN_SHAPE_FRACTION * errors.mean_shape_rms;
    (errors.test_meshes > 0 && !clearly_below).then_some(QualityWarning::NoBetterThanMeanShape {
        test_rms: errors.test_rms,
        mean_shape_rms: errors.mean_shape_rms,
        converged: status.is_some_and(|s| s.stop_reason == StopReason::Converged),
        train_meshes: errors.train_meshes,
    })
}

fn improving_warning(status: &RunStatus) -> Option<QualityWarning> {
    (status.stop_reason == StopReason::Budget && status.still_improving).then_some(
        QualityWarning::StoppedWhileImproving {
            steps: status.steps,
        },
    )
}

impl TrainedModel {
    /// [`quality_warnings`] from the test meshes alone (the training meshes are not
    /// reconstructed, so this costs about half an evaluation): for commands that use a model
    /// without evaluating it. No test meshes, no error warning.
    pub fn quality_warnings(
        &self,
        set: &MeshSet,
        status: Option<&RunStatus>,
        device: &Device,
    ) -> Result<Vec<QualityWarning>> {
        let mut warnings = Vec::new();
        let test = &self.split.test;
        if !test.is_empty() {
            let frames =
                |ids: &[usize]| -> Vec<&[Point]> { ids.iter().map(|&i| set.frame(i)).collect() };
            let errors = error_report(&frames(test), &self.reconstruct(set, test, device)?)?;
            let mean = mean_shape(&frames(&self.split.train));
            let baseline = error_report(&frames(test), &vec![mean; test.len()])?;
            let errors = Errors {
                test_meshes: test.len(),
                test_rms: errors.rms,
                mean_shape_rms: baseline.rms,
                train_meshes: self.split.train.len(),
            };
            warnings.extend(mean_shape_warning(&errors, status));
        }
        warnings.extend(status.and_then(improving_warning));
        Ok(warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn errors(test_meshes: usize, test_rms: f64, mean_shape_rms: f64) -> Errors {
        Errors {
            test_meshes,
            test_rms,
            mean_shape_rms,
            train_meshes: 4,
        }
    }

    #[test]
    fn a_model_no_better_than_the_mean_shape_is_flagged_and_a_good_one_is_not() {
        let warn = |test_meshes, test_rms, mean_shape_rms| {
            mean_shape_warning(&errors(test_meshes, test_rms, mean_shape_rms), None)
        };
        assert_eq!(warn(24, 0.025, 0.081), None);
        assert_eq!(warn(24, 0.0405, 0.081), None);
        let bad = warn(24, 2.81, 0.081).unwrap();
        assert_eq!(bad.kind(), "no_better_than_mean_shape");
        let text = bad.to_string();
        assert!(text.contains("2.8100") && text.contains("0.0810"), "{text}");
        assert!(text.contains("--resume"), "{text}");
        assert!(warn(24, 0.05, 0.081).is_some());
        assert!(warn(24, f64::NAN, 0.081).is_some());
        assert_eq!(warn(0, f64::NAN, f64::NAN), None);
    }

    /// A converged run would not do better with more steps: the advice is about its data.
    #[test]
    fn a_converged_model_no_better_than_the_mean_shape_is_not_told_to_train_longer() {
        let mut status = status(StopReason::Converged);
        let bad = mean_shape_warning(&errors(5, 0.0962, 0.1120), Some(&status)).unwrap();
        let text = bad.to_string();
        assert!(
            text.contains("converged") && text.contains("4 training meshes"),
            "{text}"
        );
        assert!(!text.contains("--resume"), "{text}");
        status.stop_reason = StopReason::Budget;
        let text = (mean_shape_warning(&errors(5, 0.0962, 0.1120), Some(&status)))
            .unwrap()
            .to_string();
        assert!(
            text.contains("train longer") && text.contains("--resume"),
            "{text}"
        );
    }

    fn status(stop_reason: StopReason) -> RunStatus {
        RunStatus {
            stop_reason,
            epochs: 30,
            epoch_budget: 30,
            steps: 30,
            steps_per_epoch: 1,
            best_epoch: 30,
            selected_on: crate::Selection::Validation,
            still_improving: true,
            lr: 1e-2,
            lr_cuts: 0,
            rollbacks: 0,
            clipped_steps: None,
            seconds: 3.0,
            path: "engine".into(),
            executor_reason: None,
            best_test_epoch: None,
            best_test_loss: None,
            phases: None,
        }
    }

    #[test]
    fn a_run_cut_by_its_budget_while_improving_is_flagged() {
        let mut status = status(StopReason::Budget);
        let warning = improving_warning(&status).unwrap();
        assert_eq!(warning, QualityWarning::StoppedWhileImproving { steps: 30 });
        let text = warning.to_string();
        assert!(
            text.contains("--resume --steps N") && text.contains("N > 30"),
            "{text}"
        );
        status.still_improving = false;
        assert_eq!(improving_warning(&status), None);
        status.still_improving = true;
        status.stop_reason = StopReason::Converged;
        assert_eq!(improving_warning(&status), None);
    }
}
