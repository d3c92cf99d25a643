//! The mesh being remeshed: faces with per-vertex face lists, and the three local operations of
//! isotropic remeshing (edge split, collapse and flip) with their topological preconditions.
//! Geometric checks (lengths, orientation) are the passes' business.

use super::surface::NONE;
use crate::geometry::{Vec3, add, area_vector, scale};

/// A triangle mesh under local edits. Dead vertices and faces keep their slots until
/// [`Editable::compact`].
pub(crate) struct Editable {
    pub positions: Vec<Vec3>,
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    /// The live faces around each vertex (empty for a dead or unused vertex).
    around: Vec<Vec<u32>>,
    /// Boundary loop of the template the vertex lies on, [`NONE`] inside.
    pub loop_of: Vec<u32>,
    /// Connected component of the template the vertex belongs to.
    pub component_of: Vec<u32>,
    live: usize,
}

impl Editable {
    /// A copy of `faces` on `positions`; the vertices no face uses are left out (dead).
    pub(crate) fn new(
        positions: Vec<Vec3>,
        faces: &[[u32; 3]],
        loop_of: Vec<u32>,
        component_of: Vec<u32>,
    ) -> Self {
        let mut around = vec![Vec::new(); positions.len()];
        for (i, f) in faces.iter().enumerate() {
            for &v in f {
                around[v as usize].push(i as u32);
            }
        }
        let live = around.iter().filter(|a| !a.is_empty()).count();
        Self {
            positions,
            faces: faces.to_vec(),
            face_alive: vec![true; faces.len()],
            around,
            loop_of,
            component_of,
            live,
        }
    }

    /// Live vertices.
    pub(crate) fn vertex_count(&self) -> usize {
        self.live
    }

    /// Vertex slots, dead ones included.
    pub(crate) fn slots(&self) -> usize {
        self.positions.len()
    }

    pub(crate) fn is_alive(&self, v: u32) -> bool {
        !self.around[v as usize].is_empty()
    }

    pub(crate) fn is_boundary(&self, v: u32) -> bool {
        self.loop_of[v as usize] != NONE
    }

    pub(crate) fn faces_around(&self, v: u32) -> &[u32] {
        &self.around[v as usize]
    }

    pub(crate) fn is_face_alive(&self, f: u32) -> bool {
        self.face_alive[f as usize]
    }

    pub(crate) fn face(&self, f: u32) -> [u32; 3] {
        self.faces[f as usize]
    }

    /// The number of neighbours: the faces around, plus one on the boundary (a fan of k faces
    /// with two boundary sides has k + 1 neighbours).
    pub(crate) fn valence(&self, v: u32) -> usize {
        self.around[v as usize].len() + usize::from(self.is_boundary(v))
    }

    /// The distinct neighbours of `v`, ascending, into `out`.
    pub(crate) fn neighbours(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        for &f in &self.around[v as usize] {
            out.extend(self.faces[f as usize].iter().filter(|&&w| w != v));
        }
        out.sort_unstable();
        out.dedup();
    }

    /// The faces on edge (a, b) (none if there is no such edge) and their vertices opposite it.
    pub(crate) fn edge_faces(&self, a: u32, b: u32) -> EdgeFaces {
        let mut e = EdgeFaces {
            faces: [NONE; 2],
            opposite: [NONE; 2],
            count: 0,
        };
        for &f in &self.around[a as usize] {
            let face = self.faces[f as usize];
            if face.contains(&b) && e.count < 2 {
                e.faces[e.count] = f;
                e.opposite[e.count] = third(face, a, b);
                e.count += 1;
            }
        }
        e
    }

    /// The distinct edges of the live faces, lower end first, ascending.
    pub(crate) fn edges(&self) -> Vec<[u32; 2]> {
        let mut edges: Vec<[u32; 2]> = self
            .live_faces()
            .flat_map(|(_, f)| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        edges
    }

    pub(crate) fn live_faces(&self) -> impl Iterator<Item = (u32, [u32; 3])> + '_ {
        self.faces
            .iter()
            .zip(&self.face_alive)
            .enumerate()
            .filter(|(_, (_, alive))| **alive)
            .map(|(i, (f, _))| (i as u32, *f))
    }

    /// Twice the area vector of face `f` with vertex `moved` (if in it) placed at `p`.
    pub(crate) fn normal_with(&self, f: u32, moved: &[(u32, Vec3)]) -> Vec3 {
        let corner = |v: u32| {
            moved
                .iter()
                .find(|(w, _)| *w == v)
                .map_or(self.positions[v as usize], |(_, p)| *p)
        };
        let [a, b, c] = self.faces[f as usize].map(corner);
        area_vector(a, b, c)
    }

    /// The area-weighted normal of `v` (not normalised).
    pub(crate) fn vertex_normal(&self, v: u32) -> Vec3 {
        self.around[v as usize]
            .iter()
            .fold([0.0; 3], |n, &f| add(n, self.normal_with(f, &[])))
    }

