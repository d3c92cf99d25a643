//! A quality report of a set's connectivity and its rest mesh (frame 0).

use crate::mesh::{Face, MeshSet, Point, bbox_diagonal};
use serde::Serialize;

/// Counts that tell whether a mesh set is fit for the pipeline. Edges are undirected; a boundary
/// edge has one incident face, a non-manifold edge three or more.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QualityReport {
    pub meshes: usize,
    pub vertices: usize,
    pub faces: usize,
    pub edges: usize,
    pub boundary_edges: usize,
    pub nonmanifold_edges: usize,
    /// Faces of frame 0 with a repeated vertex or an area at most 1e-12 × diagonal².
    pub degenerate_faces: usize,
    /// Connected components of the face graph (vertices joined by shared faces).
    pub components: usize,
    /// Vertices no face uses (kept, since they carry correspondence, but suspicious).
    pub unused_vertices: usize,
    /// Bounding-box diagonal of frame 0.
    pub bbox_diagonal: f64,
    /// Bounding-box diagonal of every frame's points together.
    pub set_bbox_diagonal: f64,
    /// The median of the frames' own bounding-box diagonals.
    pub median_frame_diagonal: f64,
    /// Frames whose own diagonal is more than [`OUTLIER_FACTOR`] times the median or less
    /// than its 1/[`OUTLIER_FACTOR`]: a stray vertex, another unit or a damaged file.
    pub outlier_frames: Vec<OutlierFrame>,
    /// V − E + F of the connectivity.
    pub euler_characteristic: i64,
    /// The distinct labels, or `None` for an unlabelled set.
    pub labels: Option<Vec<String>>,
}

/// How far (as a factor) a frame's bounding-box diagonal may be from the median frame's before
/// [`QualityReport::outlier_frames`] lists it; poses of one animation stay well within it.
pub const OUTLIER_FACTOR: f64 = 2.0;

/// A frame whose extent is far from the rest.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutlierFrame {
    pub index: usize,
    pub name: String,
    pub diagonal: f64,
}

impl QualityReport {
    pub fn of(set: &MeshSet) -> Self {
        let mut report = Self::of_mesh(set.frame(0), set.faces());
        report.meshes = set.len();
        report.labels = set.distinct_labels();
        let diagonals: Vec<f64> = (0..set.len())
            .map(|i| bbox_diagonal(set.frame(i)))
            .collect();
        let mut sorted = diagonals.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        report.median_frame_diagonal = median;
        report.set_bbox_diagonal = bbox_diagonal(set.positions());
        report.outlier_frames = diagonals
            .iter()
            .enumerate()
            .filter(|&(_, &d)| d > OUTLIER_FACTOR * median || d * OUTLIER_FACTOR < median)
            .map(|(index, &diagonal)| OutlierFrame {
                index,
                name: set.names()[index].clone(),
                diagonal,
            })
            .collect();
        report
    }

    /// The report of one mesh (`meshes` = 1, no labels).
    pub fn of_mesh(positions: &[Point], faces: &[Face]) -> Self {
        let edges = sorted_edges(faces);
        let (mut unique, mut boundary, mut nonmanifold) = (0, 0, 0);
        for run in edges.chunk_by(|a, b| a == b) {
            unique += 1;
            match run.len() {
                1 => boundary += 1,
                2 => {}
                _ => nonmanifold += 1,
            }
        }
        let diagonal = bbox_diagonal(positions);
        let (components, unused) = components(positions.len(), faces);
        Self {
            meshes: 1,
            vertices: positions.len(),
            faces: faces.len(),
            edges: unique,
            boundary_edges: boundary,
            nonmanifold_edges: nonmanifold,
            degenerate_faces: count_degenerate(positions, faces, diagonal),
            components,
            unused_vertices: unused,
            bbox_diagonal: diagonal,
            set_bbox_diagonal: diagonal,
            median_frame_diagonal: diagonal,
            outlier_frames: Vec::new(),
            euler_characteristic: positions.len() as i64 - unique as i64 + faces.len() as i64,
            labels: None,
        }
    }
}

