//! `meshvae roundtrip`: features → meshes for every frame of a set, and the errors of the
//! reconstruction against the originals (how exactly the ACAP inverse recovers the shapes).

use crate::CliError;
use crate::features::{FeatureFlags, load_and_extract};
use deform_features::{FeatureOptions, Normalization, Reconstructor};
use mesh_io::MeshSet;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct RoundtripArgs {
    /// A folder of mesh files, a multi-frame .glb/.gltf, or a .mvset cache.
    set: PathBuf,
    /// Print one JSON object (keys: frames, vertices, rms, max, rms_rel, max_rel, worst_frame,
    /// worst_frame_rms_rel, worst_vertex, seconds_features, seconds_reconstruct, options, and
    /// worst_vertices with --worst).
    #[arg(long)]
    json: bool,
    /// Also list the N vertices with the largest error over all frames (vertex, max_rel,
    /// degree, boundary, rest_position).
    #[arg(long, default_value_t = 0)]
    worst: usize,
    #[command(flatten)]
    flags: FeatureFlags,
}

/// Errors of a reconstruction against the original frames, centroids aligned.
#[derive(Debug, serde::Serialize)]
struct RoundtripReport {
    frames: usize,
    vertices: usize,
    /// RMS over all vertices of all frames of the centroid-aligned distance.
    rms: f64,
    max: f64,
    /// The same with each frame's distances divided by that frame's bounding-box diagonal.
    rms_rel: f64,
    max_rel: f64,
    worst_frame: String,
    worst_frame_rms_rel: f64,
    worst_vertex: WorstVertex,
    seconds_features: f64,
    seconds_reconstruct: f64,
    options: FeatureOptions,
    /// The `--worst N` vertices by their largest error over the frames (absent without it).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    worst_vertices: Vec<VertexError>,
}

/// One vertex's largest error over all frames, relative to each frame's diagonal.
#[derive(Debug, Clone, serde::Serialize)]
struct VertexError {
    vertex: usize,
    max_rel: f64,
    degree: usize,
    boundary: bool,
    rest_position: [f32; 3],
}

#[derive(Debug, Clone, serde::Serialize)]
struct WorstVertex {
    frame: String,
    vertex: usize,
    error_rel: f64,
    boundary: bool,
    degree: usize,
}

