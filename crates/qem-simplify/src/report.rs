//! How even and how faithful a simplification (or a remeshing) is: edge-length and cluster-size
//! spread, flipped faces, the geometric error, and the full report that `meshvae simplify`
//! prints.

use crate::geometry::{area_vector, dot, to_f64};
use crate::manifold::manifold_defect;
use crate::nearest::NearestGrid;
use crate::remesh::{Remeshed, flipped_faces_on_surface};
use crate::simplify::Simplified;
use mesh_io::{Face, Point, QualityReport, TriMesh};
use serde::Serialize;

/// Spread of the coarse mesh's edge lengths and of the clusters. CV = population standard
/// deviation / mean (0 when every value is equal).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UniformityReport {
    pub edge_cv: f64,
    pub edge_mean: f64,
    /// CV of the clusters' vertex counts.
    pub cluster_cv: f64,
    pub cluster_mean: f64,
    /// Fine vertices in the largest cluster.
    pub cluster_max: usize,
    /// CV of the clusters' surface areas on the fine mesh (a vertex owns a third of each face
    /// around it). On an unevenly sampled input, even coarse edges mean clusters of even *area*,
    /// hence uneven counts: this is the "similarly sized region" of the paper.
    pub cluster_area_cv: f64,
}

impl UniformityReport {
    /// The report on `simplified`, the simplification of `fine`.
    pub fn of(fine: &TriMesh, simplified: &Simplified) -> Self {
        Self::of_clusters(fine, &simplified.coarse, &simplified.cluster_of)
    }

    /// The report on `remeshed`, the remeshing of `fine`.
    pub fn of_remeshed(fine: &TriMesh, remeshed: &Remeshed) -> Self {
        Self::of_clusters(fine, &remeshed.coarse, &remeshed.cluster_of)
    }

    /// The report on any coarse mesh of `fine` with the map `cluster_of` (fine vertex → coarse
    /// vertex; entries out of range are ignored).
    pub fn of_clusters(fine: &TriMesh, coarse: &TriMesh, cluster_of: &[u32]) -> Self {
        let lengths = edge_lengths(&coarse.positions, &coarse.faces);
        let mut sizes = vec![0.0; coarse.vertex_count()];
        for &c in cluster_of {
            if let Some(s) = sizes.get_mut(c as usize) {
                *s += 1.0;
            }
        }
        let mut areas = vec![0.0; coarse.vertex_count()];
        for f in &fine.faces {
            let p = f.map(|v| to_f64(fine.positions[v as usize]));
            let third = crate::geometry::norm(area_vector(p[0], p[1], p[2])) / 6.0;
            for &v in f {
                if let Some(&c) = cluster_of.get(v as usize)
                    && let Some(a) = areas.get_mut(c as usize)
                {
                    *a += third;
                }
            }
        }
        let (edge_mean, edge_cv) = mean_cv(&lengths);
        let (cluster_mean, cluster_cv) = mean_cv(&sizes);
        Self {
            edge_cv,
            edge_mean,
            cluster_cv,
            cluster_mean,
            cluster_max: sizes.iter().fold(0.0, |m: f64, &s| m.max(s)) as usize,
            cluster_area_cv: mean_cv(&areas).1,
        }
    }
}

/// Coefficient of variation of the lengths of the (distinct, undirected) edges of `faces`.
pub fn edge_length_cv(positions: &[Point], faces: &[Face]) -> f64 {
    mean_cv(&edge_lengths(positions, faces)).1
}

fn edge_lengths(positions: &[Point], faces: &[Face]) -> Vec<f64> {
    let mut edges: Vec<(u32, u32)> = faces
        .iter()
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
        .into_iter()
        .map(|(a, b)| {
            let (p, q) = (to_f64(positions[a as usize]), to_f64(positions[b as usize]));
            crate::geometry::distance(p, q)
        })
        .collect()
}

/// (mean, std / mean) with the population standard deviation; (0, 0) for no values.
fn mean_cv(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (0.0, 0.0);
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let cv = if mean > 0.0 { var.sqrt() / mean } else { 0.0 };
    (mean, cv)
}

