//! `cargo xtask <task>`: project chores that are not part of the `meshvae` command.
//!
//! - `cargo xtask datasets [--pack DIR]`: checks that every standard data set is unpacked and
//!   has the expected counts; with `--pack`, writes each as a `.mvset` cache into DIR.

use clap::{Parser, Subcommand};
use mesh_io::{QualityReport, datasets};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Check the standard data sets (../shared/datasets or $MESHVAE_DATASETS) and optionally
    /// cache them.
    Datasets {
        /// Write `<name>.mvset` caches into this folder.
        #[arg(long)]
        pack: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    match Cli::parse().task {
        Task::Datasets { pack } => check_datasets(pack),
    }
}

fn check_datasets(pack: Option<PathBuf>) -> ExitCode {
    let Some(root) = datasets::root() else {
        eprintln!("no data sets found: run ../shared/datasets/unpack or set MESHVAE_DATASETS");
        return ExitCode::FAILURE;
    };
    println!("data sets in {}", root.display());
    let mut failures = 0;
    for &(name, meshes, vertices, faces, boundary) in datasets::KNOWN {
        let Some(dir) = datasets::find(name) else {
            println!("  {name:16} missing (run ../shared/datasets/unpack {name})");
            failures += 1;
            continue;
        };
        let set = match mesh_io::load_set(&dir) {
            Ok(loaded) => loaded.value,
            Err(e) => {
                println!("  {name:16} error: {e}");
                failures += 1;
                continue;
            }
        };
        let r = QualityReport::of(&set);
        let expected = (meshes, vertices, faces, boundary);
        let ok = (r.meshes, r.vertices, r.faces, r.boundary_edges) == expected;
        println!(
            "  {name:16} {} meshes, {} vertices, {} faces, {} boundary edges: {}",
            r.meshes,
            r.vertices,
            r.faces,
            r.boundary_edges,
            if ok { "ok" } else { "UNEXPECTED" }
        );
        failures += usize::from(!ok);
        if let Some(out) = &pack {
            let path = out.join(format!("{name}.mvset"));
            let written = std::fs::create_dir_all(out)
                .map_err(|e| e.to_string())
                .and_then(|()| mesh_io::cache::write_cache(&path, &set).map_err(|e| e.to_string()));
            match written {
                Ok(()) => println!("  {:16} wrote {}", "", path.display()),
                Err(e) => {
                    println!("  {name:16} cache error: {e}");
                    failures += 1;
                }
            }
        }
    }
    if failures == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
