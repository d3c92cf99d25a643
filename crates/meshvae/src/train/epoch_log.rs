//! `log.jsonl`: one JSON line per finished epoch.

use super::EpochRecord;
use crate::error::{Result, VaeError};
use std::io::Write;
use std::path::Path;

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
