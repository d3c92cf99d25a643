//! `TriMesh` (one triangle mesh) and `MeshSet` (many frames of one connectivity).

use crate::error::{MeshIoError, Result};
use std::path::Path;

/// A vertex position, in the file's units.
pub type Point = [f32; 3];
/// A triangle as three 0-based vertex indices.
pub type Face = [u32; 3];

/// One triangle mesh: positions in file order (vertex i of the file is vertex i here, unused
/// vertices included) and triangles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriMesh {
    pub positions: Vec<Point>,
    pub faces: Vec<Face>,
}

impl TriMesh {
    /// A mesh from positions and faces, checked: faces in range, coordinates finite.
    pub fn new(positions: Vec<Point>, faces: Vec<Face>) -> Result<Self> {
        let mesh = Self { positions, faces };
        mesh.validate(Path::new("<mesh>"))?;
        Ok(mesh)
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Checks what every reader guarantees: at least one vertex and one face, every face index in
    /// range, every coordinate finite. `path` names the mesh in the error.
    pub fn validate(&self, path: &Path) -> Result<()> {
        if self.positions.is_empty() || self.faces.is_empty() {
            return Err(MeshIoError::EmptyMesh { path: path.into() });
        }
        check_finite(&self.positions, path)?;
        let n = self.positions.len();
        for face in &self.faces {
            for &i in face {
                if i as usize >= n {
                    return Err(MeshIoError::IndexOutOfRange {
                        path: path.into(),
                        line: 0,
                        index: i as i64,
                        vertices: n,
                    });
                }
            }
        }
        Ok(())
    }

    /// Axis-aligned bounding box `(min, max)`; `None` for a mesh without vertices.
    pub fn bbox(&self) -> Option<(Point, Point)> {
        bbox(&self.positions)
    }

    /// Length of the bounding box's diagonal (0 for an empty mesh).
    pub fn bbox_diagonal(&self) -> f64 {
        bbox_diagonal(&self.positions)
    }
}

pub(crate) fn check_finite(positions: &[Point], path: &Path) -> Result<()> {
    for (vertex, p) in positions.iter().enumerate() {
        if let Some(&value) = p.iter().find(|c| !c.is_finite()) {
            return Err(MeshIoError::NonFinite {
                path: path.into(),
                vertex,
                value,
            });
        }
    }
    Ok(())
}

/// Axis-aligned bounding box of a point list.
pub fn bbox(points: &[Point]) -> Option<(Point, Point)> {
    let first = *points.first()?;
    Some(points.iter().fold((first, first), |(mut lo, mut hi), p| {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
        (lo, hi)
    }))
}

/// Length of the bounding-box diagonal of a point list (0 when empty).
pub fn bbox_diagonal(points: &[Point]) -> f64 {
    bbox(points).map_or(0.0, |(lo, hi)| {
        (0..3)
            .map(|k| (hi[k] as f64 - lo[k] as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    })
}

/// N meshes ("frames") sharing one face list: an animation or a set of poses.
///
/// Invariants (checked by every constructor): at least one frame, every frame has
/// `vertex_count` finite positions, faces index `0..vertex_count`, one name per frame, labels
/// (when present) one per frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSet {
    faces: Vec<Face>,
    vertex_count: usize,
    /// Frame-major: frame `f`'s positions are `positions[f * vertex_count..][..vertex_count]`.
    positions: Vec<Point>,
    names: Vec<String>,
    labels: Option<Vec<String>>,
}

impl MeshSet {
    /// Builds a set from the shared faces and a flat, frame-major position array.
    pub fn from_flat(
        faces: Vec<Face>,
        vertex_count: usize,
        positions: Vec<Point>,
        names: Vec<String>,
    ) -> Result<Self> {
        let invalid = |message: String| MeshIoError::InvalidArgument {
            argument: "positions",
            message,
        };
        if vertex_count == 0 || faces.is_empty() {
            return Err(invalid("a mesh set needs vertices and faces".into()));
        }
        if !positions.len().is_multiple_of(vertex_count)
            || positions.len() / vertex_count != names.len()
        {
            return Err(invalid(format!(
                "{} positions do not make {} frames of {} vertices",
                positions.len(),
                names.len(),
                vertex_count
            )));
        }
        if names.is_empty() {
            return Err(invalid("a mesh set needs at least one frame".into()));
        }
        let template = TriMesh {
            positions: positions[..vertex_count].to_vec(),
            faces,
        };
        template.validate(Path::new(&names[0]))?;
        for (f, name) in names.iter().enumerate().skip(1) {
            check_finite(
                &positions[f * vertex_count..(f + 1) * vertex_count],
                Path::new(name),
            )?;
        }
        Ok(Self {
            faces: template.faces,
            vertex_count,
            positions,
            names,
            labels: None,
        })
    }

    /// Builds a set from meshes that must share one face list. `names` gives one name per mesh.
    pub fn from_meshes(meshes: Vec<TriMesh>, names: Vec<String>) -> Result<Self> {
        let Some(first) = meshes.first() else {
            return Err(MeshIoError::InvalidArgument {
                argument: "meshes",
                message: "a mesh set needs at least one mesh".into(),
            });
        };
        if names.len() != meshes.len() {
            return Err(MeshIoError::InvalidArgument {
                argument: "names",
                message: format!("{} names for {} meshes", names.len(), meshes.len()),
            });
        }
        for (mesh, name) in meshes.iter().zip(&names).skip(1) {
            check_same_connectivity(first, Path::new(&names[0]), mesh, Path::new(name))?;
        }
        let vertex_count = first.vertex_count();
        let faces = first.faces.clone();
        let positions = meshes.into_iter().flat_map(|m| m.positions).collect();
        Self::from_flat(faces, vertex_count, positions, names)
    }

    /// Attaches one label per frame (e.g. `gallop` / `pose`).
    pub fn with_labels(mut self, labels: Vec<String>) -> Result<Self> {
        if labels.len() != self.len() {
            return Err(MeshIoError::InvalidArgument {
                argument: "labels",
                message: format!("{} labels for {} meshes", labels.len(), self.len()),
            });
        }
        self.labels = Some(labels);
        Ok(self)
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Always false: a set has at least one frame. Present for API symmetry with `len`.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// Positions of frame `i`. Panics if `i >= len()`, like slice indexing.
    pub fn frame(&self, i: usize) -> &[Point] {
        &self.positions[i * self.vertex_count..(i + 1) * self.vertex_count]
    }

    /// Iterator over the frames' positions, in order.
    pub fn frames(&self) -> impl ExactSizeIterator<Item = &[Point]> {
        self.positions.chunks_exact(self.vertex_count)
    }

    /// All positions, frame-major ([N, V, 3] when flattened).
    pub fn positions(&self) -> &[Point] {
        &self.positions
    }

    /// Frame names (file names without extension when loaded from files).
    pub fn names(&self) -> &[String] {
        &self.names
    }

    pub fn labels(&self) -> Option<&[String]> {
        self.labels.as_deref()
    }

    /// The distinct labels in order of first appearance, or `None` for an unlabelled set.
    pub fn distinct_labels(&self) -> Option<Vec<String>> {
        let labels = self.labels.as_ref()?;
        let mut distinct: Vec<String> = Vec::new();
        for l in labels {
            if !distinct.contains(l) {
                distinct.push(l.clone());
            }
        }
        Some(distinct)
    }

    /// Index of the frame called `name`, or, when `name` is a number below `len()`, that index.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.names
            .iter()
            .position(|n| n == name)
            .or_else(|| name.parse::<usize>().ok().filter(|&i| i < self.len()))
    }

    /// Frame `i` as a standalone mesh.
    pub fn mesh(&self, i: usize) -> TriMesh {
        TriMesh {
            positions: self.frame(i).to_vec(),
            faces: self.faces.clone(),
        }
    }

    /// The rest mesh: frame 0.
    pub fn template(&self) -> TriMesh {
        self.mesh(0)
    }

    /// Keeps only the frames at `indices` (in that order), with their names and labels.
    pub fn subset(&self, indices: &[usize]) -> Result<Self> {
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.len()) {
            return Err(MeshIoError::InvalidArgument {
                argument: "indices",
                message: format!("frame {bad} is out of range (the set has {})", self.len()),
            });
        }
        let positions = indices.iter().flat_map(|&i| self.frame(i).iter().copied());
        let set = Self::from_flat(
            self.faces.clone(),
            self.vertex_count,
            positions.collect(),
            indices.iter().map(|&i| self.names[i].clone()).collect(),
        )?;
        match &self.labels {
            Some(l) => set.with_labels(indices.iter().map(|&i| l[i].clone()).collect()),
            None => Ok(set),
        }
    }
}

/// Checks that `mesh` has the vertex count and faces of `reference`, naming `path` if not.
pub fn check_same_connectivity(
    reference: &TriMesh,
    reference_path: &Path,
    mesh: &TriMesh,
    path: &Path,
) -> Result<()> {
    if mesh.vertex_count() != reference.vertex_count() {
        return Err(MeshIoError::VertexCountMismatch {
            path: path.into(),
            reference: reference_path.into(),
            expected: reference.vertex_count(),
            found: mesh.vertex_count(),
        });
    }
    if mesh.face_count() != reference.face_count() {
        return Err(MeshIoError::FaceMismatch {
            path: path.into(),
            reference: reference_path.into(),
            detail: format!(
                "{} faces instead of {}",
                mesh.face_count(),
                reference.face_count()
            ),
        });
    }
    if let Some(i) = (0..mesh.face_count()).find(|&i| mesh.faces[i] != reference.faces[i]) {
        let (a, b) = (mesh.faces[i], reference.faces[i]);
        return Err(MeshIoError::FaceMismatch {
            path: path.into(),
            reference: reference_path.into(),
            detail: format!(
                "face {i} is {:?} instead of {:?} (1-based: {:?} vs {:?})",
                a,
                b,
                a.map(|x| x + 1),
                b.map(|x| x + 1)
            ),
        });
    }
    Ok(())
}
