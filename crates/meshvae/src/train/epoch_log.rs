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
    pub executor: Option<super::ExecutorKind>,
    /// Why candle computed them rather than the engine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub executor_reason: Option<String>,
}

impl EpochRecord {
    /// The loss `selection` ranks epochs by (the training loss where the validation loss is
    /// missing; an epoch whose test loss was not measured never wins on the test loss).
    pub fn score(&self, selection: Selection) -> f64 {
        match selection {
            Selection::Validation => self.val_loss.unwrap_or(self.train_loss),
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
