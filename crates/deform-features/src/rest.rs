//! The rest mesh ("template"): f64 positions, one-ring adjacency with clamped cotangent weights,
//! vertex normals and ring areas, connected components. Shared by the fit and the reconstruction
//! so that both use exactly the same weights.

use crate::cotan::{WeightClamp, cotan_weights};
use crate::error::FeatureError;
use crate::rotation::{Vec3, add, cross, norm, scale, sub};
use mesh_io::{Face, Point};

/// The rest mesh the features are relative to, with everything derived from it once.
#[derive(Debug, Clone)]
pub struct RestMesh {
    positions: Vec<Vec3>,
    /// Faces with three distinct vertex indices (faces repeating an index are dropped).
    faces: Vec<Face>,
    /// CSR one-ring: neighbours of `i` are `neighbours[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<usize>,
    neighbours: Vec<u32>,
    /// `weights[k]` is the cotangent weight of the edge to `neighbours[k]` (symmetric).
    weights: Vec<f64>,
    component: Vec<u32>,
    component_count: usize,
    /// Area-weighted unit vertex normals (zero where all incident faces are degenerate).
    normals: Vec<Vec3>,
    /// Sum of the areas of the faces around each vertex.
    ring_areas: Vec<f64>,
    clamp: WeightClamp,
    stats: WeightStats,
    warnings: Vec<String>,
}

/// How many weights needed the robustness rules (see [`crate::cotan`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct WeightStats {
    pub edges: usize,
    /// Edges raised to `WeightClamp::min` (obtuse neighbourhoods or only degenerate faces).
    pub clamped_low: usize,
    /// Edges lowered to `WeightClamp::max` (needle triangles).
    pub clamped_high: usize,
    /// Faces of zero area, skipped by the weights and the normals.
    pub degenerate_faces: usize,
    /// Faces that repeat a vertex index, dropped.
    pub collapsed_faces: usize,
    /// Vertices no face uses.
    pub isolated_vertices: usize,
}

impl RestMesh {
    /// The rest mesh from positions and faces, with the default [`WeightClamp`].
    pub fn new(positions: &[Point], faces: &[Face]) -> Result<Self, FeatureError> {
        Self::with_clamp(positions, faces, WeightClamp::default())
    }

    /// The rest mesh with explicit weight bounds.
    pub fn with_clamp(
        positions: &[Point],
        faces: &[Face],
        clamp: WeightClamp,
    ) -> Result<Self, FeatureError> {
        let n = positions.len();
        if n == 0 || faces.is_empty() {
            return Err(FeatureError::invalid_mesh(
                "the rest mesh has no vertices or no faces",
            ));
        }
        if !(clamp.min > 0.0 && clamp.max >= clamp.min && clamp.max.is_finite()) {
            return Err(FeatureError::InvalidOption {
                option: "weight clamp",
                message: format!("need 0 < min ≤ max < ∞, got [{}, {}]", clamp.min, clamp.max),
            });
        }
        if let Some((v, p)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(FeatureError::invalid_mesh(format!(
                "rest vertex {v} has a non-finite coordinate {p:?}"
            )));
        }
        if let Some((f, face)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&i| i as usize >= n))
        {
            return Err(FeatureError::invalid_mesh(format!(
                "face {f} is {face:?} but the mesh has {n} vertices"
            )));
        }
        let positions: Vec<Vec3> = positions.iter().map(|p| p.map(f64::from)).collect();
        let mut warnings = Vec::new();
        let kept: Vec<Face> = faces
            .iter()
            .copied()
            .filter(|f| f[0] != f[1] && f[1] != f[2] && f[0] != f[2])
            .collect();
        let collapsed = faces.len() - kept.len();
        if collapsed > 0 {
            warnings.push(format!(
                "{collapsed} faces repeat a vertex index and were dropped"
            ));
        }
        if kept.is_empty() {
            return Err(FeatureError::invalid_mesh(
                "every face repeats a vertex index",
            ));
        }
        let ew = cotan_weights(&positions, &kept, clamp);
        if !ew.degenerate_faces.is_empty() {
            let first: Vec<String> = ew
                .degenerate_faces
                .iter()
                .take(5)
                .map(|f| f.to_string())
                .collect();
            warnings.push(format!(
                "{} faces of the rest mesh have zero area (e.g. faces {}); they get no cotangent \
                 weight and no normal",
                ew.degenerate_faces.len(),
                first.join(", ")
            ));
        }

        // CSR adjacency from the undirected edges.
        let mut degree = vec![0usize; n];
        for &(i, j, _) in &ew.edges {
            degree[i as usize] += 1;
            degree[j as usize] += 1;
        }
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        for d in &degree {
            offsets.push(offsets.last().copied().unwrap_or(0) + d);
        }
        let mut fill = offsets[..n].to_vec();
        let mut neighbours = vec![0u32; offsets[n]];
        let mut weights = vec![0.0; offsets[n]];
        for &(i, j, w) in &ew.edges {
            for (a, b) in [(i, j), (j, i)] {
                let slot = &mut fill[a as usize];
                neighbours[*slot] = b;
                weights[*slot] = w;
                *slot += 1;
            }
        }
        let isolated = degree.iter().filter(|&&d| d == 0).count();
        if isolated > 0 {
            warnings.push(format!(
                "{isolated} vertices belong to no face; their features are the identity and \
                 they stay at their rest positions"
            ));
        }

