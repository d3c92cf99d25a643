//! One edge contraction: where the merged vertex goes, what it costs (the paper's Eq. 1) and
//! whether it is allowed (topology from [`Connectivity`], geometry here).

use crate::connectivity::Connectivity;
use crate::geometry::{Vec3, add, area_vector, distance, dot, norm, quality_with_normal, scale};
use crate::prefetch::{prefetch, prefetch_all};
use crate::quadric::Quadric;
use rayon::prelude::*;

/// A new face whose shape quality (1 = equilateral, see `triangle_quality`) falls below this, and
/// below its quality before the move, makes the contraction invalid: it guards against
/// degenerate slivers, which the flip test alone lets through.
pub(crate) const MIN_QUALITY: f64 = 0.01;

/// How many edges ahead [`State::cost_all`] asks for the records it will read.
const LOOKAHEAD: usize = 8;

/// Weight of the plane through a boundary edge, perpendicular to its face, relative to the unit
/// weight of a face plane: it keeps boundary vertices on the boundary's course.
pub(crate) const BOUNDARY_WEIGHT: f64 = 100.0;

/// What is kept per edge for its cost, in one record so that touching an edge costs one cache
/// miss: v̄ and the quadric error (which depend on the edge's ends alone), and the length term's
/// longest new edge as last computed. The neighbour at that distance is kept apart (in
/// [`State`]'s `farthest`), as the contraction loop scans it for many edges whose cost it does
/// not read. Contractions nearby that neither remove nor move that neighbour can only lengthen
/// the longest edge, so `longest` stays a lower bound until [`State::settle`] recomputes it.
#[derive(Debug, Clone, Copy)]
struct Placed {
    position: Vec3,
    quadric_error: f64,
    longest: f64,
}

/// The mesh under simplification, in normalised coordinates (bounding-box centre at the origin,
/// diagonal 1), with every vertex's quadric and every fine face's unit normal.
pub(crate) struct State {
    pub(crate) positions: Vec<Vec3>,
    pub(crate) quadrics: Vec<Quadric>,
    pub(crate) mesh: Connectivity,
    /// Unit normal of each fine face ([0; 3] for a zero-area face): no coarse face may point
    /// against the fine face it descends from.
    original_normals: Vec<Vec3>,
    lambda: f64,
    /// Per edge id.
    placed: Vec<Placed>,
    /// Per edge id: the neighbour at the distance `Placed::longest` (`u32::MAX` for none).
    farthest: Vec<u32>,
}

impl State {
    /// Quadrics are those of Garland & Heckbert 1997: the sum of the (unweighted) planes of the
    /// faces around a vertex, plus a weighted perpendicular plane per boundary edge.
    /// `boundary` lists the ids of the edges with one face, ascending.
    pub(crate) fn new(
        positions: Vec<Vec3>,
        faces: &[mesh_io::Face],
        boundary: &[u32],
        mesh: Connectivity,
        lambda: f64,
    ) -> Self {
        let mut quadrics = vec![Quadric::default(); positions.len()];
        let mut original_normals = Vec::with_capacity(faces.len());
        let p = |i: u32| positions[i as usize];
        for face in faces {
            let n = area_vector(p(face[0]), p(face[1]), p(face[2]));
            let len = norm(n);
            let unit = if len > 0.0 {
                scale(n, 1.0 / len)
            } else {
                [0.0; 3]
            };
            original_normals.push(unit);
            if len > 0.0 {
                let q = Quadric::plane_through(p(face[0]), unit, 1.0);
                for &v in face {
                    quadrics[v as usize] += q;
                }
            }
        }
        // Boundary edges in id order, so the summation order is fixed.
        for &e in boundary {
            let [a, b] = mesh.edge(e);
            let Some(&face) = mesh
                .faces_around(a)
                .iter()
                .find(|&&f| mesh.face(f).contains(&b))
            else {
                continue;
            };
            let along = crate::geometry::sub(p(b), p(a));
            let side = crate::geometry::cross(along, original_normals[face as usize]);
            let len = norm(side);
            if len > 0.0 {
                let q = Quadric::plane_through(p(a), scale(side, 1.0 / len), BOUNDARY_WEIGHT);
                quadrics[a as usize] += q;
                quadrics[b as usize] += q;
            }
        }
        Self {
            // Filled by `place_all`.
            placed: Vec::new(),
            farthest: Vec::new(),
            positions,
            quadrics,
            mesh,
            original_normals,
            lambda,
        }
    }