/// Coarse faces whose normal points against the fine face they descend from (dot product < 0).
/// `fine` is the mesh that was simplified.
pub fn flipped_faces(fine: &TriMesh, simplified: &Simplified) -> usize {
    let normal = |positions: &[Point], f: Face| {
        let p = f.map(|v| to_f64(positions[v as usize]));
        area_vector(p[0], p[1], p[2])
    };
    simplified
        .coarse
        .faces
        .iter()
        .zip(&simplified.face_origin)
        .filter(|(face, origin)| {
            let n_fine = normal(&fine.positions, fine.faces[**origin as usize]);
            dot(normal(&simplified.coarse.positions, **face), n_fine) < 0.0
        })
        .count()
}

/// Root-mean-square distance from the vertices of `fine` to the surface of `coarse`, divided by
/// the bounding-box diagonal of `fine`. 0 when `coarse` has no faces or `fine` no extent.
pub fn geometric_error_rel(fine: &TriMesh, coarse: &TriMesh) -> f64 {
    let diagonal = fine.bbox_diagonal();
    if coarse.faces.is_empty() || fine.positions.is_empty() || diagonal <= 0.0 {
        return 0.0;
    }
    let points: Vec<_> = fine.positions.iter().map(|&p| to_f64(p)).collect();
    let triangles = coarse
        .faces
        .iter()
        .map(|f| f.map(|v| to_f64(coarse.positions[v as usize])))
        .collect();
    let grid = NearestGrid::new(triangles, (0..coarse.faces.len() as u32).collect());
    let sum: f64 = points
        .iter()
        .map(|&p| {
            grid.closest(p, |_| true)
                .map_or(0.0, |c| c.distance_squared)
        })
        .sum();
    (sum / points.len() as f64).sqrt() / diagonal
}

/// Which method made a coarse mesh: serialised as `"qem"` or `"remesh"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Quadric edge collapse with the edge-length term ([`crate::simplify`]).
    Qem,
    /// Isotropic remeshing ([`crate::remesh()`]).
    Remesh,
}

impl Method {
    /// The name in the JSON report and on the command line: `"qem"` or `"remesh"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Qem => "qem",
            Self::Remesh => "remesh",
        }
    }
}

/// Everything `meshvae simplify --json` prints, for either method (the same keys).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimplifyReport {
    pub method: Method,
    pub vertices_in: usize,
    pub vertices_out: usize,
    pub faces_in: usize,
    pub faces_out: usize,
    /// The edge-length weight λ of QEM; `None` (JSON `null`) for a remeshing, which has none.
    pub lambda: Option<f64>,
    /// Edge-length CV of the input, for comparison with `edge_cv`.
    pub edge_cv_in: f64,
    pub edge_cv: f64,
    pub cluster_cv: f64,
    pub cluster_max: usize,
    pub cluster_area_cv: f64,
    /// The output is a 2-manifold (see [`crate::manifold::manifold_defect`]).
    pub manifold: bool,
    /// QEM: coarse faces turned against the fine face they descend from ([`flipped_faces`]).
    /// Remeshing: coarse faces turned against the template's normal at the closest point to
    /// their centroid ([`flipped_faces_on_surface`]).
    pub flipped_faces: usize,
    /// Output faces with a repeated vertex or (near) zero area, as `mesh_io::QualityReport`
    /// counts them.
    pub degenerate_faces: usize,
    pub euler_in: i64,
    pub euler_out: i64,
    /// Wall-clock seconds of the simplification alone, as measured by the caller.
    pub seconds: f64,
    pub geometric_error_rel: f64,
}

impl SimplifyReport {
    /// The report on simplifying `fine` to `simplified` with weight `lambda` in `seconds`.
    pub fn of(fine: &TriMesh, simplified: &Simplified, lambda: f64, seconds: f64) -> Self {
        let uniformity = UniformityReport::of(fine, simplified);
        let flipped = flipped_faces(fine, simplified);
        let method = (Method::Qem, Some(lambda));
        Self::assemble(
            method,
            fine,
            &simplified.coarse,
            uniformity,
            flipped,
            seconds,
        )
    }

    /// The report on remeshing `fine` to `remeshed` in `seconds`.
    pub fn of_remeshed(fine: &TriMesh, remeshed: &Remeshed, seconds: f64) -> Self {
        let uniformity = UniformityReport::of_remeshed(fine, remeshed);
        let flipped = flipped_faces_on_surface(fine, &remeshed.coarse);
        let method = (Method::Remesh, None);
        Self::assemble(method, fine, &remeshed.coarse, uniformity, flipped, seconds)
    }