        // Area-weighted normals and ring areas (degenerate faces add ~0 to both).
        let mut normals = vec![[0.0; 3]; n];
        let mut ring_areas = vec![0.0; n];
        for f in &kept {
            let p = f.map(|i| positions[i as usize]);
            let c = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let area = 0.5 * norm(c);
            for &i in f {
                normals[i as usize] = add(normals[i as usize], c);
                ring_areas[i as usize] += area;
            }
        }
        let mut no_normal = 0;
        for (nrm, &area) in normals.iter_mut().zip(&ring_areas) {
            let len = norm(*nrm);
            if len > 1e-12 * area && len > 0.0 {
                *nrm = scale(*nrm, 1.0 / len);
            } else {
                *nrm = [0.0; 3];
                no_normal += 1;
            }
        }
        let no_normal = no_normal - isolated;
        if no_normal > 0 {
            warnings.push(format!(
                "{no_normal} vertices have no rest normal (zero-area or cancelling faces around \
                 them); their fit is regularised towards the identity"
            ));
        }

        let (component, component_count) = components(n, &offsets, &neighbours);
        let stats = WeightStats {
            edges: ew.edges.len(),
            clamped_low: ew.clamped_low,
            clamped_high: ew.clamped_high,
            degenerate_faces: ew.degenerate_faces.len(),
            collapsed_faces: collapsed,
            isolated_vertices: isolated,
        };
        Ok(Self {
            positions,
            faces: kept,
            offsets,
            neighbours,
            weights,
            component,
            component_count,
            normals,
            ring_areas,
            clamp,
            stats,
            warnings,
        })
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Rest positions in f64.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The faces used (those with three distinct indices).
    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// Neighbours of vertex `i` and the cotangent weights of the edges to them.
    pub fn ring(&self, i: usize) -> (&[u32], &[f64]) {
        let range = self.offsets[i]..self.offsets[i + 1];
        (&self.neighbours[range.clone()], &self.weights[range])
    }

    /// Connected component of each vertex (isolated vertices are components of their own).
    pub fn component(&self) -> &[u32] {
        &self.component
    }

    pub fn component_count(&self) -> usize {
        self.component_count
    }

    /// Area-weighted unit vertex normals (zero where undefined).
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Sum of the areas of the faces around each vertex.
    pub fn ring_areas(&self) -> &[f64] {
        &self.ring_areas
    }

    pub fn clamp(&self) -> WeightClamp {
        self.clamp
    }

    /// How many weights and faces needed the robustness rules.
    pub fn weight_stats(&self) -> WeightStats {
        self.stats
    }

    /// Problems met building the rest mesh (degenerate faces, isolated vertices, …).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Mean of the positions of each component's vertices, per component.
    pub(crate) fn component_centroids(&self, positions: &[Vec3]) -> Vec<Vec3> {
        let mut sums = vec![[0.0; 3]; self.component_count];
        let mut counts = vec![0usize; self.component_count];
        for (p, &c) in positions.iter().zip(&self.component) {
            sums[c as usize] = add(sums[c as usize], *p);
            counts[c as usize] += 1;
        }
        sums.iter()
            .zip(&counts)
            .map(|(s, &c)| scale(*s, 1.0 / c.max(1) as f64))
            .collect()
    }
}

/// Connected components of the one-ring graph by an iterative flood fill.
fn components(n: usize, offsets: &[usize], neighbours: &[u32]) -> (Vec<u32>, usize) {
    let mut component = vec![u32::MAX; n];
    let mut count = 0u32;
    let mut stack = Vec::new();
    for start in 0..n {
        if component[start] != u32::MAX {
            continue;
        }
        component[start] = count;
        stack.push(start);
        while let Some(i) = stack.pop() {
            for &j in &neighbours[offsets[i]..offsets[i + 1]] {
                if component[j as usize] == u32::MAX {
                    component[j as usize] = count;
                    stack.push(j as usize);
                }
            }
        }
        count += 1;
    }
    (component, count as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjacency_is_symmetric_with_components_and_warnings() {
        // Two separate triangles plus an unused vertex 6, plus a face repeating an index.
        let positions: Vec<Point> = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
            [9.0, 9.0, 9.0],
        ];
        let faces = vec![[0, 1, 2], [3, 4, 5], [3, 3, 4]];
        let rest = RestMesh::new(&positions, &faces).unwrap();
        assert_eq!(rest.faces().len(), 2);
        assert_eq!(rest.component_count(), 3);
        assert_eq!(rest.ring(6).0.len(), 0);
        for i in 0..6 {
            let (nb, w) = rest.ring(i);
            assert_eq!(nb.len(), 2);
            for (&j, &wij) in nb.iter().zip(w) {
                let (nb2, w2) = rest.ring(j as usize);
                let k = nb2.iter().position(|&x| x as usize == i).unwrap();
                assert_eq!(w2[k], wij);
            }
        }
        assert!((rest.normals()[0][2] - 1.0).abs() < 1e-15);
        assert!((rest.ring_areas()[0] - 0.5).abs() < 1e-15);
        assert_eq!(rest.warnings().len(), 2, "{:?}", rest.warnings());
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let p: Vec<Point> = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(RestMesh::new(&p, &[[0, 1, 3]]).is_err());
        assert!(RestMesh::new(&p, &[]).is_err());
        assert!(RestMesh::new(&[[f32::NAN, 0.0, 0.0], p[1], p[2]], &[[0, 1, 2]]).is_err());
        let bad = WeightClamp { min: 0.0, max: 1.0 };
        assert!(RestMesh::with_clamp(&p, &[[0, 1, 2]], bad).is_err());
    }
}
