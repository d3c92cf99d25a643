//! `meshvae simplify <MESH|SET> [--method qem|remesh] [--ratio 0.5] [--lambda 0.001]
//! --out coarse.obj [--json]`

use crate::{CliError, print_warnings};
use mesh_io::TriMesh;
use qem_simplify::{RemeshConfig, SimplifyConfig, SimplifyReport, Target};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args)]
pub struct SimplifyArgs {
    /// A mesh file (OBJ, OFF, PLY, GLB), or a mesh set — a folder or a .mvset cache — whose
    /// template (frame 0) is simplified.
    input: PathBuf,
    /// `qem`: quadric edge collapse with the edge-length term (the paper's method); `remesh`:
    /// isotropic remeshing to the same count (the "uniform remeshing" ablation), clusters by
    /// nearest coarse vertex along the fine edges.
    #[arg(long, value_enum, default_value_t = Method::Qem)]
    method: Method,
    /// Fraction of the vertices to keep, in (0, 1]; the count is rounded up.
    #[arg(long, default_value_t = 0.5)]
    ratio: f64,
    /// QEM only: weight of the edge-length term (lengths in units of the bounding-box
    /// diagonal); 0 gives classical quadric simplification. [default: 0.001]
    #[arg(long)]
    lambda: Option<f64>,
    /// The coarse mesh to write (OBJ, OFF, PLY or GLB by extension), atomically.
    #[arg(long)]
    out: PathBuf,
    /// Print one JSON object, the same keys for both methods (method, vertices_in,
    /// vertices_out, faces_in, faces_out, lambda (null for remesh), edge_cv_in, edge_cv,
    /// cluster_cv, cluster_max, cluster_area_cv, manifold, flipped_faces, degenerate_faces,
    /// euler_in, euler_out, seconds, geometric_error_rel).
    #[arg(long)]
    json: bool,
}

/// How the coarse mesh is made.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    Qem,
    Remesh,
}

pub fn run(args: &SimplifyArgs) -> Result<(), CliError> {
    if mesh_io::MeshFormat::from_path(&args.out).is_none() {
        return Err(CliError::argument(
            "--out",
            format!(
                "{}: unsupported extension (expected .obj, .off, .ply or .glb)",
                args.out.display()
            ),
        ));
    }
    if args.method == Method::Remesh && args.lambda.is_some() {
        return Err(CliError::argument(
            "--lambda",
            "applies to --method qem only (a remeshing has no edge-length weight)",
        ));
    }
    let fine = read_input(&args.input)?;
    let target = Target::Ratio(args.ratio);
    let start = Instant::now();
    let report = match args.method {
        Method::Qem => {
            let lambda = args.lambda.unwrap_or(qem_simplify::DEFAULT_LAMBDA);
            let simplified = qem_simplify::simplify(&fine, &SimplifyConfig { target, lambda })?;
            let seconds = start.elapsed().as_secs_f64();
            mesh_io::write_mesh(&args.out, &simplified.coarse)?;
            SimplifyReport::of(&fine, &simplified, lambda, seconds)
        }
        Method::Remesh => {
            let config = RemeshConfig {
                target,
                ..RemeshConfig::default()
            };
            let remeshed = qem_simplify::remesh(&fine, &config)?;
            let seconds = start.elapsed().as_secs_f64();
            mesh_io::write_mesh(&args.out, &remeshed.coarse)?;
            SimplifyReport::of_remeshed(&fine, &remeshed, seconds)
        }
    };
    if args.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| CliError::argument("--json", e.to_string()))?;
        out!("{text}");
        return Ok(());
    }
    out!("{} -> {}", args.input.display(), args.out.display());
    out!("  method               {}", report.method.as_str());
    out!(
        "  vertices             {} -> {}",
        report.vertices_in,
        report.vertices_out
    );
    out!(
        "  faces                {} -> {}",
        report.faces_in,
        report.faces_out
    );
    match report.lambda {
        Some(lambda) => out!("  lambda               {lambda}"),
        None => out!("  lambda               -"),
    }
    out!(
        "  edge-length CV       {:.4} -> {:.4}",
        report.edge_cv_in,
        report.edge_cv
    );
    out!("  cluster-size CV      {:.4}", report.cluster_cv);
    out!("  largest cluster      {}", report.cluster_max);
    out!("  manifold             {}", report.manifold);
    out!("  flipped faces        {}", report.flipped_faces);
    out!("  degenerate faces     {}", report.degenerate_faces);
    out!(
        "  Euler characteristic {} -> {}",
        report.euler_in,
        report.euler_out
    );
    out!(
        "  geometric error      {:.3e} of the diagonal (RMS)",
        report.geometric_error_rel
    );
    out!("  seconds              {:.3}", report.seconds);
    Ok(())
}

/// A single mesh file as it is; a folder or cache as its template.
fn read_input(input: &Path) -> Result<TriMesh, CliError> {
    if !input.exists() {
        return Err(mesh_io::MeshIoError::Io {
            path: input.into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
        }
        .into());
    }
    let is_cache = input
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mvset"));
    if input.is_dir() || is_cache {
        let loaded = mesh_io::load_set(input)?;
        print_warnings(&loaded.warnings);
        return Ok(loaded.value.template());
    }
    let loaded = mesh_io::read_mesh(input)?;
    print_warnings(&loaded.warnings);
    Ok(loaded.value)
}