    /// Where contracting (a, b) puts the merged vertex: the minimiser of Q_a + Q_b when that
    /// system is regular and its solution lies within one edge length of the edge's midpoint
    /// (farther means the quadric is nearly flat along some direction and the "optimum" is
    /// arbitrary); otherwise whichever of the midpoint, a and b has the lowest quadric error
    /// (ties keep the midpoint, which keeps edges even).
    #[cfg(test)]
    pub(crate) fn placement(&self, a: u32, b: u32) -> Vec3 {
        self.place(
            &(self.quadrics[a as usize] + self.quadrics[b as usize]),
            a,
            b,
        )
    }

    /// [`State::placement`] given q = Q_a + Q_b.
    fn place(&self, q: &Quadric, a: u32, b: u32) -> Vec3 {
        let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
        let mid = scale(add(pa, pb), 0.5);
        if let Some(p) = q.minimizer()
            && distance(p, mid) <= distance(pa, pb)
        {
            return p;
        }
        let mut best = (q.error(mid), mid);
        for candidate in [pa, pb] {
            let e = q.error(candidate);
            if e < best.0 {
                best = (e, candidate);
            }
        }
        best.1
    }

    /// v̄, the quadric error and the length term (with its farthest neighbour, `u32::MAX` for
    /// none) of contracting (a, b), a < b, from scratch.
    fn evaluate(&self, a: u32, b: u32) -> (Placed, u32) {
        let q = self.quadrics[a as usize] + self.quadrics[b as usize];
        let p = self.place(&q, a, b);
        // The quadric is positive semi-definite; rounding can make it a hair negative.
        let quadric_error = q.error(p).max(0.0);
        let (longest, farthest) = if self.lambda > 0.0 {
            self.longest_new_edge(a, b, p)
        } else {
            (0.0, u32::MAX)
        };
        let placed = Placed {
            position: p,
            quadric_error,
            longest,
        };
        (placed, farthest)
    }

    /// Places every edge; in parallel, with the same result on any number of threads (each
    /// edge's figures depend on the mesh alone).
    pub(crate) fn place_all(&mut self) {
        let (mut placed, mut farthest) = (Vec::new(), Vec::new());
        let this = &*self;
        let edges = self.mesh.edges();
        (0..edges.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|e| {
                // The upper end's records, a few edges ahead (the lower end's are read in order).
                if let Some(&[_, b]) = edges.get(e + LOOKAHEAD) {
                    prefetch_all(&this.quadrics[b as usize]);
                    this.mesh.prefetch_edges_around(b);
                }
                let [a, b] = edges[e];
                this.evaluate(a, b)
            })
            .unzip_into_vecs(&mut placed, &mut farthest);
        self.placed = placed;
        self.farthest = farthest;
    }

    /// Re-places edge `e` (after one of its ends moved or merged) and returns its cost.
    #[cfg(test)]
    pub(crate) fn recost(&mut self, e: u32) -> f64 {
        let [a, b] = self.mesh.edge(e);
        let (placed, farthest) = self.evaluate(a, b);
        self.placed[e as usize] = placed;
        self.farthest[e as usize] = farthest;
        self.cost_of(e)
    }

    /// Re-places edge `e` = (`keep`, `other`) after the contraction of (`keep`, `removed`), and
    /// returns its cost with a lower bound of the length term: the distance from the new v̄ to
    /// the old farthest neighbour, which is still a neighbour unless it was `keep` or `removed`
    /// (then the term is measured in full). Settled at the top.
    pub(crate) fn replace(&mut self, e: u32, keep: u32, other: u32, removed: u32) -> f64 {
        let [a, b] = [keep.min(other), keep.max(other)];
        debug_assert_eq!(self.mesh.edge(e), [a, b]);
        let q = self.quadrics[a as usize] + self.quadrics[b as usize];
        let p = self.place(&q, a, b);
        let quadric_error = q.error(p).max(0.0);
        let farthest = self.farthest[e as usize];
        let (longest, farthest) = if self.lambda == 0.0 {
            (0.0, u32::MAX)
        } else if farthest == keep || farthest == removed || farthest == u32::MAX {
            self.longest_new_edge(a, b, p)
        } else {
            (distance(p, self.positions[farthest as usize]), farthest)
        };
        self.placed[e as usize] = Placed {
            position: p,
            quadric_error,
            longest,
        };
        self.farthest[e as usize] = farthest;
        self.cost_of(e)
    }