    /// The report for `(method, λ)`: what both methods share.
    fn assemble(
        (method, lambda): (Method, Option<f64>),
        fine: &TriMesh,
        coarse: &TriMesh,
        uniformity: UniformityReport,
        flipped_faces: usize,
        seconds: f64,
    ) -> Self {
        let quality_in = QualityReport::of_mesh(&fine.positions, &fine.faces);
        let quality_out = QualityReport::of_mesh(&coarse.positions, &coarse.faces);
        Self {
            method,
            vertices_in: fine.vertex_count(),
            vertices_out: coarse.vertex_count(),
            faces_in: fine.face_count(),
            faces_out: coarse.face_count(),
            lambda,
            edge_cv_in: edge_length_cv(&fine.positions, &fine.faces),
            edge_cv: uniformity.edge_cv,
            cluster_cv: uniformity.cluster_cv,
            cluster_max: uniformity.cluster_max,
            cluster_area_cv: uniformity.cluster_area_cv,
            manifold: manifold_defect(coarse.vertex_count(), &coarse.faces).is_none(),
            flipped_faces,
            degenerate_faces: quality_out.degenerate_faces,
            euler_in: quality_in.euler_characteristic,
            euler_out: quality_out.euler_characteristic,
            seconds,
            geometric_error_rel: geometric_error_rel(fine, coarse),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cv_of_known_values() {
        let (mean, cv) = mean_cv(&[1.0, 3.0]);
        assert_eq!(mean, 2.0);
        assert!((cv - 0.5).abs() < 1e-15);
        assert_eq!(mean_cv(&[2.0, 2.0, 2.0]).1, 0.0);
        // A unit right triangle: edges 1, 1, √2.
        let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let lengths = [1.0, 1.0, 2f64.sqrt()];
        let expected = mean_cv(&lengths).1;
        assert!((edge_length_cv(&positions, &[[0, 1, 2]]) - expected).abs() < 1e-7);
    }

    #[test]
    fn geometric_error_is_zero_on_itself_and_the_offset_otherwise() {
        let sphere = crate::shapes::icosphere(2);
        assert!(geometric_error_rel(&sphere, &sphere) < 1e-7);
        // Shifted by 0.01 along z, the plane z = 0 sees every vertex of a flat grid at 0.01.
        let flat = TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        };
        let lifted = TriMesh {
            positions: flat.positions.iter().map(|p| [p[0], p[1], 0.01]).collect(),
            faces: flat.faces.clone(),
        };
        let e = geometric_error_rel(&flat, &lifted);
        assert!((e - 0.01 / 2f64.sqrt()).abs() < 1e-7, "{e}");
    }

    #[test]
    fn both_methods_fill_the_same_report() {
        let sphere = crate::shapes::icosphere(2);
        let config = crate::SimplifyConfig::default();
        let s = crate::simplify(&sphere, &config).expect("simplifies");
        let qem = SimplifyReport::of(&sphere, &s, 0.001, 0.5);
        assert_eq!((qem.method, qem.lambda), (Method::Qem, Some(0.001)));
        let r = crate::remesh(&sphere, &crate::RemeshConfig::default()).expect("remeshes");
        let remeshed = SimplifyReport::of_remeshed(&sphere, &r, 0.25);
        assert_eq!((remeshed.method, remeshed.lambda), (Method::Remesh, None));
        for report in [&qem, &remeshed] {
            assert_eq!(report.vertices_in, 162);
            assert_eq!(report.vertices_out, 81);
            assert!(report.manifold);
            assert_eq!((report.euler_in, report.euler_out), (2, 2));
            assert_eq!(report.flipped_faces, 0);
            assert_eq!(report.degenerate_faces, 0);
        }
        assert_eq!(remeshed.seconds, 0.25);
        // The same cluster statistics as computed from the map directly.
        let direct = UniformityReport::of_clusters(&sphere, &r.coarse, &r.cluster_of);
        assert_eq!(remeshed.cluster_cv, direct.cluster_cv);
        assert_eq!(Method::Remesh.as_str(), "remesh");
    }
}
