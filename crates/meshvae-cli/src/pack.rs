//! `meshvae pack <SET> --out FILE.mvset`

use crate::{print_warnings, CliError};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct PackArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or another .mvset.
    set: PathBuf,
    /// The cache file to write (conventionally *.mvset); written atomically.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &PackArgs) -> Result<(), CliError> {
    let loaded = mesh_io::load_set(&args.set)?;
    print_warnings(&loaded.warnings);
    mesh_io::cache::write_cache(&args.out, &loaded.value)?;
    eprintln!(
        "wrote {} ({} meshes of {} vertices)",
        args.out.display(),
        loaded.value.len(),
        loaded.value.vertex_count()
    );
    Ok(())
}