/// Every face's three edges as sorted (min, max) pairs, sorted, duplicates kept.
fn sorted_edges(faces: &[Face]) -> Vec<(u32, u32)> {
    let mut edges: Vec<(u32, u32)> = faces
        .iter()
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges
}

fn count_degenerate(positions: &[Point], faces: &[Face], diagonal: f64) -> usize {
    let tiny = 1e-12 * diagonal * diagonal;
    let p = |i: u32| positions[i as usize].map(f64::from);
    faces
        .iter()
        .filter(|f| {
            if f[0] == f[1] || f[1] == f[2] || f[2] == f[0] {
                return true;
            }
            let (a, b, c) = (p(f[0]), p(f[1]), p(f[2]));
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() <= tiny
        })
        .count()
}

/// (components of the face graph, vertices used by no face).
fn components(vertices: usize, faces: &[Face]) -> (usize, usize) {
    let mut parent: Vec<u32> = (0..vertices as u32).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    let mut used = vec![false; vertices];
    for f in faces {
        for &i in f {
            used[i as usize] = true;
        }
        for (a, b) in [(f[0], f[1]), (f[1], f[2])] {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            if ra != rb {
                parent[ra as usize] = rb;
            }
        }
    }
    let roots = (0..vertices as u32)
        .filter(|&i| used[i as usize] && root(&mut parent, i) == i)
        .count();
    (roots, used.iter().filter(|u| !**u).count())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_triangles_and_a_tetrahedron() {
        // A quad as two triangles (4 boundary edges) beside a closed tetrahedron, one unused vertex.
        let positions: Vec<Point> = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [5., 0., 0.],
            [6., 0., 0.],
            [5., 1., 0.],
            [5., 0., 1.],
            [9., 9., 9.],
        ];
        let faces = vec![
            [0, 1, 2],
            [0, 2, 3],
            [4, 6, 5],
            [4, 5, 7],
            [5, 6, 7],
            [4, 7, 6],
        ];
        let r = QualityReport::of_mesh(&positions, &faces);
        assert_eq!(r.boundary_edges, 4);
        assert_eq!(r.nonmanifold_edges, 0);
        assert_eq!(r.components, 2);
        assert_eq!(r.unused_vertices, 1);
        assert_eq!(r.edges, 5 + 6);
        assert_eq!(r.degenerate_faces, 0);
        assert_eq!(r.euler_characteristic, 9 - 11 + 6);
    }

    #[test]
    fn nonmanifold_and_degenerate() {
        let positions: Vec<Point> = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [0., 1., 0.],
            [0., -1., 0.],
            [0., 0., 1.],
            [2., 0., 0.],
        ];
        // Three faces on edge (0,1); one zero-area face (0,1,5 are collinear).
        let faces = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4], [0, 1, 5]];
        let r = QualityReport::of_mesh(&positions, &faces);
        assert_eq!(r.nonmanifold_edges, 1);
        assert_eq!(r.degenerate_faces, 1);
    }

    #[test]
    fn the_set_diagonal_spans_every_frame_and_a_stray_frame_is_flagged() {
        let faces = vec![[0, 1, 2]];
        let tri = |dx: f32, far: f32| vec![[dx, 0., 0.], [dx + 1., 0., 0.], [dx, far, 0.]];
        let mut positions = Vec::new();
        for i in 0..5 {
            // Frame 3 has one vertex 25 diagonals away, as a flipped byte would put it.
            positions.extend(tri(i as f32, if i == 3 { 25.0 } else { 1.0 }));
        }
        let names = (0..5).map(|i| format!("f{i}")).collect();
        let set = MeshSet::from_flat(faces, 3, positions, names).unwrap();
        let r = QualityReport::of(&set);
        assert!((r.bbox_diagonal - 2f64.sqrt()).abs() < 1e-6);
        assert!((r.median_frame_diagonal - 2f64.sqrt()).abs() < 1e-6);
        // x spans 0..5, y 0..25.
        assert!((r.set_bbox_diagonal - (25.0f64 + 625.0).sqrt()).abs() < 1e-4);
        assert_eq!(r.outlier_frames.len(), 1);
        assert_eq!(
            (r.outlier_frames[0].index, r.outlier_frames[0].name.as_str()),
            (3, "f3")
        );
    }
}
