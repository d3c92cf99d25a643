//! The template as the surface the remesher projects onto: its triangles by connected
//! component, its boundary loops as polylines, and the test of a face against it.

use crate::geometry::{Vec3, add, area_vector, distance, dot, norm, scale, to_f64};
use crate::nearest::{Closest, NearestGrid};
use mesh_io::{Face, TriMesh};

/// How far beyond the closest template point, in units of a face's longest edge, a template
/// face facing the face's way still counts as "where the face is" (see [`Surface::is_flipped`]).
pub(crate) const THIN_PART: f64 = 0.1;

/// "No component" / "not on a boundary loop".
pub(crate) const NONE: u32 = u32::MAX;

/// The template, ready for closest-point queries restricted to one component or one loop.
pub(crate) struct Surface {
    /// Mean edge length of the template (counting each face's sides).
    spacing: f64,
    /// Unit face normals (zero for a degenerate face).
    face_normals: Vec<Vec3>,
    /// Fine vertex → connected component (numbered by lowest vertex), [`NONE`] when unused.
    pub component_of: Vec<u32>,
    /// Fine vertex → boundary loop (numbered by lowest vertex), [`NONE`] off the boundary.
    pub loop_of: Vec<u32>,
    /// The faces of each component (ids: face indices).
    by_component: Vec<NearestGrid>,
    /// The boundary edges of each loop, as segments (ids: the loop).
    by_loop: Vec<NearestGrid>,
    /// All faces, when there is more than one component.
    whole: Option<NearestGrid>,
}

impl Surface {
    /// The surface of `mesh` (faces valid, checked by the caller) whose boundary edges are
    /// `boundary`.
    pub(crate) fn new(mesh: &TriMesh, boundary: &[[u32; 2]]) -> Self {
        let n = mesh.vertex_count();
        let positions: Vec<Vec3> = mesh.positions.iter().map(|&p| to_f64(p)).collect();
        let component_of = label_sets(
            n,
            mesh.faces.iter().flat_map(|f| [[f[0], f[1]], [f[1], f[2]]]),
        );
        let loop_of = label_sets(n, boundary.iter().copied());
        let corners = |f: &Face| f.map(|v| positions[v as usize]);

        let mut face_normals = Vec::with_capacity(mesh.faces.len());
        let mut sides = 0.0;
        for f in &mesh.faces {
            let [a, b, c] = corners(f);
            sides += distance(a, b) + distance(b, c) + distance(c, a);
            face_normals.push(unit(area_vector(a, b, c)));
        }

        let components = count(&component_of);
        let mut items = vec![(Vec::new(), Vec::new()); components];
        for (i, f) in mesh.faces.iter().enumerate() {
            let (tris, ids) = &mut items[component_of[f[0] as usize] as usize];
            tris.push(corners(f));
            ids.push(i as u32);
        }
        let by_component = items
            .into_iter()
            .map(|(tris, ids)| NearestGrid::new(tris, ids))
            .collect();

        let mut segments = vec![(Vec::new(), Vec::new()); count(&loop_of)];
        for &[a, b] in boundary {
            let l = loop_of[a as usize];
            let (pa, pb) = (positions[a as usize], positions[b as usize]);
            segments[l as usize].0.push([pa, pb, pb]);
            segments[l as usize].1.push(l);
        }
        let by_loop = segments
            .into_iter()
            .map(|(segs, ids)| NearestGrid::new(segs, ids))
            .collect();

        let whole = (components > 1).then(|| {
            let tris = mesh.faces.iter().map(corners).collect();
            NearestGrid::new(tris, (0..mesh.faces.len() as u32).collect())
        });
        Self {
            spacing: sides / (3 * mesh.faces.len()).max(1) as f64,
            face_normals,
            component_of,
            loop_of,
            by_component,
            by_loop,
            whole,
        }
    }

    /// The closest point to `p` on the faces of component `component` that face the way of
    /// `normal` (positive dot product), or on any of its faces if none does. On a thin part
    /// (an ear, a lip) this keeps a vertex on its own side. Facing faces farther than the
    /// closest face by more than two template edges do not count: the answer stays local.
    pub(crate) fn on_component_facing(
        &self,
        component: u32,
        p: Vec3,
        normal: Vec3,
    ) -> Option<Closest> {
        let grid = self.by_component.get(component as usize)?;
        let closest = grid.closest(p, |_| true)?;
        if dot(self.face_normals[closest.id as usize], normal) > 0.0 {
            return Some(closest);
        }
        let reach = closest.distance_squared.sqrt() + 2.0 * self.spacing;
        let facing = |f: u32| dot(self.face_normals[f as usize], normal) > 0.0;
        Some(grid.closest_within(p, reach, facing).unwrap_or(closest))
    }

    /// The closest point to `p` on boundary loop `boundary_loop`.
    pub(crate) fn on_loop(&self, boundary_loop: u32, p: Vec3) -> Option<Vec3> {
        let grid = self.by_loop.get(boundary_loop as usize)?;
        Some(grid.closest(p, |_| true)?.point)
    }

