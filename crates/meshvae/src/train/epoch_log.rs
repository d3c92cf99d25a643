//! `log.jsonl`: one JSON line per finished epoch.

use crate::error::{Result, VaeError};
use crate::train::split::Selection;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// One line of `log.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    pub epoch: usize,
    /// Mean over the epoch's training meshes of the total loss and of its weighted terms.
    pub train_loss: f64,
    pub rec: f64,
    pub kl: f64,
    pub l2: f64,
    /// Validation loss on the validation meshes (none if the split has none).
    #[serde(default)]
    pub val_loss: Option<f64>,
    /// The same loss on the test meshes (none if the split has none).
    pub test_loss: Option<f64>,
    pub seconds: f64,
    /// Optimizer steps taken so far, this epoch's included (0 in logs written before steps
    /// were counted).
    #[serde(default)]
    pub step: u64,
    /// The learning rate of the epoch's last step (absent from older logs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lr: Option<f64>,
    /// Optimizer steps since the last new best validation (or training) loss when the epoch
    /// ended; training converges when this reaches the schedule's patience. Absent where the
    /// schedule never stops early, and from older logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub since_best: Option<u64>,
    /// What computed the epoch's steps (absent from older logs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub executor: Option<crate::executor::ExecutorKind>,
    /// Why candle computed them rather than the engine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub executor_reason: Option<String>,
}

impl EpochRecord {
    /// The loss `selection` ranks epochs by (an epoch whose validation or test loss was not
    /// measured never wins on it).
    pub fn score(&self, selection: Selection) -> f64 {
        match selection {
            // An epoch without a validation pass was not a candidate.
            Selection::Validation => self.val_loss.unwrap_or(f64::INFINITY),
            Selection::Train => self.train_loss,
            Selection::Test => self.test_loss.unwrap_or(f64::INFINITY),
        }
    }
}

pub(super) fn append_log(path: &Path, record: &EpochRecord) -> Result<()> {
    let line = serde_json::to_string(record).map_err(|e| VaeError::model(path, e.to_string()))?;
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| VaeError::io(path, e))?;
    writeln!(file, "{line}").map_err(|e| VaeError::io(path, e))
}

/// Keeps the log lines of epochs up to `epoch` (a killed run may have logged one more).
pub(super) fn truncate_log(path: &Path, epoch: usize) -> Result<()> {
    if !path.exists() {
        return Ok(());
    }
    let text = std::fs::read_to_string(path).map_err(|e| VaeError::io(path, e))?;
    let kept: String = text
        .lines()
        .filter(|line| serde_json::from_str::<EpochRecord>(line).is_ok_and(|r| r.epoch <= epoch))
        .map(|line| format!("{line}\n"))
        .collect();
    if kept != text {
        mesh_io::atomic::write_bytes_atomic(path, kept.as_bytes())?;
    }
    Ok(())
}

/// Reads `log.jsonl`.
pub fn read_log(path: &Path) -> Result<Vec<EpochRecord>> {
    let text = std::fs::read_to_string(path).map_err(|e| VaeError::io(path, e))?;
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, line)| {
            serde_json::from_str(line)
                .map_err(|e| VaeError::model(path, format!("line {}: {e}", i + 1)))
        })
        .collect()
}

/// The epochs (by [`EpochRecord::epoch`]) whose training loss exceeds `factor` times the median
/// of the `window` epochs before them: a finite blow-up, which the rollback (it reacts only to a
/// non-finite loss) does not see. The first `window` epochs are not judged. `meshvae eval`
/// reports them with `window` 50 and `factor` 3.
pub fn loss_spikes(log: &[EpochRecord], window: usize, factor: f64) -> Vec<usize> {
    let losses: Vec<f64> = log.iter().map(|r| r.train_loss).collect();
    let mut sorted = Vec::with_capacity(window);
    (window.max(1)..losses.len())
        .filter(|&i| {
            sorted.clear();
            sorted.extend_from_slice(&losses[i - window..i]);
            sorted.sort_by(f64::total_cmp);
            let median = match window {
                0 => return false,
                w if w % 2 == 1 => sorted[w / 2],
                w => 0.5 * (sorted[w / 2 - 1] + sorted[w / 2]),
            };
            // A NaN loss counts as a spike.
            losses[i].is_nan() || losses[i] > factor * median
        })
        .map(|i| log[i].epoch)
        .collect()
}

/// The rule [`loss_spikes`] applies by default: 3× the median of the 50 epochs before.
pub const SPIKE_WINDOW: usize = 50;
pub const SPIKE_FACTOR: f64 = 3.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn log_of(losses: &[f64]) -> Vec<EpochRecord> {
        losses
            .iter()
            .enumerate()
            .map(|(i, &l)| EpochRecord {
                epoch: i + 1,
                train_loss: l,
                rec: l,
                kl: 0.0,
                l2: 0.0,
                val_loss: None,
                test_loss: None,
                seconds: 0.0,
                step: i as u64 + 1,
                lr: None,
                since_best: None,
                executor: None,
                executor_reason: None,
            })
            .collect()
    }

    #[test]
    fn spikes_are_epochs_above_three_times_the_recent_median() {
        // A falling curve never spikes.
        let falling: Vec<f64> = (0..200).map(|k| 100.0 / (1.0 + k as f64)).collect();
        assert!(loss_spikes(&log_of(&falling), 50, 3.0).is_empty());
        // A noisy plateau (10 to 16, median 13): one epoch above 39 spikes, and a NaN counts
        // as one; 37 is within the rule.
        let mut losses: Vec<f64> = (0..200).map(|k| 10.0 + (k % 7) as f64).collect();
        assert!(loss_spikes(&log_of(&losses), 50, 3.0).is_empty());
        losses[120] = 39.5;
        losses[150] = f64::NAN;
        assert_eq!(loss_spikes(&log_of(&losses), 50, 3.0), vec![121, 151]);
        losses[120] = 37.0;
        assert_eq!(loss_spikes(&log_of(&losses), 50, 3.0), vec![151]);
        // The median of an even window is the mean of its middle two (1.5 here).
        assert!(loss_spikes(&log_of(&[1.0, 2.0, 4.4]), 2, 3.0).is_empty());
        assert_eq!(loss_spikes(&log_of(&[1.0, 2.0, 4.6]), 2, 3.0), vec![3]);
        assert!(loss_spikes(&log_of(&losses[..50]), 50, 3.0).is_empty());
    }
}
