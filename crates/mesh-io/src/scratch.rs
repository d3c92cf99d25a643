//! [`ScratchFile`]: a path for a test's file in a temporary folder of its own, removed with the
//! folder when dropped (tests run in parallel threads, so no two share a folder).

use std::path::{Path, PathBuf};

/// A file path in `<temp dir>/<prefix>-<pid>-<name>/<name>`; the folder is created now and
/// removed, with whatever it holds, when the value is dropped.
#[derive(Debug)]
pub struct ScratchFile(PathBuf);

impl ScratchFile {
    /// Creates the folder. Errors: the folder cannot be created.
    pub fn new(prefix: &str, name: &str) -> std::io::Result<Self> {
        let pid = std::process::id();
        let dir = std::env::temp_dir().join(format!("{prefix}-{pid}-{name}"));
        std::fs::create_dir_all(&dir)?;
        Ok(Self(dir.join(name)))
    }
}

impl Drop for ScratchFile {
    fn drop(&mut self) {
        if let Some(dir) = self.0.parent() {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

impl AsRef<Path> for ScratchFile {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl std::ops::Deref for ScratchFile {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_folder_lives_as_long_as_the_value() {
        let file = ScratchFile::new("mesh-io-scratch", "a.txt").unwrap();
        std::fs::write(&file, b"x").unwrap();
        let dir = file.parent().unwrap().to_path_buf();
        assert!(dir.is_dir() && file.is_file());
        drop(file);
        assert!(!dir.exists());
    }
}