pub fn run(args: &RoundtripArgs) -> Result<(), CliError> {
    let (set, extractor, out, seconds_features) = load_and_extract(&args.set, &args.flags)?;
    // What the network sees: normalised, stored as f32; the inverse works from that only.
    let normalization = Normalization::fit([&out.features])?;
    let stored = normalization.apply(&out.features);
    let raw = normalization.invert(&stored);

    let start = Instant::now();
    let reconstructor = Reconstructor::new(extractor.rest())?;
    let meshes = reconstructor.reconstruct_all(&raw)?;
    let seconds_reconstruct = start.elapsed().as_secs_f64();

    let boundary = boundary_vertices(&set);
    let degree: Vec<usize> = (0..set.vertex_count())
        .map(|v| extractor.rest().ring(v).0.len())
        .collect();
    let n = set.vertex_count();
    let (mut sum2, mut sum2_rel, mut max, mut max_rel) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut worst_frame = (0usize, 0.0f64);
    let mut worst_vertex = (0usize, 0usize, 0.0f64);
    let mut per_vertex_max = vec![0.0f64; n];
    for (f, rec) in meshes.iter().enumerate() {
        let original: Vec<[f64; 3]> = set.frame(f).iter().map(|p| p.map(f64::from)).collect();
        let diagonal = mesh_io::bbox_diagonal(set.frame(f)).max(f64::MIN_POSITIVE);
        let (c_rec, c_orig) = (centroid(rec), centroid(&original));
        let mut frame_sum2 = 0.0;
        for (v, (a, b)) in rec.iter().zip(&original).enumerate() {
            let d2: f64 = (0..3)
                .map(|k| ((a[k] - c_rec[k]) - (b[k] - c_orig[k])).powi(2))
                .sum();
            let d = d2.sqrt();
            frame_sum2 += d2;
            max = max.max(d);
            let rel = d / diagonal;
            max_rel = max_rel.max(rel);
            per_vertex_max[v] = per_vertex_max[v].max(rel);
            if rel > worst_vertex.2 {
                worst_vertex = (f, v, rel);
            }
        }
        sum2 += frame_sum2;
        sum2_rel += frame_sum2 / (diagonal * diagonal);
        let frame_rms_rel = (frame_sum2 / n as f64).sqrt() / diagonal;
        if frame_rms_rel > worst_frame.1 {
            worst_frame = (f, frame_rms_rel);
        }
    }
    let count = (meshes.len() * n) as f64;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| per_vertex_max[b].total_cmp(&per_vertex_max[a]));
    let rest = set.frame(args.flags.rest_index(&set)?);
    let worst_vertices = order
        .iter()
        .take(args.worst)
        .map(|&v| VertexError {
            vertex: v,
            max_rel: per_vertex_max[v],
            degree: degree[v],
            boundary: boundary[v],
            rest_position: rest[v],
        })
        .collect();
    let report = RoundtripReport {
        frames: set.len(),
        vertices: n,
        rms: (sum2 / count).sqrt(),
        max,
        rms_rel: (sum2_rel / count).sqrt(),
        max_rel,
        worst_frame: set.names()[worst_frame.0].clone(),
        worst_frame_rms_rel: worst_frame.1,
        worst_vertex: WorstVertex {
            frame: set.names()[worst_vertex.0].clone(),
            vertex: worst_vertex.1,
            error_rel: worst_vertex.2,
            boundary: boundary[worst_vertex.1],
            degree: degree[worst_vertex.1],
        },
        seconds_features,
        seconds_reconstruct,
        options: args.flags.options(),
        worst_vertices,
    };
    if args.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| CliError::argument("--json", e.to_string()))?;
        out!("{text}");
    } else {
        out!("{}", args.set.display());
        out!(
            "  frames × vertices    {} × {}",
            report.frames,
            report.vertices
        );
        out!(
            "  rms / max            {:.3e} / {:.3e}",
            report.rms,
            report.max
        );
        out!(
            "  rms_rel / max_rel    {:.3e} / {:.3e} (of the bounding-box diagonal)",
            report.rms_rel,
            report.max_rel
        );
        out!(
            "  worst frame          {} (rms_rel {:.3e})",
            report.worst_frame,
            report.worst_frame_rms_rel
        );
        let w = &report.worst_vertex;
        out!(
            "  worst vertex         {} in frame {} ({:.3e}, degree {}, {})",
            w.vertex,
            w.frame,
            w.error_rel,
            w.degree,
            if w.boundary { "boundary" } else { "interior" }
        );
        out!(
            "  seconds              features {:.3}, reconstruct {:.3}",
            report.seconds_features,
            report.seconds_reconstruct
        );
        if !report.worst_vertices.is_empty() {
            out!("  vertex  max_rel    degree  boundary  rest position");
            for w in &report.worst_vertices {
                out!(
                    "  {:6}  {:.3e}  {:6}  {:8}  {:?}",
                    w.vertex,
                    w.max_rel,
                    w.degree,
                    w.boundary,
                    w.rest_position
                );
            }
        }
    }
    Ok(())
}

fn centroid(points: &[[f64; 3]]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for p in points {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    c.map(|x| x / points.len().max(1) as f64)
}

/// Whether each vertex lies on a boundary edge (an edge with one incident face).
fn boundary_vertices(set: &MeshSet) -> Vec<bool> {
    let mut edges: Vec<(u32, u32)> = set
        .faces()
        .iter()
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    let mut boundary = vec![false; set.vertex_count()];
    for run in edges.chunk_by(|a, b| a == b) {
        if run.len() == 1 {
            boundary[run[0].0 as usize] = true;
            boundary[run[0].1 as usize] = true;
        }
    }
    boundary
}
