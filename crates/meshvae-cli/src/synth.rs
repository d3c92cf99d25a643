//! `meshvae synth --out DIR [--seed S]`

use crate::CliError;
use mesh_io::synth::{SynthConfig, generate};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SynthArgs {
    /// Folder to write the OBJ files and labels.csv into (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Seed of the shape parameters; the same seed gives the same set.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Meshes per label (`bend`, `twist`).
    #[arg(long, default_value_t = SynthConfig::default().meshes_per_label)]
    per_label: usize,
}

pub fn run(args: &SynthArgs) -> Result<(), CliError> {
    if args.out.is_file() {
        return Err(CliError::argument(
            "--out",
            format!("{} is a file, not a folder", args.out.display()),
        ));
    }
    let config = SynthConfig {
        seed: args.seed,
        meshes_per_label: args.per_label,
        ..SynthConfig::default()
    };
    let synth = generate(&config)?;
    let files = mesh_io::write_folder(&args.out, &synth.set)?;
    eprintln!(
        "wrote {} meshes of {} vertices and labels.csv to {}",
        files.len(),
        synth.set.vertex_count(),
        args.out.display()
    );
    Ok(())
}
