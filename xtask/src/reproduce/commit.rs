//! Which code made a record: the commit the xtask binary was built from, as `git describe` names
//! it, and whether tracked files had uncommitted changes; and the commits that trained a model
//! folder ([`TrainedBy`]).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;
use std::process::Command;

/// The code of a run: [`RunResult::commit`](super::record::RunResult::commit).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Commit {
    /// `git describe --always --abbrev=12`: the commit's hash, or the nearest tag and the
    /// hash where a tag precedes it.
    pub describe: String,
    /// Whether tracked files differed from the commit: the numbers then come from code that
    /// no commit holds.
    pub dirty: bool,
}

impl Commit {
    /// The commit checked out in `dir`, or `None` where `dir` is not a git work tree (a
    /// source archive) or git is missing.
    pub fn of(dir: &Path) -> Option<Self> {
        let git = |args: &[&str]| {
            let out = Command::new("git")
                .arg("-C")
                .arg(dir)
                .args(args)
                .output()
                .ok()?;
            out.status
                .success()
                .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
        };
        let describe = git(&["describe", "--always", "--abbrev=12"])?;
        // Untracked files (run folders, notes) and the documentation (the records and pages a
        // reproduction writes) do not change what the code computes.
        let status = git(&[
            "status",
            "--porcelain",
            "--untracked-files=no",
            "--",
            ".",
            ":(exclude)docs",
        ])?;
        Some(Self {
            describe,
            dirty: !status.is_empty(),
        })
    }

    /// The commit this binary was compiled from (its build script asked git), or `None` for
    /// a build outside a git work tree. What a record names: the tree the binary runs beside
    /// may have moved on since the build.
    pub fn compiled() -> Option<Self> {
        Some(Self {
            describe: option_env!("XTASK_COMMIT")?.to_string(),
            dirty: option_env!("XTASK_COMMIT_DIRTY") == Some("true"),
        })
    }

    /// The commit's hash as `git describe` abbreviates it (without a tag).
    pub fn hash(&self) -> &str {
        match self.describe.rsplit_once("-g") {
            Some((_, hash)) if hash.chars().all(|c| c.is_ascii_hexdigit()) => hash,
            _ => &self.describe,
        }
    }
}

/// The commits that trained a model folder, kept beside it (`<folder>.commits.json`, where
/// `meshvae train --force` does not remove it): a run resumed by other code, or a finished
/// folder evaluated again by other code, would otherwise be recorded as this code's alone.
pub struct TrainedBy {
    path: std::path::PathBuf,
}

impl TrainedBy {
    pub fn of(model_dir: &Path) -> Self {
        let mut name = model_dir.as_os_str().to_owned();
        name.push(".commits.json");
        Self { path: name.into() }
    }

