//! [`TrainLock`]: one training at a time in a model folder. Two processes resuming the same
//! folder (a queue restarted while the old one still ran) each truncate `log.jsonl` to their
//! checkpoint and then append to it, interleaving two runs' epochs, and overwrite each other's
//! weights and checkpoints; the folder no longer describes any one run.
//!
//! The lock is the file `training.lock` in the folder, holding the process id. It is taken
//! before anything in the folder is read or changed and removed when the training ends; a lock
//! whose process has exited (a kill) is taken over.

use super::folder::ModelFolder;
use crate::error::{Result, VaeError};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The name of the lock file in a model folder.
pub(crate) const LOCK_FILE: &str = "training.lock";

/// A held lock on a model folder; dropping it releases the folder.
#[derive(Debug)]
pub(crate) struct TrainLock {
    path: PathBuf,
}

impl TrainLock {
    /// Takes the lock of `folder` (creating the folder), or fails naming the process that
    /// trains it.
    pub(crate) fn acquire(folder: &ModelFolder) -> Result<Self> {
        let dir = &folder.dir;
        if dir.exists() && !dir.is_dir() {
            return Err(VaeError::model(dir, "exists and is not a folder"));
        }
        std::fs::create_dir_all(dir).map_err(|e| VaeError::io(dir, e))?;
        let path = dir.join(LOCK_FILE);
        let me = std::process::id();
        for _ in 0..2 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut file) => {
                    write!(file, "{me}").map_err(|e| VaeError::io(&path, e))?;
                    return Ok(Self { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let holder = std::fs::read_to_string(&path)
                        .ok()
                        .and_then(|s| s.trim().parse::<u32>().ok());
                    if let Some(pid) = holder.filter(|&pid| alive(pid)) {
                        return Err(VaeError::model(
                            dir,
                            format!(
                                "is being trained by process {pid}{} (its lock `{LOCK_FILE}`); \
                                 stop that one first, or delete the lock if it is no \
                                 longer running",
                                if pid == me { ", this one" } else { "" }
                            ),
                        ));
                    }
                    // Left by a process that is gone: take it over.
                    std::fs::remove_file(&path).map_err(|e| VaeError::io(&path, e))?;
                }
                Err(e) => return Err(VaeError::io(&path, e)),
            }
        }
        Err(VaeError::model(
            dir,
            format!("its lock `{LOCK_FILE}` keeps coming back: another training started"),
        ))
    }
}

impl Drop for TrainLock {
    fn drop(&mut self) {
        // Only our own lock: a folder taken over after this process was thought gone is not.
        let ours = std::fs::read_to_string(&self.path)
            .is_ok_and(|s| s.trim() == std::process::id().to_string());
        if ours {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Whether process `pid` is running. Where that cannot be asked, it is assumed to be.
fn alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        return Path::new("/proc").join(pid.to_string()).exists();
    }
    if cfg!(unix) {
        return std::process::Command::new("kill")
            .args(["-0", &pid.to_string()])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_training_per_folder_and_a_dead_holders_lock_is_taken_over() {
        let dir = std::env::temp_dir().join(format!("meshvae-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let folder = ModelFolder::new(&dir);
        let lock = TrainLock::acquire(&folder).unwrap();
        let path = dir.join(LOCK_FILE);
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            std::process::id().to_string()
        );
        // A second training of the folder, here or in another process, is refused.
        let err = TrainLock::acquire(&folder).unwrap_err().to_string();
        assert!(
            err.contains("is being trained by process") && err.contains("this one"),
            "{err}"
        );
        drop(lock);
        assert!(!path.exists(), "the lock is released");
        // A lock left by a process that no longer runs (pid 2³¹ − 2 is never one on Linux).
        if cfg!(unix) {
            std::fs::write(&path, "2147483646").unwrap();
            let taken = TrainLock::acquire(&folder).unwrap();
            assert_eq!(
                std::fs::read_to_string(&path).unwrap(),
                std::process::id().to_string()
            );
            drop(taken);
        }
        // A file where the folder should be.
        let file = dir.join("not-a-folder");
        std::fs::write(&file, "x").unwrap();
        let err = TrainLock::acquire(&ModelFolder::new(&file)).unwrap_err();
        assert!(err.to_string().contains("not a folder"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
