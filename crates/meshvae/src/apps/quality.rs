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
    /// The test error is not clearly below the mean training shape's.
    NoBetterThanMeanShape { test_rms: f64, mean_shape_rms: f64 },
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
            } => write!(
                f,
                "the test error (RMS {test_rms:.4}) is not clearly below the mean training \
                 shape's ({mean_shape_rms:.4}, {:.0} %): this model has learned little, and its \
                 meshes are not to be trusted; train longer (`meshvae train … --resume` with a \
                 larger --steps, or without budget flags to train until converged)",
                100.0 * test_rms / mean_shape_rms
            ),
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
    if let Some(w) = mean_shape_warning(report.test.meshes, report.test.rms, report.mean_shape.rms)
    {
        warnings.push(w);
    }
    warnings.extend(status.and_then(improving_warning));
    warnings
}

fn mean_shape_warning(meshes: usize, test_rms: f64, mean_shape_rms: f64) -> Option<QualityWarning> {
    // A NaN error (a broken model) compares false, so it is caught by the negation.
    let clearly_below = test_rms <= MEAN_SHAPE_FRACTION * mean_shape_rms;
    (meshes > 0 && !clearly_below).then_some(QualityWarning::NoBetterThanMeanShape {
        test_rms,
        mean_shape_rms,
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
            warnings.extend(mean_shape_warning(test.len(), errors.rms, baseline.rms));
        }
        warnings.extend(status.and_then(improving_warning));
        Ok(warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_no_better_than_the_mean_shape_is_flagged_and_a_good_one_is_not() {
        assert_eq!(mean_shape_warning(24, 0.025, 0.081), None);
        assert_eq!(mean_shape_warning(24, 0.0405, 0.081), None);
        let bad = mean_shape_warning(24, 2.81, 0.081).unwrap();
        assert_eq!(bad.kind(), "no_better_than_mean_shape");
        let text = bad.to_string();
        assert!(text.contains("2.8100") && text.contains("0.0810"), "{text}");
        assert!(text.contains("--resume"), "{text}");
        assert!(mean_shape_warning(24, 0.05, 0.081).is_some());
        assert!(mean_shape_warning(24, f64::NAN, 0.081).is_some());
        assert_eq!(mean_shape_warning(0, f64::NAN, f64::NAN), None);
    }

    #[test]
    fn a_run_cut_by_its_budget_while_improving_is_flagged() {
        let mut status = RunStatus {
            stop_reason: StopReason::Budget,
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
        };
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