    /// The commits so far, in order; `None` where the folder's training was not recorded (no
    /// file, or an unreadable one).
    pub fn read(&self) -> Option<Vec<Commit>> {
        let text = std::fs::read_to_string(&self.path).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Notes that `commit` trains the folder now: a fresh start begins the list, a resumed run
    /// adds it unless it is the last one already. Code outside git is not noted.
    pub fn note(&self, commit: Option<&Commit>, fresh: bool) -> std::io::Result<()> {
        let Some(commit) = commit else {
            return Ok(());
        };
        let mut list = match (fresh, self.read()) {
            (true, _) => Vec::new(),
            (false, Some(list)) => list,
            // Resuming a folder trained before its commits were kept.
            (false, None) => vec![Commit {
                describe: "unrecorded".into(),
                dirty: false,
            }],
        };
        if list.last() != Some(commit) {
            list.push(commit.clone());
        }
        if let Some(parent) = self.path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        let text = serde_json::to_string_pretty(&list).map_err(std::io::Error::other)?;
        mesh_io::atomic::write_bytes_atomic(&self.path, text.as_bytes())
            .map_err(std::io::Error::other)
    }

    /// What a record of the folder, written by `commit`, says besides its own commit: `None`
    /// when `commit` alone trained it; otherwise every commit that did (`unrecorded` for
    /// training before the commits were kept; an empty list when none is known).
    pub fn for_record(&self, commit: Option<&Commit>) -> Option<Vec<Commit>> {
        // Outside git nothing is known, and the record's missing commit says so already.
        commit?;
        match self.read() {
            Some(list) if list.iter().all(|c| Some(c) == commit) && !list.is_empty() => None,
            Some(list) => Some(list),
            None => Some(Vec::new()),
        }
    }
}

impl fmt::Display for Commit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.dirty {
            write!(f, "{} with uncommitted changes", self.describe)
        } else {
            f.write_str(&self.describe)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trained_by_lists_every_commit_that_trained_a_folder() {
        let dir = std::env::temp_dir().join(format!("trained-by-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let by = TrainedBy::of(&dir.join("ours"));
        let (a, b) = (
            Commit {
                describe: "aaaaaaa".into(),
                dirty: false,
            },
            Commit {
                describe: "bbbbbbb".into(),
                dirty: true,
            },
        );
        // Nothing kept: a finished folder evaluated again names no known training.
        assert_eq!(by.for_record(Some(&a)), Some(vec![]));
        assert_eq!(by.for_record(None), None);
        // One commit trained it, resumed by the same: nothing besides the record's own.
        by.note(Some(&a), true).unwrap();
        by.note(Some(&a), false).unwrap();
        assert_eq!(by.read(), Some(vec![a.clone()]));
        assert_eq!(by.for_record(Some(&a)), None);
        // Resumed by other code, or evaluated by it: every commit, in order.
        by.note(Some(&b), false).unwrap();
        assert_eq!(by.for_record(Some(&b)), Some(vec![a.clone(), b.clone()]));
        assert_eq!(by.for_record(Some(&a)), Some(vec![a.clone(), b.clone()]));
        // A fresh start forgets the earlier training.
        by.note(Some(&b), true).unwrap();
        assert_eq!(by.for_record(Some(&b)), None);
        // A folder trained before the commits were kept, resumed now.
        std::fs::remove_file(dir.join("ours.commits.json")).unwrap();
        by.note(Some(&a), false).unwrap();
        let unrecorded = by.for_record(Some(&a)).unwrap();
        assert_eq!(unrecorded.len(), 2);
        assert_eq!(unrecorded[0].describe, "unrecorded");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_hash_is_read_with_or_without_a_tag() {
        let commit = |describe: &str| Commit {
            describe: describe.into(),
            dirty: false,
        };
        assert_eq!(commit("e5c08e2a1b2c").hash(), "e5c08e2a1b2c");
        assert_eq!(commit("v0.1-14-ge5c08e2a1b2c").hash(), "e5c08e2a1b2c");
        assert_eq!(commit("release-good").hash(), "release-good");
        let dirty = Commit {
            dirty: true,
            ..commit("e5c08e2a1b2c")
        };
        assert_eq!(dirty.to_string(), "e5c08e2a1b2c with uncommitted changes");
    }

    #[test]
    fn the_binary_names_the_commit_it_was_built_from() {
        // Built just now from this tree: the stamp is the tree's commit.
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        assert_eq!(Commit::compiled(), Commit::of(root));
    }

    #[test]
    fn this_workspace_names_its_commit_or_nothing() {
        let here = Path::new(env!("CARGO_MANIFEST_DIR"));
        // A source archive has no .git; a clone always has a commit.
        if let Some(commit) = Commit::of(here) {
            assert!(!commit.describe.is_empty());
            assert!(commit.hash().len() >= 7, "{commit:?}");
        }
        let nowhere = std::env::temp_dir().join(format!("xtask-no-git-{}", std::process::id()));
        std::fs::create_dir_all(&nowhere).unwrap();
        // Outside any work tree (the temporary folder is not inside one on a sane machine).
        if Commit::of(&std::env::temp_dir()).is_none() {
            assert!(Commit::of(&nowhere).is_none());
        }
        let _ = std::fs::remove_dir_all(&nowhere);
    }

    #[test]
    fn only_code_changes_make_a_tree_dirty() {
        let dir = std::env::temp_dir().join(format!("meshvae-commit-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("docs")).unwrap();
        let git = |args: &[&str]| {
            let ok = Command::new("git")
                .arg("-C")
                .arg(&dir)
                .args(["-c", "user.name=t", "-c", "user.email=t@t"])
                .args(args)
                .status()
                .is_ok_and(|s| s.success());
            assert!(ok, "git {args:?}");
        };
        std::fs::write(dir.join("code.rs"), "1").unwrap();
        std::fs::write(dir.join("docs/record.json"), "1").unwrap();
        git(&["init", "-q"]);
        git(&["add", "."]);
        git(&["commit", "-q", "-m", "c"]);
        assert!(!Commit::of(&dir).unwrap().dirty);
        std::fs::write(dir.join("docs/record.json"), "2").unwrap();
        assert!(
            !Commit::of(&dir).unwrap().dirty,
            "a changed record is not code"
        );
        std::fs::write(dir.join("code.rs"), "2").unwrap();
        assert!(Commit::of(&dir).unwrap().dirty, "changed code is");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
