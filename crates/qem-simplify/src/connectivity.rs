//! The mesh being simplified: faces (relabelled in place as vertices merge), edges (with stable
//! ids, the keys of the priority queue), each vertex's incident faces and edges, and the
//! topological side of a contraction (the link condition).
//!
//! Faces are never created: a face of the coarse mesh is a fine face whose corners were
//! relabelled, which is what lets every coarse face name the fine face it descends from.

use mesh_io::Face;

/// Faces, edges and vertex incidence of a manifold mesh under edge contraction.
#[derive(Debug, Clone)]
pub(crate) struct Connectivity {
    faces: Vec<Face>,
    face_alive: Vec<bool>,
    /// The live faces around each vertex (empty for removed or unused vertices).
    incident: Vec<Vec<u32>>,
    /// Edge id → its endpoints (lower first). Ids are those of the sorted initial edge list;
    /// an edge keeps its id when an endpoint is relabelled.
    edges: Vec<[u32; 2]>,
    /// The live edges at each vertex, with their other ends.
    vertex_edges: Vec<Vec<Spoke>>,
}

/// An edge seen from one of its ends: its id and its other end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Spoke {
    pub(crate) edge: u32,
    pub(crate) to: u32,
}

impl Connectivity {
    /// `faces` must index below `vertex_count` (checked by the caller).
    #[cfg(test)]
    pub(crate) fn new(vertex_count: usize, faces: &[Face]) -> Self {
        use crate::manifold::{sorted_edge_keys, vertex_faces};
        Self::from_parts(
            faces,
            &sorted_edge_keys(faces),
            vertex_faces(vertex_count, faces),
        )
    }

    /// From the faces, their [`crate::manifold::sorted_edge_keys`] and
    /// [`crate::manifold::vertex_faces`].
    pub(crate) fn from_parts(faces: &[Face], edge_keys: &[u64], incident: Vec<Vec<u32>>) -> Self {
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(edge_keys.len() / 2 + 1);
        let mut last = None;
        for &key in edge_keys {
            if last != Some(key) {
                edges.push(crate::manifold::key_ends(key));
                last = Some(key);
            }
        }
        let mut vertex_edges: Vec<Vec<Spoke>> = incident
            .iter()
            .map(|faces| Vec::with_capacity(faces.len() + 1))
            .collect();
        for (e, &[a, b]) in edges.iter().enumerate() {
            let edge = e as u32;
            vertex_edges[a as usize].push(Spoke { edge, to: b });
            vertex_edges[b as usize].push(Spoke { edge, to: a });
        }
        Self {
            faces: faces.to_vec(),
            face_alive: vec![true; faces.len()],
            incident,
            edges,
            vertex_edges,
        }
    }

    /// Number of edge ids (live or not).
    pub(crate) fn edge_id_count(&self) -> usize {
        self.edges.len()
    }

    /// The endpoints of edge `e`, lower first.
    pub(crate) fn edge(&self, e: u32) -> [u32; 2] {
        self.edges[e as usize]
    }

    /// The live edges at `v`.
    pub(crate) fn edges_around(&self, v: u32) -> &[Spoke] {
        &self.vertex_edges[v as usize]
    }

    pub(crate) fn face(&self, f: u32) -> Face {
        self.faces[f as usize]
    }