    /// Whether the contraction of (`keep`, `removed`) next to edge `e` (neither of whose ends
    /// changed) may have shortened its length term: only if it moved or removed the farthest
    /// neighbour. Otherwise the term can only have grown, and the cached one stays a lower bound.
    pub(crate) fn length_may_drop(&self, e: u32, keep: u32, removed: u32) -> bool {
        let farthest = self.farthest[e as usize];
        self.lambda > 0.0 && (farthest == keep || farthest == removed)
    }

    /// Recomputes the length term of edge `e` for its current neighbourhood and returns its
    /// exact cost (v̄ and the quadric error are exact since the edge was last placed).
    pub(crate) fn settle(&mut self, e: u32) -> f64 {
        if self.lambda > 0.0 {
            let [a, b] = self.mesh.edge(e);
            let (longest, farthest) = self.longest_new_edge(a, b, self.placed[e as usize].position);
            self.placed[e as usize].longest = longest;
            self.farthest[e as usize] = farthest;
        }
        self.cost_of(e)
    }

    /// After a contraction moved or removed the farthest neighbour of edge `e`: the length term
    /// may have dropped, and the distance to `keep` (now a neighbour of one of its ends) is a
    /// lower bound of it. Returns the cost with that bound, to be settled at the top.
    pub(crate) fn lower_length(&mut self, e: u32, keep: u32) -> f64 {
        let d = distance(
            self.placed[e as usize].position,
            self.positions[keep as usize],
        );
        self.placed[e as usize].longest = d;
        self.farthest[e as usize] = keep;
        self.cost_of(e)
    }

    /// Eq. 1 of the paper: v̄ᵀ(Q_a + Q_b)v̄ + λ · (longest new edge from v̄ to the other
    /// neighbours of a and b), lengths in units of the bounding-box diagonal, as cached for `e`
    /// (exact after placing the edge or [`State::settle`], else a lower bound).
    pub(crate) fn cost_of(&self, e: u32) -> f64 {
        let slot = &self.placed[e as usize];
        slot.quadric_error + self.lambda * slot.longest
    }

    /// The v̄ of edge `e` as last placed.
    pub(crate) fn placed(&self, e: u32) -> Vec3 {
        self.placed[e as usize].position
    }

    /// The longest edge from `p` to a neighbour of a or b other than a and b, and that
    /// neighbour (`u32::MAX` when there is none).
    fn longest_new_edge(&self, a: u32, b: u32, p: Vec3) -> (f64, u32) {
        let positions = &self.positions[..];
        // Starting below 0 makes the first neighbour the farthest so far.
        let (mut longest_squared, mut farthest) = (-1.0f64, u32::MAX);
        for (v, other) in [(a, b), (b, a)] {
            for spoke in self.mesh.edges_around(v) {
                if spoke.to == other {
                    continue;
                }
                let q = positions[spoke.to as usize];
                let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                let d2 = dx * dx + dy * dy + dz * dz;
                if d2 > longest_squared {
                    longest_squared = d2;
                    farthest = spoke.to;
                }
            }
        }
        (longest_squared.max(0.0).sqrt(), farthest)
    }

    /// Whether contracting (a, b) to `p` keeps a valid mesh: the link condition, and for every
    /// face that survives with a moved corner, no inversion against its current normal or
    /// against the fine face it descends from, and no new sliver.
    pub(crate) fn is_valid(&mut self, a: u32, b: u32, p: Vec3) -> bool {
        for v in [a, b] {
            prefetch_all(&self.quadrics[v as usize]);
            for &f in self.mesh.faces_around(v) {
                self.mesh.prefetch_face(f);
                prefetch_all(&self.original_normals[f as usize]);
            }
        }
        if !self.mesh.link_condition(a, b) {
            return false;
        }
        for v in [a, b] {
            for &f in self.mesh.faces_around(v) {
                for w in self.mesh.face(f) {
                    prefetch_all(&self.positions[w as usize]);
                }
            }
        }
        for (moved, other) in [(a, b), (b, a)] {
            for &f in self.mesh.faces_around(moved) {
                let face = self.mesh.face(f);
                if face.contains(&other) {
                    continue; // removed by the contraction
                }
                let old = face.map(|v| self.positions[v as usize]);
                let new = face.map(|v| {
                    if v == moved {
                        p
                    } else {
                        self.positions[v as usize]
                    }
                });
                if !self.face_stays_valid(f, old, new) {
                    return false;
                }
            }
        }
        true
    }

