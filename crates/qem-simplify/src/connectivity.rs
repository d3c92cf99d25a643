//! The mesh being simplified: faces (relabelled in place as vertices merge), edges (with stable
//! ids, the keys of the priority queue), each vertex's incident faces and edges, and the
//! topological side of a contraction (the link condition).
//!
//! Faces are never created: a face of the coarse mesh is a fine face whose corners were
//! relabelled, which is what lets every coarse face name the fine face it descends from.

use crate::lists::Lists;
use crate::manifold::Topology;
use mesh_io::Face;

/// Faces, edges and vertex incidence of a manifold mesh under edge contraction.
#[derive(Debug, Clone)]
pub(crate) struct Connectivity {
    faces: Vec<Face>,
    face_alive: Vec<bool>,
    /// The live faces around each vertex (empty for removed or unused vertices).
    incident: Lists<u32>,
    /// Edge id → its endpoints (lower first). Ids are those of the sorted initial edge list;
    /// an edge keeps its id when an endpoint is relabelled.
    edges: Vec<[u32; 2]>,
    /// The live edges at each vertex, with their other ends.
    vertex_edges: Lists<Spoke>,
    /// Scratch for the link condition: `mark[w] == stamp` for the neighbours of one vertex.
    mark: Vec<u32>,
    stamp: u32,
    /// Scratch for [`Connectivity::collapse`].
    scratch_spokes: Vec<Spoke>,
    scratch_faces: Vec<u32>,
}

/// An edge seen from one of its ends: its id and its other end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Spoke {
    pub(crate) edge: u32,
    pub(crate) to: u32,
}

impl Connectivity {
    /// `faces` must index below `vertex_count` and form a 2-manifold.
    #[cfg(test)]
    pub(crate) fn new(vertex_count: usize, faces: &[Face]) -> Self {
        match crate::manifold::topology(vertex_count, faces) {
            Ok(topology) => Self::from_topology(faces, topology),
            Err(defect) => panic!("test mesh is not a manifold: {defect}"),
        }
    }

    /// From the faces and their [`crate::manifold::topology`].
    pub(crate) fn from_topology(faces: &[Face], topology: Topology) -> Self {
        let Topology {
            incident, edges, ..
        } = topology;
        // Each vertex's spokes in edge id order.
        let n = incident.len();
        let mut lengths = vec![0u32; n];
        for &[a, b] in &edges {
            lengths[a as usize] += 1;
            lengths[b as usize] += 1;
        }
        let mut vertex_edges =
            Lists::with_room(&lengths, crate::manifold::SLACK, Spoke { edge: 0, to: 0 });
        for (e, &[a, b]) in edges.iter().enumerate() {
            let edge = e as u32;
            vertex_edges.push(a, Spoke { edge, to: b });
            vertex_edges.push(b, Spoke { edge, to: a });
        }
        Self {
            faces: faces.to_vec(),
            face_alive: vec![true; faces.len()],
            incident,
            edges,
            mark: vec![0; n],
            stamp: 0,
            scratch_spokes: Vec::new(),
            scratch_faces: Vec::new(),
            vertex_edges,
        }
    }

    /// Number of edge ids (live or not).
    pub(crate) fn edge_id_count(&self) -> usize {
        self.edges.len()
    }

    /// Every edge id's endpoints, lower first.
    pub(crate) fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// The endpoints of edge `e`, lower first.
    pub(crate) fn edge(&self, e: u32) -> [u32; 2] {
        self.edges[e as usize]
    }

    /// The live edges at `v`.
    pub(crate) fn edges_around(&self, v: u32) -> &[Spoke] {
        self.vertex_edges.get(v)
    }

    /// Asks for where `v`'s list of edges is kept.
    pub(crate) fn prefetch_vertex(&self, v: u32) {
        self.vertex_edges.prefetch_span(v);
    }

    /// Asks for `v`'s list of faces.
    pub(crate) fn prefetch_faces_around(&self, v: u32) {
        self.incident.prefetch_items(v);
    }

    /// Asks for `v`'s list of edges (its place known, see [`Connectivity::prefetch_vertex`]).
    pub(crate) fn prefetch_edges_around(&self, v: u32) {
        self.vertex_edges.prefetch_items(v);
    }

    /// Asks for face `f`'s corners.
    pub(crate) fn prefetch_face(&self, f: u32) {
        crate::prefetch::prefetch(&self.faces[f as usize]);
    }

    /// Asks for edge `e`'s ends.
    pub(crate) fn prefetch_edge(&self, e: u32) {
        crate::prefetch::prefetch(&self.edges[e as usize]);
    }

    pub(crate) fn face(&self, f: u32) -> Face {
        self.faces[f as usize]
    }

