//! Is a face list a 2-manifold (with or without boundary)? Used to reject bad input and to
//! report on the output.

use crate::lists::Lists;
use mesh_io::Face;
use rayon::prelude::*;

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
/// edge), else a pinched vertex (lowest vertex). One pass over each vertex's faces, O(F), in
/// parallel over ranges of vertices joined in order, so the result does not depend on the
/// number of threads.
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
    let incident = vertex_faces(vertex_count, faces);
    // A few ranges per thread (each needs a scratch array as long as the vertex list).
    let ranges = (rayon::current_num_threads() * 2).clamp(1, vertex_count.div_ceil(4096).max(1));
    let size = vertex_count.div_ceil(ranges).max(1);
    let parts: Vec<Part> = (0..ranges)
        .into_par_iter()
        .map(|r| {
            let range = (r * size).min(vertex_count)..((r + 1) * size).min(vertex_count);
            scan(range, vertex_count, faces, &incident)
        })
        .collect();
    let mut edges = Vec::with_capacity(parts.iter().map(|p| p.edges.len()).sum());
    let mut boundary = Vec::new();
    let mut pinched = None;
    for part in parts {
        // The lowest overused edge wins over any pinched vertex.
        if let Some(defect) = part.overused {
            return Err(defect);
        }
        pinched = pinched.or(part.pinched);
        let first = edges.len() as u32;
        boundary.extend(part.boundary.iter().map(|&e| first + e));
        edges.extend_from_slice(&part.edges);
    }
    match pinched {
        Some(defect) => Err(defect),
        None => Ok(Topology {
            incident,
            edges,
            boundary,
        }),
    }
}

/// What [`scan`] finds for a range of vertices.
struct Part {
    /// The edges whose lower end is in the range, in order.
    edges: Vec<[u32; 2]>,
    /// Indices into `edges` of the boundary edges.
    boundary: Vec<u32>,
    /// The first overused edge, if any (the scan stops there).
    overused: Option<ManifoldDefect>,
    /// The first pinched vertex, if any.
    pinched: Option<ManifoldDefect>,
}

/// The edges, boundary edges and defects of the vertices in `range`.
fn scan(
    range: std::ops::Range<usize>,
    vertex_count: usize,
    faces: &[Face],
    incident: &Lists<u32>,
) -> Part {
    let mut part = Part {
        edges: Vec::with_capacity(range.len() * 3 + 2),
        boundary: Vec::new(),
        overused: None,
        pinched: None,
    };
    // Per vertex v: its distinct neighbours w, each with a face holding edge (v, w) and how many
    // do (`slot[w]` finds w's entry while `slot[w].0 == v`), and a union-find over v's faces
    // joining those that share an edge at v.
    let mut slot = vec![(u32::MAX, 0u32); vertex_count];
    let mut local: Vec<(u32, u32, u32)> = Vec::new();
    let mut higher: Vec<(u32, u32)> = Vec::new();
    let mut parent = Vec::<u32>::new();
    for v in range {
        let around = incident.get(v as u32);
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
                part.overused = Some(ManifoldDefect::EdgeOverused {
                    a: v32,
                    b: w,
                    faces: count as usize,
                });
                return part;
            }
            if count == 1 {
                part.boundary.push(part.edges.len() as u32);
            }
            part.edges.push([v32, w]);
        }
        // Faces sharing an edge at v are one fan; reported once no edge is overused.
        if fans > 1 && part.pinched.is_none() {
            part.pinched = Some(ManifoldDefect::VertexNotFan { vertex: v32, fans });
        }
    }
    part
}

fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// The faces incident to each vertex, in ascending face order, with room for [`SLACK`] more.
/// Indices at or past `vertex_count` are ignored.
fn vertex_faces(vertex_count: usize, faces: &[Face]) -> Lists<u32> {
    let mut lengths = vec![0u32; vertex_count];
    for f in faces {
        for &v in f {
            if let Some(d) = lengths.get_mut(v as usize) {
                *d += 1;
            }
        }
    }
    let mut lists = Lists::with_room(&lengths, SLACK, 0);
    for (i, f) in faces.iter().enumerate() {
        for &v in f {
            if (v as usize) < vertex_count {
                lists.push(v, i as u32);
            }
        }
    }
    lists
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
        // The same on a mesh large enough to be scanned in several ranges: the pinched vertex
        // in the first range, the overused edge in the last.
        let sphere = crate::shapes::icosphere(5);
        let n = sphere.vertex_count() as u32;
        assert!(n > 2 * 4096);
        let mut faces = sphere.faces.clone();
        faces.push([0, n, n + 1]);
        let pinched_only = manifold_defect(n as usize + 2, &faces);
        faces.extend([
            [n + 2, n + 3, n + 4],
            [n + 3, n + 2, n + 5],
            [n + 2, n + 3, n + 6],
        ]);
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool");
            assert_eq!(
                pool.install(|| manifold_defect(n as usize + 2, &faces[..faces.len() - 3])),
                pinched_only
            );
            assert_eq!(
                pool.install(|| manifold_defect(n as usize + 7, &faces)),
                Some(ManifoldDefect::EdgeOverused {
                    a: n + 2,
                    b: n + 3,
                    faces: 3
                })
            );
        }
        assert_eq!(
            pinched_only,
            Some(ManifoldDefect::VertexNotFan { vertex: 0, fans: 2 })
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
