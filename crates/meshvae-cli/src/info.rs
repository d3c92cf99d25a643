//! `meshvae info <SET> [--json]`

use crate::{CliError, print_warnings};
use mesh_io::QualityReport;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct InfoArgs {
    /// A folder of mesh files (OBJ, OFF, PLY, GLB), a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// Print one JSON object (keys: meshes, vertices, faces, edges, boundary_edges,
    /// nonmanifold_edges, degenerate_faces, components, unused_vertices, bbox_diagonal,
    /// euler_characteristic, labels).
    #[arg(long)]
    json: bool,
}

pub fn run(args: &InfoArgs) -> Result<(), CliError> {
    let loaded = mesh_io::load_set(&args.set)?;
    print_warnings(&loaded.warnings);
    let report = QualityReport::of(&loaded.value);
    if args.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| CliError::argument("--json", e.to_string()))?;
        println!("{text}");
        return Ok(());
    }
    println!("{}", args.set.display());
    println!("  meshes               {}", report.meshes);
    println!("  vertices             {}", report.vertices);
    println!("  faces                {}", report.faces);
    println!("  edges                {}", report.edges);
    println!("  boundary edges       {}", report.boundary_edges);
    println!("  non-manifold edges   {}", report.nonmanifold_edges);
    println!("  degenerate faces     {}", report.degenerate_faces);
    println!("  components           {}", report.components);
    println!("  unused vertices      {}", report.unused_vertices);
    println!("  Euler characteristic {}", report.euler_characteristic);
    println!("  bbox diagonal        {:.6}", report.bbox_diagonal);
    match &report.labels {
        Some(labels) => println!("  labels               {}", labels.join(", ")),
        None => println!("  labels               none"),
    }
    Ok(())
}
