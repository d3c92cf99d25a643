//! Is a face list a 2-manifold (with or without boundary)? Used to reject bad input and to
//! report on the output.

use crate::lists::Lists;
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
    topology(vertex_count, faces).err()
}

/// Room for this many more items in each vertex's list of faces and of edges: merges add a
/// few, and the room saves moving the list.
pub(crate) const SLACK: usize = 4;

/// The edges and vertex incidence of a 2-manifold face list.
pub(crate) struct Topology {
    /// The faces around each vertex, in ascending face order.
    pub(crate) incident: Lists<u32>,
    /// The distinct edges, lower end first, in ascending order: the index is the edge id.
    pub(crate) edges: Vec<[u32; 2]>,
    /// The ids of the edges with a single face (ascending).
    pub(crate) boundary: Vec<u32>,
}

/// The [`Topology`] of `faces` (indices below `vertex_count`, checked by the caller), or the
/// first [`ManifoldDefect`]: a repeated vertex (lowest face), else an overused edge (lowest
/// edge), else a pinched vertex (lowest vertex). One pass over each vertex's faces, O(F).
pub(crate) fn topology(
    vertex_count: usize,
    faces: &[Face],
) -> std::result::Result<Topology, ManifoldDefect> {
    if let Some(face) = faces
        .iter()
        .position(|f| f[0] == f[1] || f[1] == f[2] || f[2] == f[0])
    {
        return Err(ManifoldDefect::RepeatedVertex { face });
    }
    let (offsets, around_all) = vertex_faces(vertex_count, faces);
    let mut edges = Vec::with_capacity(faces.len() * 3 / 2 + 2);
    let mut boundary = Vec::new();
    let mut pinched = None;
    // Per vertex v: its distinct neighbours w, each with a face holding edge (v, w) and how many
    // do (`slot[w]` finds w's entry while `slot[w].0 == v`), and a union-find over v's faces
    // joining those that share an edge at v.
    let mut slot = vec![(u32::MAX, 0u32); vertex_count];
    let mut local: Vec<(u32, u32, u32)> = Vec::new();
    let mut higher: Vec<(u32, u32)> = Vec::new();
    let mut parent = Vec::<u32>::new();
    for (v, span) in offsets.windows(2).enumerate() {
        let around = &around_all[span[0] as usize..span[1] as usize];
        let v32 = v as u32;
        local.clear();
        parent.clear();
        parent.extend(0..around.len() as u32);
        let mut fans = around.len();
        for (here, &f) in around.iter().enumerate() {
            for w in faces[f as usize] {
                let Some(entry) = slot.get_mut(w as usize).filter(|_| w != v32) else {
                    continue;
                };
                if entry.0 == v32 {
                    let seen = &mut local[entry.1 as usize];
                    seen.2 += 1;
                    let (rx, ry) = (root(&mut parent, seen.1), root(&mut parent, here as u32));
                    if rx != ry {
                        parent[rx as usize] = ry;
                        fans -= 1;
                    }
                } else {
                    *entry = (v32, local.len() as u32);
                    local.push((w, here as u32, 1));
                }
            }
        }
        // Each edge is met from both ends; it is judged at its lower one, in edge order.
        higher.clear();
        higher.extend(
            local
                .iter()
                .filter(|&&(w, _, _)| w > v32)
                .map(|&(w, _, count)| (w, count)),
        );
        higher.sort_unstable();
        for &(w, count) in &higher {
            if count > 2 {
                return Err(ManifoldDefect::EdgeOverused {
                    a: v32,
                    b: w,
                    faces: count as usize,
                });
            }
            if count == 1 {
                boundary.push(edges.len() as u32);
            }
            edges.push([v32, w]);
        }
        // Faces sharing an edge at v are one fan; reported once no edge is overused.
        if fans > 1 && pinched.is_none() {
            pinched = Some(ManifoldDefect::VertexNotFan { vertex: v32, fans });
        }
    }
    match pinched {
        Some(defect) => Err(defect),
        None => Ok(Topology {
            incident: Lists::from_lists(
                offsets
                    .windows(2)
                    .map(|w| &around_all[w[0] as usize..w[1] as usize]),
                SLACK,
            ),
            edges,
            boundary,
        }),
    }
}

fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// The faces incident to each vertex, in ascending face order, as offsets (one per vertex,
/// plus one) into one list. Indices at or past `vertex_count` are ignored.
fn vertex_faces(vertex_count: usize, faces: &[Face]) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; vertex_count + 1];
    for f in faces {
        for &v in f {
            if let Some(d) = offsets.get_mut(v as usize + 1) {
                *d += 1;
            }
        }
    }
    for v in 0..vertex_count {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor = offsets.clone();
    let mut items = vec![0u32; offsets[vertex_count] as usize];
    for (i, f) in faces.iter().enumerate() {
        for &v in f {
            if let Some(c) = cursor
                .get_mut(v as usize)
                .filter(|_| (v as usize) < vertex_count)
            {
                items[*c as usize] = i as u32;
                *c += 1;
            }
        }
    }
    (offsets, items)
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

    #[test]
    fn topology_lists_every_edge_once_in_order_and_the_boundary_ones() {
        for mesh in [
            crate::shapes::icosphere(2),
            crate::shapes::torus(9, 5, 1.0, 0.3),
            crate::shapes::bumpy_grid(7, 5),
        ] {
            let t = topology(mesh.vertex_count(), &mesh.faces).expect("manifold");
            // Brute force: every face side, sorted; runs of one are boundary edges.
            let mut sides: Vec<[u32; 2]> = mesh
                .faces
                .iter()
                .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
                .map(|[a, b]| [a.min(b), a.max(b)])
                .collect();
            sides.sort_unstable();
            let runs: Vec<&[[u32; 2]]> = sides.chunk_by(|x, y| x == y).collect();
            let edges: Vec<[u32; 2]> = runs.iter().map(|r| r[0]).collect();
            let boundary: Vec<u32> = (0..runs.len() as u32)
                .filter(|&e| runs[e as usize].len() == 1)
                .collect();
            assert_eq!(t.edges, edges);
            assert_eq!(t.boundary, boundary);
            for v in 0..mesh.vertex_count() as u32 {
                let around: Vec<u32> = (0..mesh.faces.len() as u32)
                    .filter(|&f| mesh.faces[f as usize].contains(&v))
                    .collect();
                assert_eq!(t.incident.get(v), around.as_slice());
            }
        }
        assert!(
            !topology(16, &crate::shapes::bumpy_grid(3, 3).faces)
                .expect("manifold")
                .boundary
                .is_empty()
        );
    }

    #[test]
    fn an_overused_edge_is_reported_before_a_lower_pinched_vertex() {
        // Vertex 0 is pinched (two separate triangles), edge (5, 6) has three faces.
        let faces = [[0, 1, 2], [0, 3, 4], [5, 6, 7], [6, 5, 8], [5, 6, 9]];
        assert_eq!(
            manifold_defect(10, &faces),
            Some(ManifoldDefect::EdgeOverused {
                a: 5,
                b: 6,
                faces: 3
            })
        );
        // Two fans touching at 0, each closed around it: still two fans.
        let double_cone = [
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 1],
            [0, 4, 5],
            [0, 5, 6],
            [0, 6, 4],
        ];
        assert_eq!(
            manifold_defect(7, &double_cone),
            Some(ManifoldDefect::VertexNotFan { vertex: 0, fans: 2 })
        );
    }
}
