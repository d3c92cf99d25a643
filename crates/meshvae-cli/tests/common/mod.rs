//! Helpers shared by the CLI tests: run the binary, check its outcome, make a scratch folder.
// Each test binary compiles this module and uses only some of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `meshvae` binary built for these tests.
pub fn meshvae(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_meshvae"))
        .args(args)
        .output()
        .expect("the meshvae binary runs")
}

/// A test's folder in the system's temporary directory, removed with what it holds when dropped
/// unless the test is failing (its models run to hundreds of MB; a failure's files are kept to
/// look at).
#[derive(Debug)]
pub struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

/// An empty folder of the system's temporary directory, unique to this test process.
pub fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("meshvae-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

/// A scratch folder `name` with a synthetic set of `per_label` meshes per label in `set/`:
/// (the folder, the set, `model/` beside it, not created).
pub fn synth_case(name: &str, per_label: usize) -> (Scratch, PathBuf, PathBuf) {
    let dir = scratch(name);
    let (set, model) = (dir.join("set"), dir.join("model"));
    let n = per_label.to_string();
    ok(&meshvae(&["synth", "--out", s(&set), "--per-label", &n]));
    (dir, set, model)
}

/// `meshvae train SET --out OUT --epochs N --batch 4 --latent 16 --quiet EXTRA…`: a short run
/// on a small set.
pub fn train_short(set: &Path, out: &Path, epochs: usize, extra: &[&str]) -> Output {
    let n = epochs.to_string();
    let mut args = vec![
        "train",
        s(set),
        "--out",
        s(out),
        "--epochs",
        &n,
        "--batch",
        "4",
    ];
    args.extend_from_slice(&["--latent", "16", "--quiet"]);
    args.extend_from_slice(extra);
    meshvae(&args)
}

/// The command's stdout; fails the test (showing stderr) when it did not succeed.
pub fn ok(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "failed: {err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The command failed with `code`, without a panic, and its message names `part`.
pub fn fails_with(out: &Output, code: i32, part: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "stderr: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert!(err.contains(part), "stderr lacks {part:?}: {err}");
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}