    pub(crate) fn faces_around(&self, v: u32) -> &[u32] {
        &self.incident[v as usize]
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

    /// Every corner of the faces around `v` other than `v` itself, sorted, with repeats: an
    /// interior edge (v, w) puts w in twice, a boundary edge once.
    pub(crate) fn ring_with_counts(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        for &f in self.faces_around(v) {
            out.extend(self.faces[f as usize].into_iter().filter(|&w| w != v));
        }
        out.sort_unstable();
    }

    /// The distinct neighbours of `v`, sorted.
    #[cfg(test)]
    pub(crate) fn neighbours(&self, v: u32, out: &mut Vec<u32>) {
        self.ring_with_counts(v, out);
        out.dedup();
    }

    /// Whether contracting edge (a, b) keeps a 2-manifold of the same topology: the link
    /// condition Lk(a) ∩ Lk(b) = Lk(ab), with boundaries closed by a virtual vertex joined to
    /// every boundary vertex. `ra`/`rb` are scratch buffers. False when (a, b) is no edge.
    pub(crate) fn link_condition(
        &self,
        a: u32,
        b: u32,
        ra: &mut Vec<u32>,
        rb: &mut Vec<u32>,
    ) -> bool {
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
        self.ring_with_counts(a, ra);
        self.ring_with_counts(b, rb);
        // Common neighbours must be exactly the opposite vertices.
        let mut common = 0usize;
        let (mut i, mut j) = (0, 0);
        while i < ra.len() && j < rb.len() {
            match ra[i].cmp(&rb[j]) {
                std::cmp::Ordering::Less => i += 1,
                std::cmp::Ordering::Greater => j += 1,
                std::cmp::Ordering::Equal => {
                    let w = ra[i];
                    if w != a && w != b {
                        common += 1;
                    }
                    while i < ra.len() && ra[i] == w {
                        i += 1;
                    }
                    while j < rb.len() && rb[j] == w {
                        j += 1;
                    }
                }
            }
        }
        if common != shared {
            return false;
        }
        let boundary_edge = |ring: &[u32], w: u32| ring.iter().filter(|&&x| x == w).count() == 1;
        let boundary_vertex = |ring: &[u32]| ring.chunk_by(|x, y| x == y).any(|r| r.len() == 1);
        if shared == 2 {
            // An interior edge joining two boundary vertices would pinch the surface.
            if boundary_vertex(ra) && boundary_vertex(rb) {
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
            if boundary_edge(ra, c) && boundary_edge(rb, c) {
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
        let moved = std::mem::take(&mut self.vertex_edges[remove as usize]);
        self.vertex_edges[keep as usize].retain(|s| s.to != remove);
        // `keep`'s own edges, before it takes any of `remove`'s.
        let kept = self.vertex_edges[keep as usize].len();
        for Spoke { edge, to: x } in moved {
            if x == keep {
                dead_edges.push(edge);
                continue;
            }
            let duplicate = self.vertex_edges[keep as usize][..kept]
                .iter()
                .any(|s| s.to == x);
            if duplicate {
                dead_edges.push(edge);
                self.vertex_edges[x as usize].retain(|s| s.edge != edge);
            } else {
                self.edges[edge as usize] = [keep.min(x), keep.max(x)];
                self.vertex_edges[keep as usize].push(Spoke { edge, to: x });
                for s in &mut self.vertex_edges[x as usize] {
                    if s.edge == edge {
                        s.to = keep;
                    }
                }
            }
        }
        let moved = std::mem::take(&mut self.incident[remove as usize]);
        for f in moved {
            let face = &mut self.faces[f as usize];
            if face.contains(&keep) {
                self.face_alive[f as usize] = false;
                for w in *face {
                    if w != keep && w != remove {
                        self.incident[w as usize].retain(|&g| g != f);
                    }
                }
            } else {
                for corner in face.iter_mut() {
                    if *corner == remove {
                        *corner = keep;
                    }
                }
                self.incident[keep as usize].push(f);
            }
        }
        let alive = &self.face_alive;
        self.incident[keep as usize].retain(|&f| alive[f as usize]);
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
        let (mut ra, mut rb) = (Vec::new(), Vec::new());
        let c = Connectivity::new(6, &octahedron());
        assert!(c.link_condition(0, 2, &mut ra, &mut rb));
        assert!(c.link_condition(4, 1, &mut ra, &mut rb));
        // 0 and 1 are opposite: not an edge.
        assert!(!c.link_condition(0, 1, &mut ra, &mut rb));
        let tetra = Connectivity::new(4, &[[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]]);
        assert!(!tetra.link_condition(0, 1, &mut ra, &mut rb));
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
        let (mut ra, mut rb) = (Vec::new(), Vec::new());
        assert!(!c.link_condition(0, 1, &mut ra, &mut rb));
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
        let (mut ra, mut rb, mut dead) = (Vec::new(), Vec::new(), Vec::new());
        let mut done = 0;
        for e in 0..c.edge_id_count() as u32 {
            if done == 40 {
                break;
            }
            let [a, b] = c.edge(e);
            if c.edges_around(a).iter().any(|s| s.edge == e)
                && c.link_condition(a, b, &mut ra, &mut rb)
            {
                c.collapse(a, b, &mut dead);
                done += 1;
                assert_edges_match_faces(&c, n);
            }
        }
        assert_eq!(done, 40);
    }

    #[test]
    fn boundary_rules() {
        let (mut ra, mut rb) = (Vec::new(), Vec::new());
        // A lone triangle cannot lose an edge.
        let tri = Connectivity::new(3, &[[0, 1, 2]]);
        assert!(!tri.link_condition(0, 1, &mut ra, &mut rb));
        // A strip 0-1-2 / 3-4-5 of four triangles: the interior edge (1, 4) joins two boundary
        // vertices and must not be contracted; the boundary edge (0, 1) may be.
        let strip = Connectivity::new(6, &[[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]]);
        assert!(!strip.link_condition(1, 4, &mut ra, &mut rb));
        assert!(strip.link_condition(0, 1, &mut ra, &mut rb));
    }
}