    fn face_stays_valid(&self, f: u32, old: [Vec3; 3], new: [Vec3; 3]) -> bool {
        let n_old = area_vector(old[0], old[1], old[2]);
        let n_new = area_vector(new[0], new[1], new[2]);
        // `dot(n, n) > 0` is `norm(n) > 0` without the square root.
        if dot(n_new, n_old) <= 0.0 && dot(n_old, n_old) > 0.0 {
            return false;
        }
        let original = self.original_normals[f as usize];
        if dot(n_new, original) <= 0.0 && dot(original, original) > 0.0 {
            return false;
        }
        let q_new = quality_with_normal(new[0], new[1], new[2], n_new);
        // The old quality matters only for a new sliver (it may have been one already).
        q_new >= MIN_QUALITY
            || (q_new > 0.0 && q_new >= quality_with_normal(old[0], old[1], old[2], n_old))
    }

    /// Asks for the records that re-placing edge `e` = (·, `other`) reads.
    pub(crate) fn prefetch_edge(&self, e: u32, other: u32) {
        prefetch_all(&self.quadrics[other as usize]);
        prefetch(&self.positions[other as usize]);
        prefetch_all(&self.placed[e as usize]);
        prefetch(&self.farthest[e as usize]);
        self.mesh.prefetch_vertex(other);
    }

    /// Asks for what settling edge `e` reads first.
    pub(crate) fn prefetch_top(&self, e: u32) {
        self.mesh.prefetch_edge(e);
        prefetch_all(&self.placed[e as usize]);
    }

    /// Asks for the positions of `v`'s neighbours.
    pub(crate) fn prefetch_neighbours(&self, v: u32) {
        for s in self.mesh.edges_around(v) {
            prefetch_all(&self.positions[s.to as usize]);
        }
    }

    /// Asks for the faces around the ends of edge `e` (where they are listed, and the
    /// quadrics), which checking its contraction reads next.
    pub(crate) fn prefetch_incident(&self, e: u32) {
        for v in self.mesh.edge(e) {
            self.mesh.prefetch_faces_around(v);
        }
    }

    /// Asks for edge `e`'s v̄ and cost.
    pub(crate) fn prefetch_placed(&self, e: u32) {
        prefetch_all(&self.placed[e as usize]);
    }

    /// Asks for where the edges around edge `e`'s ends are listed.
    pub(crate) fn prefetch_ends(&self, e: u32) {
        for v in self.mesh.edge(e) {
            self.mesh.prefetch_vertex(v);
        }
    }

    /// Asks for the record that the loop's scan of edge `e` reads.
    pub(crate) fn prefetch_farthest(&self, e: u32) {
        prefetch(&self.farthest[e as usize]);
    }

