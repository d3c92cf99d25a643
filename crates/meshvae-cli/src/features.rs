//! `meshvae features <SET> --out FILE` and `meshvae roundtrip <SET> [--json]`

use crate::CliError;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct FeaturesArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// The safetensors file to write.
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
pub struct RoundtripArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

pub fn run_features(args: &FeaturesArgs) -> Result<(), CliError> {
    let _ = (&args.set, &args.out);
    Err(CliError::argument("features", "not built yet"))
}

pub fn run_roundtrip(args: &RoundtripArgs) -> Result<(), CliError> {
    let _ = (&args.set, args.json);
    Err(CliError::argument("roundtrip", "not built yet"))
}