    /// Splits edge (a, b) (which must exist) at `p`: each face (a, b, c) becomes (a, m, c) (in
    /// its slot, corners in place) and (m, b, c) (appended), orientation kept. The new vertex m lies on the boundary loop of a boundary
    /// edge. Returns m.
    pub(crate) fn split(&mut self, a: u32, b: u32, p: Vec3) -> u32 {
        let e = self.edge_faces(a, b);
        let m = self.positions.len() as u32;
        self.positions.push(p);
        self.around.push(Vec::with_capacity(6));
        self.loop_of.push(if e.count == 1 {
            self.loop_of[a as usize]
        } else {
            NONE
        });
        self.component_of.push(self.component_of[a as usize]);
        for k in 0..e.count {
            let f = e.faces[k];
            let face = self.faces[f as usize];
            // The side from u to v in the face's own orientation, w the third corner.
            let i = (0..3)
                .find(|&i| {
                    let (x, y) = (face[i], face[(i + 1) % 3]);
                    (x == a && y == b) || (x == b && y == a)
                })
                .unwrap_or(0);
            let (v, w) = (face[(i + 1) % 3], face[(i + 2) % 3]);
            // f keeps its corner order, m in v's place.
            self.faces[f as usize][(i + 1) % 3] = m;
            let g = self.faces.len() as u32;
            self.faces.push([m, v, w]);
            self.face_alive.push(true);
            self.around[v as usize].retain(|&x| x != f);
            self.around[v as usize].push(g);
            self.around[w as usize].push(g);
            self.around[m as usize].extend([f, g]);
        }
        self.live += 1;
        m
    }

    /// Undoes the latest [`Editable::split`] (nothing may have changed since): its vertex and
    /// faces go, and the faces it cut are as they were.
    pub(crate) fn unsplit_last(&mut self) {
        let m = self.slots() as u32 - 1;
        let mut around = std::mem::take(&mut self.around[m as usize]);
        // The faces split() appended, (m, v, w), are the newer half; the cut ones hold m in
        // v's place.
        around.sort_unstable();
        let (cut, added) = around.split_at(around.len() / 2);
        for &g in added {
            let [_, v, w] = self.faces[g as usize];
            let Some(&f) = cut.iter().find(|&&f| self.faces[f as usize].contains(&w)) else {
                continue;
            };
            for corner in &mut self.faces[f as usize] {
                if *corner == m {
                    *corner = v;
                }
            }
            self.around[v as usize].retain(|&x| x != g);
            self.around[v as usize].push(f);
            self.around[w as usize].retain(|&x| x != g);
        }
        let first_new = added.first().map_or(self.faces.len(), |&g| g as usize);
        self.faces.truncate(first_new);
        self.face_alive.truncate(first_new);
        self.positions.pop();
        self.around.pop();
        self.loop_of.pop();
        self.component_of.pop();
        self.live -= 1;
    }

    /// Whether collapsing edge (a, b) keeps a 2-manifold of the same topology: the link
    /// condition (the common neighbours of a and b are exactly the corners opposite the edge),
    /// with the boundary closed by a virtual vertex (two boundary vertices merge only along a
    /// boundary edge), and never a lone triangle or a tetrahedron collapsed flat.
    pub(crate) fn can_collapse(&self, a: u32, b: u32, scratch: &mut Scratch) -> bool {
        let e = self.edge_faces(a, b);
        if e.count == 0 || (e.count == 2 && self.is_boundary(a) && self.is_boundary(b)) {
            return false;
        }
        self.neighbours(a, &mut scratch.a);
        self.neighbours(b, &mut scratch.b);
        let mut common = 0;
        for w in &scratch.a {
            if scratch.b.binary_search(w).is_ok() {
                if !e.opposite[..e.count].contains(w) {
                    return false;
                }
                common += 1;
            }
        }
        if common != e.count {
            return false;
        }
        // The opposite corner of a boundary edge must keep a face.
        if e.count == 1 && self.around[e.opposite[0] as usize].len() < 2 {
            return false;
        }
        // Faces (a, c, d) and (b, c, d) (c, d the opposite corners) close a tetrahedron, which
        // would fold flat.
        if e.count == 2 {
            let [c, d] = e.opposite;
            let folds = |v: u32| {
                self.around[v as usize].iter().any(|&f| {
                    let face = self.faces[f as usize];
                    face.contains(&c) && face.contains(&d)
                })
            };
            if folds(a) && folds(b) {
                return false;
            }
        }
        true
    }

    /// Collapses edge (a, b) into b, which moves to `p`; a dies. The faces on the edge go; the
    /// others of a take b in its place. Call only when [`Editable::can_collapse`] holds.
    pub(crate) fn collapse(&mut self, a: u32, b: u32, p: Vec3) {
        let faces = std::mem::take(&mut self.around[a as usize]);
        for f in faces {
            let face = self.faces[f as usize];
            if face.contains(&b) {
                self.face_alive[f as usize] = false;
                for v in face {
                    if v != a {
                        self.around[v as usize].retain(|&x| x != f);
                    }
                }
            } else {
                self.faces[f as usize] = face.map(|v| if v == a { b } else { v });
                self.around[b as usize].push(f);
            }
        }
        self.positions[b as usize] = p;
        self.live -= 1;
    }

