//! Is a face list a 2-manifold (with or without boundary)? Used to reject bad input and to
//! report on the output.

use mesh_io::Face;

/// The first reason a face list is not a 2-manifold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ManifoldDefect {
    /// A face uses one vertex twice.
    RepeatedVertex { face: usize },
    /// An edge shared by more than two faces.
    EdgeOverused { a: u32, b: u32, faces: usize },
    /// The faces around a vertex form several fans (a "bow tie"), not one disc or half-disc.
    VertexNotFan { vertex: u32, fans: usize },
}

impl std::fmt::Display for ManifoldDefect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::RepeatedVertex { face } => write!(f, "face {face} uses a vertex twice"),
            Self::EdgeOverused { a, b, faces } => {
                write!(
                    f,
                    "edge ({a}, {b}) is shared by {faces} faces (at most 2 allowed)"
                )
            }
            Self::VertexNotFan { vertex, fans } => write!(
                f,
                "the faces around vertex {vertex} form {fans} separate fans (a pinched vertex)"
            ),
        }
    }
}

/// `None` when `faces` (indices below `vertex_count`) form a 2-manifold: no face repeats a
/// vertex, every edge has one or two faces, and the faces around every vertex are one fan.
pub fn manifold_defect(vertex_count: usize, faces: &[Face]) -> Option<ManifoldDefect> {
    defect_of(
        faces,
        &sorted_edge_keys(faces),
        &vertex_faces(vertex_count, faces),
    )
}

/// [`manifold_defect`] from the precomputed [`sorted_edge_keys`] and [`vertex_faces`].
pub(crate) fn defect_of(
    faces: &[Face],
    edge_keys: &[u64],
    incident: &[Vec<u32>],
) -> Option<ManifoldDefect> {
    if let Some(face) = faces
        .iter()
        .position(|f| f[0] == f[1] || f[1] == f[2] || f[2] == f[0])
    {
        return Some(ManifoldDefect::RepeatedVertex { face });
    }
    if let Some(run) = edge_keys.chunk_by(|x, y| x == y).find(|run| run.len() > 2) {
        let [a, b] = key_ends(run[0]);
        return Some(ManifoldDefect::EdgeOverused {
            a,
            b,
            faces: run.len(),
        });
    }
    let (mut neighbours, mut parent) = (Vec::new(), Vec::new());
    for (vertex, around) in incident.iter().enumerate() {
        let fans = count_fans(vertex as u32, around, faces, &mut neighbours, &mut parent);
        if fans > 1 {
            return Some(ManifoldDefect::VertexNotFan {
                vertex: vertex as u32,
                fans,
            });
        }
    }
    None
}

/// An undirected edge as one sortable number: lower end in the high half.
pub(crate) fn edge_key(a: u32, b: u32) -> u64 {
    (u64::from(a.min(b)) << 32) | u64::from(a.max(b))
}

/// The ends of an [`edge_key`], lower first.
pub(crate) fn key_ends(key: u64) -> [u32; 2] {
    [(key >> 32) as u32, key as u32]
}

/// Every face side as an [`edge_key`], sorted: an interior edge appears twice, a boundary edge
/// once.
pub(crate) fn sorted_edge_keys(faces: &[Face]) -> Vec<u64> {
    let mut keys: Vec<u64> = faces
        .iter()
        .flat_map(|f| {
            [
                edge_key(f[0], f[1]),
                edge_key(f[1], f[2]),
                edge_key(f[2], f[0]),
            ]
        })
        .collect();
    keys.sort_unstable();
    keys
}

/// The faces incident to each vertex, in ascending face order. Indices at or past
/// `vertex_count` are ignored.
pub(crate) fn vertex_faces(vertex_count: usize, faces: &[Face]) -> Vec<Vec<u32>> {
    let mut degree = vec![0usize; vertex_count];
    for f in faces {
        for &v in f {
            if let Some(d) = degree.get_mut(v as usize) {
                *d += 1;
            }
        }
    }
    let mut incident: Vec<Vec<u32>> = degree.into_iter().map(Vec::with_capacity).collect();
    for (i, f) in faces.iter().enumerate() {
        for &v in f {
            if let Some(list) = incident.get_mut(v as usize) {
                list.push(i as u32);
            }
        }
    }
    incident
}

/// Fans around `vertex`: components of the graph on its neighbours in which each face around it
/// joins its two other corners (faces sharing an edge at `vertex` share a neighbour).
fn count_fans(
    vertex: u32,
    around: &[u32],
    faces: &[Face],
    neighbours: &mut Vec<u32>,
    parent: &mut Vec<usize>,
) -> usize {
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let others = |f: u32| {
        let face = faces[f as usize];
        let mut it = face.into_iter().filter(move |&w| w != vertex);
        [it.next().unwrap_or(vertex), it.next().unwrap_or(vertex)]
    };
    // Valences are small: linear scans beat sorting here.
    neighbours.clear();
    for w in around.iter().flat_map(|&f| others(f)) {
        if !neighbours.contains(&w) {
            neighbours.push(w);
        }
    }
    parent.clear();
    parent.extend(0..neighbours.len());
    let mut fans = neighbours.len();
    for &f in around {
        let [a, b] = others(f);
        let position = |x: u32| neighbours.iter().position(|&w| w == x);
        let (Some(i), Some(j)) = (position(a), position(b)) else {
            continue;
        };
        let (ri, rj) = (root(parent, i), root(parent, j));
        if ri != rj {
            parent[ri] = rj;
            fans -= 1;
        }
    }
    fans
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tetrahedron_and_open_fan_are_manifold() {
        let tetra = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
        assert_eq!(manifold_defect(4, &tetra), None);
        let fan = [[0, 1, 2], [0, 2, 3], [0, 3, 4]];
        assert_eq!(manifold_defect(5, &fan), None);
    }

    #[test]
    fn defects_are_named() {
        assert_eq!(
            manifold_defect(3, &[[0, 1, 1]]),
            Some(ManifoldDefect::RepeatedVertex { face: 0 })
        );
        let three_on_an_edge = [[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        assert_eq!(
            manifold_defect(5, &three_on_an_edge),
            Some(ManifoldDefect::EdgeOverused {
                a: 0,
                b: 1,
                faces: 3
            })
        );
        // Two triangles touching at vertex 0 only.
        let bow_tie = [[0, 1, 2], [0, 3, 4]];
        assert_eq!(
            manifold_defect(5, &bow_tie),
            Some(ManifoldDefect::VertexNotFan { vertex: 0, fans: 2 })
        );
    }
}