    pub(crate) fn faces_around(&self, v: u32) -> &[u32] {
        self.incident.get(v)
    }

    /// The live faces with their index, in ascending original order.
    pub(crate) fn live_faces(&self) -> impl Iterator<Item = (usize, Face)> + '_ {
        self.faces
            .iter()
            .zip(&self.face_alive)
            .enumerate()
            .filter(|(_, (_, alive))| **alive)
            .map(|(i, (f, _))| (i, *f))
    }

    /// The distinct neighbours of `v`, sorted.
    #[cfg(test)]
    pub(crate) fn neighbours(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        out.extend(self.edges_around(v).iter().map(|s| s.to));
        out.sort_unstable();
    }

    /// How many live faces hold both `v` and `w`.
    fn faces_of_edge(&self, v: u32, w: u32) -> usize {
        self.faces_around(v)
            .iter()
            .filter(|&&f| self.faces[f as usize].contains(&w))
            .count()
    }

    /// Whether `v` lies on the boundary. The mesh stays a 2-manifold, so the faces around `v`
    /// are one fan: a closed one has as many edges as faces, an open one one edge more.
    fn on_boundary(&self, v: u32) -> bool {
        self.edges_around(v).len() > self.faces_around(v).len()
    }

    /// Whether contracting edge (a, b) keeps a 2-manifold of the same topology: the link
    /// condition Lk(a) ∩ Lk(b) = Lk(ab), with boundaries closed by a virtual vertex joined to
    /// every boundary vertex. False when (a, b) is no edge.
    pub(crate) fn link_condition(&mut self, a: u32, b: u32) -> bool {
        // Vertices opposite the edge (the third corners of the faces that hold it).
        let mut opposite = [u32::MAX; 2];
        let mut shared = 0usize;
        for &f in self.faces_around(a) {
            let face = self.faces[f as usize];
            if face.contains(&b) {
                if shared == 2 {
                    return false;
                }
                opposite[shared] = face.into_iter().find(|&w| w != a && w != b).unwrap_or(a);
                shared += 1;
            }
        }
        if shared == 0 {
            return false;
        }
        // Common neighbours must be exactly the opposite vertices.
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.mark.fill(0);
            self.stamp = 1;
        }
        let stamp = self.stamp;
        for s in self.vertex_edges.get(a) {
            self.mark[s.to as usize] = stamp;
        }
        let common = self
            .vertex_edges
            .get(b)
            .iter()
            .filter(|s| self.mark[s.to as usize] == stamp)
            .count();
        if common != shared {
            return false;
        }
        if shared == 2 {
            // An interior edge joining two boundary vertices would pinch the surface.
            if self.on_boundary(a) && self.on_boundary(b) {
                return false;
            }
            // Both (a, c, d) and (b, c, d) exist: the edge is in a tetrahedron.
            let (c, d) = (opposite[0], opposite[1]);
            let has_face = |v: u32| {
                self.faces_around(v).iter().any(|&f| {
                    let face = self.faces[f as usize];
                    face.contains(&c) && face.contains(&d)
                })
            };
            if has_face(a) && has_face(b) {
                return false;
            }
        } else {
            // A lone triangle whose three edges are all boundary would collapse to an edge.
            let c = opposite[0];
            if self.faces_of_edge(a, c) == 1 && self.faces_of_edge(b, c) == 1 {
                return false;
            }
        }
        true
    }

    /// Contracts edge (keep, remove): faces holding both die, the others of `remove` are
    /// relabelled to `keep`; edge (keep, remove) and the edges of `remove` that would duplicate
    /// one of `keep`'s die, their ids pushed to `dead_edges`. The caller has checked the link
    /// condition.
    pub(crate) fn collapse(&mut self, keep: u32, remove: u32, dead_edges: &mut Vec<u32>) {
        let mut moved = std::mem::take(&mut self.scratch_spokes);
        self.vertex_edges.take_into(remove, &mut moved);
        for s in &moved {
            self.vertex_edges.prefetch_items(s.to);
        }
        self.vertex_edges.retain(keep, |s| s.to != remove);
        // `keep`'s own edges, before it takes any of `remove`'s.
        let kept = self.vertex_edges.get(keep).len();
        for &Spoke { edge, to: x } in &moved {
            if x == keep {
                dead_edges.push(edge);
                continue;
            }
            let duplicate = self.vertex_edges.get(keep)[..kept]
                .iter()
                .any(|s| s.to == x);
            if duplicate {
                dead_edges.push(edge);
                self.vertex_edges.retain(x, |s| s.edge != edge);
            } else {
                self.edges[edge as usize] = [keep.min(x), keep.max(x)];
                self.vertex_edges.push(keep, Spoke { edge, to: x });
                for s in self.vertex_edges.get_mut(x) {
                    if s.edge == edge {
                        s.to = keep;
                    }
                }
            }
        }
        self.scratch_spokes = moved;
        let mut moved = std::mem::take(&mut self.scratch_faces);
        self.incident.take_into(remove, &mut moved);
        for &f in &moved {
            let face = &mut self.faces[f as usize];
            if face.contains(&keep) {
                self.face_alive[f as usize] = false;
                for w in *face {
                    if w != keep && w != remove {
                        self.incident.retain(w, |&g| g != f);
                    }
                }
            } else {
                for corner in face.iter_mut() {
                    if *corner == remove {
                        *corner = keep;
                    }
                }
                self.incident.push(keep, f);
            }
        }
        self.scratch_faces = moved;
        let alive = &self.face_alive;
        self.incident.retain(keep, |&f| alive[f as usize]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An octahedron: 6 vertices, 12 edges, 8 faces; every edge passes the link condition.
    fn octahedron() -> Vec<Face> {
        vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ]
    }

    #[test]
    fn octahedron_edges_pass_and_a_tetrahedron_edge_fails() {
        let mut c = Connectivity::new(6, &octahedron());
        assert!(c.link_condition(0, 2));
        assert!(c.link_condition(4, 1));
        // 0 and 1 are opposite: not an edge.
        assert!(!c.link_condition(0, 1));
        let mut tetra = Connectivity::new(4, &[[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]]);
        assert!(!tetra.link_condition(0, 1));
    }

    #[test]
    fn collapse_relabels_and_removes_the_two_faces() {
        let mut c = Connectivity::new(6, &octahedron());
        let mut dead = Vec::new();
        c.collapse(0, 2, &mut dead);
        // (0, 2) itself and the duplicates of (0, 4), (0, 5).
        assert_eq!(dead.len(), 3);
        let live: Vec<Face> = c.live_faces().map(|(_, f)| f).collect();
        assert_eq!(live.len(), 6);
        assert_edges_match_faces(&c, 6);
        assert!(live.iter().all(|f| !f.contains(&2)));
        assert!(c.faces_around(2).is_empty());
        let mut n = Vec::new();
        c.neighbours(0, &mut n);
        assert_eq!(n, vec![1, 3, 4, 5]);
        // Now the mesh is a square pyramid pair around 0,1,3: vertex 0 has valence 4, and edge
        // (0, 1) has three common neighbours (3, 4, 5) but only two opposite vertices.
        assert!(!c.link_condition(0, 1));
    }

    /// The live edge table equals the edges of the live faces, and every vertex lists its own.
    fn assert_edges_match_faces(c: &Connectivity, n: u32) {
        let mut from_faces: Vec<[u32; 2]> = c
            .live_faces()
            .flat_map(|(_, f)| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        from_faces.sort_unstable();
        from_faces.dedup();
        let mut listed: Vec<[u32; 2]> = (0..n)
            .flat_map(|v| c.edges_around(v).iter().map(|s| c.edge(s.edge)))
            .collect();
        listed.sort_unstable();
        let doubled: Vec<[u32; 2]> = from_faces.iter().flat_map(|&e| [e, e]).collect();
        assert_eq!(listed, doubled);
        for v in 0..n {
            for s in c.edges_around(v) {
                let [a, b] = c.edge(s.edge);
                assert!((a == v && b == s.to) || (b == v && a == s.to));
            }
        }
    }

    #[test]
    fn edge_table_follows_a_sequence_of_collapses() {
        let sphere = crate::shapes::icosphere(2);
        let n = sphere.vertex_count() as u32;
        let mut c = Connectivity::new(sphere.vertex_count(), &sphere.faces);
        let mut dead = Vec::new();
        let mut done = 0;
        for e in 0..c.edge_id_count() as u32 {
            if done == 40 {
                break;
            }
            let [a, b] = c.edge(e);
            if c.edges_around(a).iter().any(|s| s.edge == e) && c.link_condition(a, b) {
                c.collapse(a, b, &mut dead);
                done += 1;
                assert_edges_match_faces(&c, n);
            }
        }
        assert_eq!(done, 40);
    }

    #[test]
    fn boundary_rules() {
        // A lone triangle cannot lose an edge.
        let mut tri = Connectivity::new(3, &[[0, 1, 2]]);
        assert!(!tri.link_condition(0, 1));
        // A strip 0-1-2 / 3-4-5 of four triangles: the interior edge (1, 4) joins two boundary
        // vertices and must not be contracted; the boundary edge (0, 1) may be.
        let mut strip = Connectivity::new(6, &[[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]]);
        assert!(!strip.link_condition(1, 4));
        assert!(strip.link_condition(0, 1));
    }
}