    /// Whether triangle (a, b, c) faces against the template: its normal points against
    /// (negative dot product) the normal of the template face closest to its centroid, and
    /// against that of every template face up to `thin` × its longest edge farther away.
    /// [`THIN_PART`] is the measure of the output; 0 is the strict one.
    pub(crate) fn is_flipped(&self, a: Vec3, b: Vec3, c: Vec3, thin: f64) -> bool {
        let Some(grid) = self.whole.as_ref().or(self.by_component.first()) else {
            return false;
        };
        let n = area_vector(a, b, c);
        let centroid = scale(add(add(a, b), c), 1.0 / 3.0);
        let Some(closest) = grid.closest(centroid, |_| true) else {
            return false;
        };
        if dot(n, self.face_normals[closest.id as usize]) >= 0.0 {
            return false;
        }
        let longest = distance(a, b).max(distance(b, c)).max(distance(c, a));
        let reach = closest.distance_squared.sqrt() + thin * longest;
        let facing = |f: u32| dot(self.face_normals[f as usize], n) > 0.0;
        grid.closest_within(centroid, reach, facing).is_none()
    }
}

fn unit(v: Vec3) -> Vec3 {
    let length = norm(v);
    if length > 0.0 {
        scale(v, 1.0 / length)
    } else {
        [0.0; 3]
    }
}

/// Labels the sets of `n` elements joined by `pairs`, numbered by lowest member; elements in no
/// pair get [`NONE`].
fn label_sets(n: usize, pairs: impl Iterator<Item = [u32; 2]>) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut used = vec![false; n];
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for [a, b] in pairs {
        used[a as usize] = true;
        used[b as usize] = true;
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        // The lower root wins, so a set's root is its lowest member.
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
    let mut label = vec![NONE; n];
    let mut next = 0;
    for v in 0..n {
        if !used[v] {
            continue;
        }
        let r = root(&mut parent, v as u32) as usize;
        if label[r] == NONE {
            label[r] = next;
            next += 1;
        }
        label[v] = label[r];
    }
    label
}

fn count(labels: &[u32]) -> usize {
    labels
        .iter()
        .filter(|&&l| l != NONE)
        .map(|&l| l as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Coarse faces that point against the template. A face is flipped when its normal has a
/// negative dot product with the normal of the template face closest to its centroid, and with
/// the normal of every template face within 0.1 × its longest edge beyond that distance. The
/// margin matters only where the template is thinner than a tenth of the face (the ears of
/// elephant-gallop): there a correct face's centroid, off the surface by its sag, can lie
/// nearer the far side, and it is compared with the side it lies on. This is the flip count of
/// a remeshing, whose faces descend from no particular fine face. Faces with an index out of
/// range are skipped.
pub fn flipped_faces_on_surface(fine: &TriMesh, coarse: &TriMesh) -> usize {
    if fine.faces.is_empty()
        || fine
            .faces
            .iter()
            .flatten()
            .any(|&v| v as usize >= fine.vertex_count())
    {
        return 0;
    }
    let surface = Surface::new(fine, &[]);
    let position = |v: u32| coarse.positions.get(v as usize).map(|&p| to_f64(p));
    coarse
        .faces
        .iter()
        .filter(|f| match f.map(position) {
            [Some(a), Some(b), Some(c)] => surface.is_flipped(a, b, c, THIN_PART),
            _ => false,
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_and_loops_are_labelled_by_lowest_vertex() {
        // Two triangles apart, and vertex 3 unused.
        let labels = label_sets(7, [[4, 5], [5, 6], [0, 1], [1, 2]].into_iter());
        assert_eq!(labels, vec![0, 0, 0, NONE, 1, 1, 1]);
    }

    #[test]
    fn projection_normals_and_flips_on_a_sphere() {
        let sphere = crate::shapes::icosphere(3);
        let surface = Surface::new(&sphere, &[]);
        // A point outside the sphere projects close to the unit sphere, normal outwards.
        let p = [0.9, 1.2, -0.4];
        let closest = surface.on_component_facing(0, p, p).expect("one component");
        let r = norm(closest.point);
        assert!((r - 1.0).abs() < 0.01, "{r}");
        let n = surface.face_normals[closest.id as usize];
        assert!(dot(n, scale(p, 1.0 / norm(p))) > 0.99);
        // The sphere against itself flips nothing; reversed faces all flip.
        assert_eq!(flipped_faces_on_surface(&sphere, &sphere), 0);
        let mut inside_out = sphere.clone();
        for f in &mut inside_out.faces {
            f.swap(1, 2);
        }
        assert_eq!(
            flipped_faces_on_surface(&sphere, &inside_out),
            sphere.face_count()
        );
    }

    #[test]
    fn boundary_loops_project_onto_their_own_polyline() {
        let grid = crate::shapes::bumpy_grid(6, 6);
        let topology =
            crate::manifold::topology(grid.vertex_count(), &grid.faces).expect("manifold");
        let boundary: Vec<[u32; 2]> = topology
            .boundary
            .iter()
            .map(|&e| topology.edges[e as usize])
            .collect();
        let surface = Surface::new(&grid, &boundary);
        assert_eq!(surface.loop_of[0], 0);
        assert_eq!(surface.loop_of[7], NONE); // (1, 1) is inside
        // A point above the square near the side y = 0 lands on that side, not inside.
        let q = surface.on_loop(0, [0.5, 0.1, 0.3]).expect("one loop");
        assert!(q[1].abs() < 1e-12 && (0.2..0.8).contains(&q[0]), "{q:?}");
    }
}
