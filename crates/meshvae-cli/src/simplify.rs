//! `meshvae simplify <MESH|SET> [--ratio 0.5] [--lambda 0.001] --out coarse.obj [--json]`

use crate::CliError;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SimplifyArgs {
    /// A mesh file, or a mesh set (its template, frame 0, is simplified).
    input: PathBuf,
    /// The coarse mesh to write (OBJ, OFF, PLY or GLB by extension).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &SimplifyArgs) -> Result<(), CliError> {
    let _ = (&args.input, &args.out);
    Err(CliError::argument("simplify", "not built yet"))
}
