//! `meshvae info <SET> [--json]`

use crate::{CliError, print_warnings};
use mesh_io::QualityReport;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct InfoArgs {
    /// A folder of mesh files (OBJ, OFF, PLY, GLB), a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// Print one JSON object (keys: meshes, vertices, faces, edges, boundary_edges,
    /// nonmanifold_edges, degenerate_faces, components, unused_vertices, bbox_diagonal (frame 0),
    /// set_bbox_diagonal (all frames), median_frame_diagonal, outlier_frames (index, name,
    /// diagonal of frames whose extent is more than twice or less than half the median's),
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
        out!("{text}");
        return Ok(());
    }
    out!("{}", args.set.display());
    out!("  meshes               {}", report.meshes);
    out!("  vertices             {}", report.vertices);
    out!("  faces                {}", report.faces);
    out!("  edges                {}", report.edges);
    out!("  boundary edges       {}", report.boundary_edges);
    out!("  non-manifold edges   {}", report.nonmanifold_edges);
    out!("  degenerate faces     {}", report.degenerate_faces);
    out!("  components           {}", report.components);
    out!("  unused vertices      {}", report.unused_vertices);
    out!("  Euler characteristic {}", report.euler_characteristic);
    out!(
        "  bbox diagonal        {:.6} (frame 0)",
        report.bbox_diagonal
    );
    out!(
        "                       {:.6} (all frames), median frame {:.6}",
        report.set_bbox_diagonal,
        report.median_frame_diagonal
    );
    for f in &report.outlier_frames {
        eprintln!(
            "warning: frame {} ({}) has a bounding-box diagonal of {:.6}, far from the median \
             frame's {:.6}: a stray vertex, another unit or a damaged file?",
            f.index, f.name, f.diagonal, report.median_frame_diagonal
        );
    }
    match &report.labels {
        Some(labels) => out!("  labels               {}", labels.join(", ")),
        None => out!("  labels               none"),
    }
    Ok(())
}
