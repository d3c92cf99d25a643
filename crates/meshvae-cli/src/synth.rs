//! `meshvae synth --out DIR [--seed S] [--per-label N] [--rings R --segments S --cap-rings C]`

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
    /// Rings of vertices along the capsule's cylinder (the default 40 gives 2,498 vertices with
    /// the other defaults; vertices = 2 + segments × (rings + 2 × cap rings)).
    #[arg(long, default_value_t = SynthConfig::default().rings)]
    rings: usize,
    /// Vertices around each ring.
    #[arg(long, default_value_t = SynthConfig::default().segments)]
    segments: usize,
    /// Rings of each hemispherical cap.
    #[arg(long, default_value_t = SynthConfig::default().cap_rings)]
    cap_rings: usize,
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
        rings: args.rings,
        segments: args.segments,
        cap_rings: args.cap_rings,
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
