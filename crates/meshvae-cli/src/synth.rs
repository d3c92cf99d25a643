//! `meshvae synth --out DIR [--seed S]`

use crate::CliError;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SynthArgs {
    /// Folder to write the OBJ files and labels.csv into (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Seed of the shape parameters; the same seed gives the same set.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub fn run(args: &SynthArgs) -> Result<(), CliError> {
    let _ = (&args.out, args.seed);
    Err(CliError::argument("synth", "the synthetic generator is not built yet"))
}