    /// Whether edge (a, b) can be flipped to (c, d): an inner edge, c and d not yet joined.
    pub(crate) fn can_flip(&self, a: u32, b: u32) -> Option<[u32; 2]> {
        let e = self.edge_faces(a, b);
        if e.count != 2 {
            return None;
        }
        let [c, d] = e.opposite;
        let joined = self.around[c as usize]
            .iter()
            .any(|&f| self.faces[f as usize].contains(&d));
        (c != d && !joined).then_some([c, d])
    }

    /// The corners around inner edge (a, b) as `[a', b', c, d]`: faces (a', b', c) and
    /// (b', a', d) in their own orientation, {a', b'} = {a, b}. `None` on a boundary edge or no
    /// edge.
    pub(crate) fn diamond(&self, a: u32, b: u32) -> Option<[u32; 4]> {
        let e = self.edge_faces(a, b);
        if e.count != 2 {
            return None;
        }
        let [c, d] = e.opposite;
        Some(if runs(self.faces[e.faces[0] as usize], a, b) {
            [a, b, c, d]
        } else {
            [b, a, c, d]
        })
    }

    /// Flips edge (a, b) (checked by [`Editable::can_flip`]): faces (a, b, c) and (b, a, d)
    /// become (c, a, d) and (d, b, c), orientation kept. Returns what [`Editable::unflip`]
    /// needs to put the two faces back exactly (same slots).
    pub(crate) fn flip(&mut self, a: u32, b: u32) -> Option<Unflip> {
        let e = self.edge_faces(a, b);
        let [a, b, c, d] = self.diamond(a, b)?;
        let [f, g] = e.faces;
        let undo = Unflip {
            faces: [f, g],
            old: [self.faces[f as usize], self.faces[g as usize]],
            corners: [a, b, c, d],
        };
        // diamond() names the corners so that f = (a, b, c) and g = (b, a, d).
        self.faces[f as usize] = [c, a, d];
        self.faces[g as usize] = [d, b, c];
        self.around[b as usize].retain(|&x| x != f);
        self.around[a as usize].retain(|&x| x != g);
        self.around[d as usize].push(f);
        self.around[c as usize].push(g);
        Some(undo)
    }

    /// Undoes the flip that returned `undo` (nothing may have changed around since).
    pub(crate) fn unflip(&mut self, undo: Unflip) {
        let [f, g] = undo.faces;
        let [a, b, c, d] = undo.corners;
        self.faces[f as usize] = undo.old[0];
        self.faces[g as usize] = undo.old[1];
        self.around[d as usize].retain(|&x| x != f);
        self.around[c as usize].retain(|&x| x != g);
        self.around[b as usize].push(f);
        self.around[a as usize].push(g);
    }

    /// The midpoint of edge (a, b).
    pub(crate) fn midpoint(&self, a: u32, b: u32) -> Vec3 {
        scale(
            add(self.positions[a as usize], self.positions[b as usize]),
            0.5,
        )
    }

    /// The live vertices renumbered in slot order, and the live faces in slot order: positions,
    /// faces and each vertex's component.
    pub(crate) fn compact(&self) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<u32>) {
        let mut index = vec![NONE; self.slots()];
        let mut positions = Vec::with_capacity(self.live);
        let mut components = Vec::with_capacity(self.live);
        for (v, slot) in index.iter_mut().enumerate() {
            if self.is_alive(v as u32) {
                *slot = positions.len() as u32;
                positions.push(self.positions[v]);
                components.push(self.component_of[v]);
            }
        }
        let faces = self
            .live_faces()
            .map(|(_, f)| f.map(|v| index[v as usize]))
            .collect();
        (positions, faces, components)
    }
}

/// The faces on an edge and the corners opposite it (`count` of each: 0, 1 or 2).
#[derive(Debug, Clone, Copy)]
pub(crate) struct EdgeFaces {
    pub faces: [u32; 2],
    pub opposite: [u32; 2],
    pub count: usize,
}

/// What undoing a flip needs: the two face slots, their old corners, and the diamond.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Unflip {
    faces: [u32; 2],
    old: [[u32; 3]; 2],
    corners: [u32; 4],
}

/// Reusable neighbour lists.
#[derive(Default)]
pub(crate) struct Scratch {
    pub a: Vec<u32>,
    pub b: Vec<u32>,
}

/// The corner of `face` that is neither a nor b.
fn third(face: [u32; 3], a: u32, b: u32) -> u32 {
    face.into_iter().find(|&v| v != a && v != b).unwrap_or(NONE)
}

/// Whether `face` has the side a → b in its orientation.
fn runs(face: [u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|i| face[i] == a && face[(i + 1) % 3] == b)
}

#[cfg(test)]
mod tests;