    /// Performs the contraction: `keep` moves to `p` and takes `remove`'s quadric, faces and
    /// edges; the ids of the edges that die go to `dead_edges`.
    pub(crate) fn contract(&mut self, keep: u32, remove: u32, p: Vec3, dead_edges: &mut Vec<u32>) {
        self.positions[keep as usize] = p;
        let q = self.quadrics[remove as usize];
        self.quadrics[keep as usize] += q;
        self.mesh.collapse(keep, remove, dead_edges);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    fn state(mesh: &mesh_io::TriMesh, lambda: f64) -> State {
        let positions: Vec<Vec3> = mesh.positions.iter().map(|&p| p.map(f64::from)).collect();
        let topology = crate::manifold::topology(positions.len(), &mesh.faces).expect("manifold");
        let boundary = topology.boundary.clone();
        let connectivity = Connectivity::from_topology(&mesh.faces, topology);
        let mut s = State::new(positions, &mesh.faces, &boundary, connectivity, lambda);
        s.place_all();
        s
    }

    /// The quadric of vertex v from scratch as a dense 4×4 matrix: Σ p pᵀ over its faces' planes.
    fn dense_vertex_quadric(mesh: &mesh_io::TriMesh, v: u32) -> [[f64; 4]; 4] {
        let mut m = [[0.0; 4]; 4];
        for f in mesh.faces.iter().filter(|f| f.contains(&v)) {
            let p = f.map(|i| mesh.positions[i as usize].map(f64::from));
            let n = area_vector(p[0], p[1], p[2]);
            let n = scale(n, 1.0 / norm(n));
            let plane = [n[0], n[1], n[2], -dot(n, p[0])];
            for i in 0..4 {
                for j in 0..4 {
                    m[i][j] += plane[i] * plane[j];
                }
            }
        }
        m
    }

    #[test]
    fn lambda_zero_cost_is_the_classical_quadric_error_at_the_placement() {
        let mesh = crate::shapes::icosphere(2);
        let mut s = state(&mesh, 0.0);
        for e in (0..s.mesh.edge_id_count() as u32).step_by(7) {
            let [a, b] = s.mesh.edge(e);
            let cost = s.recost(e);
            let p = s.placed(e);
            let (qa, qb) = (
                dense_vertex_quadric(&mesh, a),
                dense_vertex_quadric(&mesh, b),
            );
            let v = [p[0], p[1], p[2], 1.0];
            let dense: f64 = (0..4)
                .flat_map(|i| (0..4).map(move |j| (i, j)))
                .map(|(i, j)| v[i] * (qa[i][j] + qb[i][j]) * v[j])
                .sum();
            assert!(
                (cost - dense.max(0.0)).abs() < 1e-12,
                "edge {e}: {cost} vs {dense}"
            );
        }
    }

    #[test]
    fn length_term_adds_lambda_times_the_longest_new_edge() {
        let mesh = crate::shapes::torus(12, 8, 1.0, 0.3);
        let lambda = 0.25;
        let (mut classical, mut with_length) = (state(&mesh, 0.0), state(&mesh, lambda));
        for e in 0..classical.mesh.edge_id_count() as u32 {
            let [a, b] = classical.mesh.edge(e);
            let c0 = classical.recost(e);
            let c1 = with_length.recost(e);
            let p = with_length.placed(e);
            // Brute force: every vertex sharing a face with a or b, except a and b.
            let longest = mesh
                .faces
                .iter()
                .filter(|f| f.contains(&a) || f.contains(&b))
                .flat_map(|f| f.iter().copied())
                .filter(|&w| w != a && w != b)
                .map(|w| distance(p, mesh.positions[w as usize].map(f64::from)))
                .fold(0.0, f64::max);
            assert!((c1 - c0 - lambda * longest).abs() < 1e-12, "edge {e}");
        }
    }

    #[test]
    fn placement_is_the_quadric_optimum_when_regular_else_the_best_of_three() {
        let mesh = crate::shapes::icosphere(1);
        let s = state(&mesh, 0.0);
        for e in 0..s.mesh.edge_id_count() as u32 {
            let [a, b] = s.mesh.edge(e);
            let q = s.quadrics[a as usize] + s.quadrics[b as usize];
            let p = s.placement(a, b);
            // Curved closed surface: the optimum exists and sits near the edge.
            let optimum = q.minimizer().expect("regular");
            assert!(distance(p, optimum) < 1e-12);
            // No point of the segment is better.
            let (pa, pb) = (s.positions[a as usize], s.positions[b as usize]);
            for k in 0..=10 {
                let t = k as f64 / 10.0;
                let x = add(scale(pa, 1.0 - t), scale(pb, t));
                assert!(q.error(p) <= q.error(x) + 1e-12);
            }
        }
        // A flat grid: every quadric is singular; the midpoint wins the tie.
        let flat = mesh_io::TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        };
        let s = state(&flat, 0.0);
        let p = s.placement(0, 2);
        // Boundary planes pin both corners, so the least error is at an end or the middle;
        // the three candidates are all the choices there are.
        let q = s.quadrics[0] + s.quadrics[2];
        let candidates = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.5, 0.5, 0.0]];
        assert!(candidates.iter().any(|&c| distance(c, p) < 1e-12));
        assert!(candidates.iter().all(|&c| q.error(p) <= q.error(c) + 1e-12));
    }

    #[test]
    fn a_contraction_that_would_flip_a_face_is_invalid() {
        // A fan around vertex 0 in the plane; moving 0 far outside the fan flips faces.
        let mesh = mesh_io::TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [-1.0, 0.0, 0.0],
                [0.0, -1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]],
        };
        let mut s = state(&mesh, 0.0);
        assert!(s.is_valid(0, 1, [0.5, 0.0, 0.0]));
        assert!(
            !s.is_valid(0, 1, [-2.0, 0.0, 0.0]),
            "moving past 3 inverts faces"
        );
        // Onto the line through 2 and 3: face (0, 2, 3) becomes degenerate.
        assert!(!s.is_valid(0, 1, [-0.5, 0.5, 0.0]));
    }
}
