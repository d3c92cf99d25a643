//! `meshvae pack <SET> --out FILE.mvset|FILE.glb`

use crate::{CliError, print_warnings};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct PackArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// The file to write, atomically: `*.mvset` for the binary cache, `*.glb` for one glTF file
    /// holding every frame as a morph target with an animation that plays them.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &PackArgs) -> Result<(), CliError> {
    let ext = args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let write = match ext.as_deref() {
        Some("mvset") => mesh_io::cache::write_cache,
        Some("glb") => mesh_io::glb::write_glb_set,
        _ => {
            return Err(CliError::argument(
                "--out",
                format!(
                    "{}: expected a .mvset or .glb file name",
                    args.out.display()
                ),
            ));
        }
    };
    let loaded = mesh_io::load_set(&args.set)?;
    print_warnings(&loaded.warnings);
    write(&args.out, &loaded.value)?;
    eprintln!(
        "wrote {} ({} meshes of {} vertices)",
        args.out.display(),
        loaded.value.len(),
        loaded.value.vertex_count()
    );
    Ok(())
}
