//! Stamps the binary with the commit of the source it is compiled from (`git describe`, and
//! whether tracked code differed from it), so that a record names the code that made it even
//! when the binary runs beside another checkout or after the tree has moved on.

use std::path::Path;
use std::process::Command;

fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("-C")
        .arg(root)
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    // Read when the script runs, not baked in when it is compiled: a build-script binary is
    // reused by every checkout that shares the target folder, and would stamp the commit of
    // whichever checkout compiled it.
    let manifest = std::env::var_os("CARGO_MANIFEST_DIR").map(std::path::PathBuf::from);
    let Some(manifest) = manifest.as_deref() else {
        return;
    };
    let root = manifest.parent().unwrap_or(manifest);
    // Again whenever the code or the commit changes: every top-level entry but the pages and
    // the build output (directories are scanned whole), and git's HEAD, index and refs.
    if let Ok(entries) = std::fs::read_dir(root) {
        for entry in entries.flatten() {
            let name = entry.file_name();
            if !matches!(name.to_str(), Some("docs" | "target" | ".git")) {
                println!("cargo:rerun-if-changed={}", entry.path().display());
            }
        }
    }
    for what in ["HEAD", "index", "packed-refs", "refs"] {
        if let Some(path) = git(root, &["rev-parse", "--git-path", what]) {
            println!("cargo:rerun-if-changed={}", root.join(path).display());
        }
    }
    let Some(describe) = git(root, &["describe", "--always", "--abbrev=12"]) else {
        return; // not a git work tree: the records name no commit
    };
    // As `Commit::of`: untracked files and the pages do not change what the code computes.
    let status = git(
        root,
        &[
            "status",
            "--porcelain",
            "--untracked-files=no",
            "--",
            ".",
            ":(exclude)docs",
        ],
    );
    println!("cargo:rustc-env=XTASK_COMMIT={describe}");
    println!(
        "cargo:rustc-env=XTASK_COMMIT_DIRTY={}",
        status.is_none_or(|s| !s.is_empty())
    );
}
