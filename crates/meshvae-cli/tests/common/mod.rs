//! Helpers shared by the CLI tests: run the binary, make a scratch folder.

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs the `meshvae` binary built for these tests.
pub fn meshvae(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_meshvae"))
        .args(args)
        .output()
        .expect("the meshvae binary runs")
}

/// An empty folder of the system's temporary directory, unique to this test process.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("meshvae-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
