//! The λ sweep of docs/benchmarks.md ("Mesh simplification"): for each template and λ, the
//! coarse mesh's edge-length and cluster-size spread and its geometric error.
//!
//! `cargo run --release -p qem-simplify --example sweep [-- SET...]` (default: horse-gallop,
//! samba, elephant-gallop; sets are looked up with `mesh_io::datasets::find`).

use qem_simplify::{SimplifyConfig, SimplifyReport, Target, UniformityReport, simplify};
use std::time::Instant;

const LAMBDAS: &[f64] = &[0.0, 1e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = ["horse-gallop", "samba", "elephant-gallop"]
            .map(String::from)
            .to_vec();
    }
    println!(
        "| set | λ | edge_cv | cluster_cv | cluster_area_cv | cluster_max | geometric_error_rel | valid | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for name in &names {
        let Some(dir) = mesh_io::datasets::find(name) else {
            eprintln!("{name}: not found, skipped");
            continue;
        };
        let fine = mesh_io::load_set(&dir)?.value.template();
        for &lambda in LAMBDAS {
            let config = SimplifyConfig {
                target: Target::Ratio(0.5),
                lambda,
            };
            let start = Instant::now();
            let s = simplify(&fine, &config)?;
            let seconds = start.elapsed().as_secs_f64();
            let r = SimplifyReport::of(&fine, &s, lambda, seconds);
            let u = UniformityReport::of(&fine, &s);
            // Manifold, no flipped or degenerate face, Euler characteristic and target kept.
            let valid = r.manifold
                && r.flipped_faces == 0
                && r.degenerate_faces == 0
                && r.euler_in == r.euler_out
                && r.vertices_out == fine.vertex_count().div_ceil(2);
            println!(
                "| {name} | {lambda:e} | {:.3} | {:.3} | {:.3} | {} | {:.2e} | {valid} | {:.3} |",
                r.edge_cv,
                r.cluster_cv,
                u.cluster_area_cv,
                r.cluster_max,
                r.geometric_error_rel,
                seconds
            );
        }
    }
    Ok(())
}
