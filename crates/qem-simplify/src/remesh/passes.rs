//! The passes of Botsch & Kobbelt's isotropic remeshing over an [`Editable`] mesh: split long
//! edges, collapse short ones, flip towards regular valences, relax tangentially and project
//! back onto the template; plus the last exact splits or collapses that hit the vertex count.

use super::editable::{Editable, Scratch};
use super::surface::{NONE, Surface};
use crate::error::{Result, SimplifyError};
use crate::geometry::{Vec3, add, distance, dot, norm, quality_with_normal, scale, sub};
use rayon::prelude::*;

/// A new or moved face must keep at least this shape quality (1 = equilateral), unless it was
/// already worse: no needles or caps from the passes themselves.
pub(crate) const MIN_QUALITY: f64 = 0.05;

/// How tangential relaxation weighs the neighbours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Smoothing {
    /// Each neighbour weighted by its area (a third of its faces'): vertices drift towards
    /// where the area is, which evens out the faces' sizes (Botsch & Kobbelt 2004).
    #[default]
    Area,
    /// Plain average of the neighbours.
    Uniform,
}

/// Splits every edge longer than `high` at its midpoint, repeating until none is (each sweep
/// halves the long edges; the cap only guards against the pathological). Returns how many
/// splits.
pub(crate) fn split_long(m: &mut Editable, high: f64) -> usize {
    let mut total = 0;
    for _ in 0..64 {
        let mut done = 0;
        for [a, b] in m.edges() {
            if distance(m.positions[a as usize], m.positions[b as usize]) > high {
                m.split(a, b, m.midpoint(a, b));
                done += 1;
            }
        }
        total += done;
        if done == 0 {
            break;
        }
    }
    total
}

/// Collapses edges shorter than `low`, shortest first, each only if it keeps the surface a
/// manifold of the same topology, creates no edge longer than `high` and folds or squashes no
/// face. Returns how many collapses.
pub(crate) fn collapse_short(m: &mut Editable, low: f64, high: f64) -> usize {
    let mut edges: Vec<(f64, [u32; 2])> = m
        .edges()
        .into_iter()
        .map(|[a, b]| {
            (
                distance(m.positions[a as usize], m.positions[b as usize]),
                [a, b],
            )
        })
        .filter(|&(l, _)| l < low)
        .collect();
    edges.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let mut scratch = Scratch::default();
    let mut done = 0;
    for (_, [a, b]) in edges {
        if !m.is_alive(a) || !m.is_alive(b) {
            continue;
        }
        // Earlier collapses moved the ends: the edge may be long by now, or gone.
        if distance(m.positions[a as usize], m.positions[b as usize]) >= low {
            continue;
        }
        if try_collapse(m, a, b, high, &mut scratch) {
            done += 1;
        }
    }
    done
}

/// Collapses edge (a, b) if that is valid (see [`collapse_short`]), into its midpoint, or into
/// its boundary end when one end alone is on the boundary (the boundary stays put).
pub(crate) fn try_collapse(m: &mut Editable, a: u32, b: u32, high: f64, s: &mut Scratch) -> bool {
    let (from, into, p) = collapse_plan(m, a, b);
    if !m.can_collapse(from, into, s) || !collapse_keeps_shape(m, from, into, p, high, s) {
        return false;
    }
    m.collapse(from, into, p);
    true
}

/// Which end of edge (a, b) goes, which stays, and where that one moves: `(from, into, p)`.
/// The midpoint, or the boundary end when one end alone is on the boundary. Two boundary ends
/// only merge along a boundary edge, which `can_collapse` checks.
pub(crate) fn collapse_plan(m: &Editable, a: u32, b: u32) -> (u32, u32, Vec3) {
    match (m.is_boundary(a), m.is_boundary(b)) {
        (true, true) | (false, false) => (a, b, m.midpoint(a, b)),
        (true, false) => (b, a, m.positions[a as usize]),
        (false, true) => (a, b, m.positions[b as usize]),
    }
}

/// No edge from `p` longer than `high`, and no face around a or b that survives the collapse
/// turned over or squashed. `s` holds the neighbours of a and b (from `can_collapse`).
fn collapse_keeps_shape(m: &Editable, a: u32, b: u32, p: Vec3, high: f64, s: &Scratch) -> bool {
    let too_long = |w: &u32| *w != a && *w != b && distance(p, m.positions[*w as usize]) > high;
    if s.a.iter().any(too_long) || s.b.iter().any(too_long) {
        return false;
    }
    let moved = [(a, p), (b, p)];
    for &v in &[a, b] {
        for &f in m.faces_around(v) {
            let face = m.face(f);
            if face.contains(&a) && face.contains(&b) {
                continue;
            }
            if !keeps_shape(m, f, &moved) {
                return false;
            }
        }
    }
    true
}

/// Face `f` with the vertices `moved` displaced: not turned over (its normal within 90° of the
/// old one) and not squashed below [`MIN_QUALITY`] unless it already was.
fn keeps_shape(m: &Editable, f: u32, moved: &[(u32, Vec3)]) -> bool {
    let old = m.normal_with(f, &[]);
    let new = m.normal_with(f, moved);
    dot(old, new) > 0.0 && quality(m, f, moved, new) >= MIN_QUALITY.min(quality(m, f, &[], old))
}

fn quality(m: &Editable, f: u32, moved: &[(u32, Vec3)], normal: Vec3) -> f64 {
    let corner = |v: u32| {
        moved
            .iter()
            .find(|(w, _)| *w == v)
            .map_or(m.positions[v as usize], |(_, p)| *p)
    };
    let [a, b, c] = m.face(f).map(corner);
    quality_with_normal(a, b, c, normal)
}

/// Flips inner edges where that brings the four vertices' valences closer to 6 (4 on the
/// boundary), in total absolute deviation, without folding or squashing the two faces.
/// Returns how many flips.
pub(crate) fn equalize_valences(m: &mut Editable) -> usize {
    let mut done = 0;
    for [a, b] in m.edges() {
        let Some([c, d]) = m.can_flip(a, b) else {
            continue;
        };
        let deviation = |v: u32, change: isize| {
            let ideal = if m.is_boundary(v) { 4 } else { 6 };
            (m.valence(v) as isize + change - ideal).abs()
        };
        let before = deviation(a, 0) + deviation(b, 0) + deviation(c, 0) + deviation(d, 0);
        let after = deviation(a, -1) + deviation(b, -1) + deviation(c, 1) + deviation(d, 1);
        if after < before && flip_keeps_shape(m, a, b) && m.flip(a, b).is_some() {
            done += 1;
        }
    }
    done
}

/// The two faces after flipping (a, b) face the way both old faces did, and are not squashed
/// below [`MIN_QUALITY`] unless the old ones were.
fn flip_keeps_shape(m: &Editable, a: u32, b: u32) -> bool {
    let Some([a, b, c, d]) = m.diamond(a, b) else {
        return false;
    };
    let p = |v: u32| m.positions[v as usize];
    let old = [[a, b, c], [b, a, d]].map(|[x, y, z]| (p(x), p(y), p(z)));
    let new = [[c, a, d], [d, b, c]].map(|[x, y, z]| (p(x), p(y), p(z)));
    let normal = |(x, y, z): (Vec3, Vec3, Vec3)| crate::geometry::area_vector(x, y, z);
    let q = |t: (Vec3, Vec3, Vec3)| quality_with_normal(t.0, t.1, t.2, normal(t));
    let worst_old = q(old[0]).min(q(old[1]));
    new.iter().all(|&t| {
        old.iter().all(|&o| dot(normal(t), normal(o)) > 0.0) && q(t) >= MIN_QUALITY.min(worst_old)
    })
}

/// One step of tangential relaxation, then projection onto the template: inner vertices move
/// to the (weighted) average of their neighbours within their tangent plane, then onto the
/// closest point of their template component; boundary vertices move halfway to the middle of
/// their two boundary neighbours, then onto their template boundary loop. Vertices whose move
/// would turn over or squash a face stay where they were. Computed for all vertices from the
/// old positions (in parallel; the result does not depend on the thread count).
pub(crate) fn relax_and_project(m: &mut Editable, surface: &Surface, smoothing: Smoothing) {
    let slots = m.slots();
    let areas: Vec<f64> = match smoothing {
        Smoothing::Area => (0..slots as u32)
            .into_par_iter()
            .map(|v| {
                let faces = m.faces_around(v);
                faces
                    .iter()
                    .map(|&f| norm(m.normal_with(f, &[])))
                    .sum::<f64>()
                    / 6.0
            })
            .collect(),
        Smoothing::Uniform => Vec::new(),
    };
    let proposal: Vec<Vec3> = (0..slots as u32)
        .into_par_iter()
        .map(|v| {
            if !m.is_alive(v) {
                return m.positions[v as usize];
            }
            let target = relaxed(m, v, &areas);
            project(m, surface, v, target, m.vertex_normal(v))
        })
        .collect();
    move_guarded(m, proposal);
}

/// Projects every live vertex onto the template (its component, or its boundary loop).
pub(crate) fn project_all(m: &mut Editable, surface: &Surface) {
    let proposal: Vec<Vec3> = (0..m.slots() as u32)
        .into_par_iter()
        .map(|v| {
            let p = m.positions[v as usize];
            if m.is_alive(v) {
                project(m, surface, v, p, m.vertex_normal(v))
            } else {
                p
            }
        })
        .collect();
    move_guarded(m, proposal);
}

/// The relaxed position of live vertex `v`.
fn relaxed(m: &Editable, v: u32, areas: &[f64]) -> Vec3 {
    let p = m.positions[v as usize];
    let mut neighbours = Vec::with_capacity(8);
    m.neighbours(v, &mut neighbours);
    if m.is_boundary(v) {
        let ends: Vec<Vec3> = neighbours
            .iter()
            .filter(|&&w| m.edge_faces(v, w).count == 1)
            .map(|&w| m.positions[w as usize])
            .collect();
        if ends.len() != 2 {
            return p;
        }
        let middle = scale(add(ends[0], ends[1]), 0.5);
        return add(p, scale(sub(middle, p), 0.5));
    }
    let (mut sum, mut weight) = ([0.0; 3], 0.0);
    for &w in &neighbours {
        let k = areas.get(w as usize).copied().unwrap_or(1.0);
        sum = add(sum, scale(m.positions[w as usize], k));
        weight += k;
    }
    if weight <= 0.0 {
        return p;
    }
    let n = m.vertex_normal(v);
    let length = norm(n);
    let mut step = sub(scale(sum, 1.0 / weight), p);
    if length > 0.0 {
        let n = scale(n, 1.0 / length);
        step = sub(step, scale(n, dot(step, n)));
    }
    add(p, step)
}

/// `p` moved onto the template part vertex `v` belongs to: its boundary loop, or the faces of
/// its component facing the way of `normal` (v's normal).
pub(crate) fn project(m: &Editable, surface: &Surface, v: u32, p: Vec3, normal: Vec3) -> Vec3 {
    let boundary_loop = m.loop_of[v as usize];
    let projected = if boundary_loop != NONE {
        surface.on_loop(boundary_loop, p)
    } else {
        surface
            .on_component_facing(m.component_of[v as usize], p, normal)
            .map(|c| c.point)
    };
    projected.unwrap_or(p)
}

/// Moves the vertices to `proposal`, then puts back, until none is left, the vertices of every
/// face the move turned over or squashed. Ends, at worst, where it started.
fn move_guarded(m: &mut Editable, proposal: Vec<Vec3>) {
    let faces: Vec<(u32, [u32; 3])> = m.live_faces().collect();
    let before: Vec<(Vec3, f64)> = faces
        .par_iter()
        .map(|&(f, _)| {
            let n = m.normal_with(f, &[]);
            (n, quality(m, f, &[], n))
        })
        .collect();
    let old = std::mem::replace(&mut m.positions, proposal);
    loop {
        let m_ref = &*m;
        let bad: Vec<[u32; 3]> = faces
            .par_iter()
            .zip(&before)
            .filter(|((f, _), (n_old, q_old))| {
                let n = m_ref.normal_with(*f, &[]);
                (dot(n, *n_old) <= 0.0 && norm(*n_old) > 0.0)
                    || quality(m_ref, *f, &[], n) < MIN_QUALITY.min(*q_old)
            })
            .map(|(&(_, face), _)| face)
            .collect();
        let mut reverted = false;
        for v in bad.into_iter().flatten() {
            if m.positions[v as usize] != old[v as usize] {
                m.positions[v as usize] = old[v as usize];
                reverted = true;
            }
        }
        if !reverted {
            return;
        }
    }
}

/// Collapses the shortest or splits the longest edges until exactly `target` vertices are
/// live. Collapses follow [`collapse_short`]'s rules with no edge past `high`, then with no
/// length limit if that is not enough; splits always succeed.
pub(crate) fn reach_count(m: &mut Editable, target: usize, high: f64) -> Result<()> {
    let mut limit = high;
    let mut scratch = Scratch::default();
    while m.vertex_count() > target {
        let before = m.vertex_count();
        for (_, [a, b]) in by_length(m) {
            if m.vertex_count() == target {
                break;
            }
            if m.is_alive(a) && m.is_alive(b) {
                try_collapse(m, a, b, limit, &mut scratch);
            }
        }
        if m.vertex_count() == before {
            if limit.is_infinite() {
                return Err(SimplifyError::TargetUnreachable {
                    target,
                    reached: before,
                });
            }
            limit = f64::INFINITY;
        }
    }
    while m.vertex_count() < target {
        for (_, [a, b]) in by_length(m).into_iter().rev() {
            if m.vertex_count() == target {
                break;
            }
            if m.edge_faces(a, b).count > 0 {
                m.split(a, b, m.midpoint(a, b));
            }
        }
    }
    Ok(())
}

/// The edges, shortest first (ties by index).
fn by_length(m: &Editable) -> Vec<(f64, [u32; 2])> {
    let mut edges: Vec<(f64, [u32; 2])> = m
        .edges()
        .into_iter()
        .map(|[a, b]| {
            (
                distance(m.positions[a as usize], m.positions[b as usize]),
                [a, b],
            )
        })
        .collect();
    edges.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    edges
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::to_f64;
    use crate::manifold::manifold_defect;
    use mesh_io::TriMesh;

    /// The mesh as the remesher holds it, with its template surface.
    fn setup(mesh: &TriMesh) -> (Editable, Surface) {
        let topology = crate::manifold::topology(mesh.vertex_count(), &mesh.faces).unwrap();
        let boundary: Vec<[u32; 2]> = topology
            .boundary
            .iter()
            .map(|&e| topology.edges[e as usize])
            .collect();
        let surface = Surface::new(mesh, &boundary);
        let positions = mesh.positions.iter().map(|&p| to_f64(p)).collect();
        let m = Editable::new(
            positions,
            &mesh.faces,
            surface.loop_of.clone(),
            surface.component_of.clone(),
        );
        (m, surface)
    }

    fn lengths(m: &Editable) -> Vec<f64> {
        m.edges()
            .iter()
            .map(|&[a, b]| distance(m.positions[a as usize], m.positions[b as usize]))
            .collect()
    }

    fn cv(values: &[f64]) -> f64 {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt() / mean
    }

    fn manifold(m: &Editable) -> bool {
        let (positions, faces, _) = m.compact();
        manifold_defect(positions.len(), &faces).is_none()
    }

    #[test]
    fn split_leaves_no_long_edge_and_keeps_the_boundary_on_it() {
        let grid = crate::shapes::bumpy_grid(5, 5);
        let (mut m, _) = setup(&grid);
        let before = m.vertex_count();
        let high = 0.1;
        let splits = split_long(&mut m, high);
        assert!(splits > 0 && m.vertex_count() == before + splits);
        assert!(lengths(&m).iter().all(|&l| l <= high));
        assert!(manifold(&m));
        // New boundary vertices are midpoints of boundary edges: on the square's sides.
        for v in 0..m.slots() as u32 {
            if m.is_alive(v) && m.is_boundary(v) {
                let [x, y, _] = m.positions[v as usize];
                let on_side = [x, y]
                    .iter()
                    .any(|c| c.abs() < 1e-6 || (c - 1.0).abs() < 1e-6);
                assert!(on_side, "boundary vertex {v} at {x}, {y}");
            }
        }
    }

    #[test]
    fn collapse_removes_short_edges_without_long_ones_or_folds() {
        let sphere = crate::shapes::icosphere(3);
        let (mut m, _) = setup(&sphere);
        let mean = lengths(&m).iter().sum::<f64>() / lengths(&m).len() as f64;
        let (low, high) = (1.5 * mean, 2.5 * mean);
        let done = collapse_short(&mut m, low, high);
        assert!(done > 100, "{done} collapses");
        assert_eq!(m.vertex_count(), sphere.vertex_count() - done);
        assert!(lengths(&m).iter().all(|&l| l <= high));
        assert!(manifold(&m));
        // Every face still faces outwards, away from the centre.
        for (_, f) in m.live_faces() {
            let [a, b, c] = f.map(|v| m.positions[v as usize]);
            let centroid = scale(add(add(a, b), c), 1.0 / 3.0);
            assert!(dot(crate::geometry::area_vector(a, b, c), centroid) > 0.0);
        }
        // A second pass finds fewer short edges to take (most were collapsed or are blocked).
        let again = collapse_short(&mut m, low, high);
        assert!(again < done);
    }

    #[test]
    fn flips_bring_valences_towards_six() {
        // The bumpy grid alternates valence 4 and 8 inside.
        let grid = crate::shapes::bumpy_grid(12, 12);
        let (mut m, _) = setup(&grid);
        let deviation = |m: &Editable| -> usize {
            (0..m.slots() as u32)
                .filter(|&v| m.is_alive(v))
                .map(|v| {
                    let ideal = if m.is_boundary(v) { 4 } else { 6 };
                    (m.valence(v) as isize - ideal).unsigned_abs()
                })
                .sum()
        };
        let before = deviation(&m);
        let flips = equalize_valences(&mut m);
        assert!(flips > 0);
        assert!(deviation(&m) < before, "{} vs {before}", deviation(&m));
        assert!(manifold(&m));
        assert_eq!(m.vertex_count(), grid.vertex_count());
    }

    #[test]
    fn relaxation_evens_a_jittered_flat_grid_and_keeps_it_on_the_plane() {
        // A flat grid whose inner vertices are jittered within the plane.
        let mut grid = crate::shapes::bumpy_grid(10, 10);
        for (i, p) in grid.positions.iter_mut().enumerate() {
            p[2] = 0.0;
            let (x, y) = (i % 10, i / 10);
            if (1..9).contains(&x) && (1..9).contains(&y) {
                p[0] += 0.03 * ((i * 7 % 5) as f32 - 2.0);
                p[1] += 0.03 * ((i * 3 % 5) as f32 - 2.0);
            }
        }
        for smoothing in [Smoothing::Area, Smoothing::Uniform] {
            let (mut m, surface) = setup(&grid);
            let before = cv(&lengths(&m));
            for _ in 0..5 {
                relax_and_project(&mut m, &surface, smoothing);
            }
            let after = cv(&lengths(&m));
            assert!(after < 0.8 * before, "{smoothing:?}: {after} vs {before}");
            for (v, p) in m.positions.iter().enumerate() {
                assert!(p[2].abs() < 1e-12, "off the plane");
                if m.is_boundary(v as u32) {
                    let on_side = [p[0], p[1]]
                        .iter()
                        .any(|c| c.abs() < 1e-9 || (c - 1.0).abs() < 1e-9);
                    assert!(on_side, "boundary vertex {v} left the boundary: {p:?}");
                }
            }
        }
    }

    #[test]
    fn projection_puts_vertices_back_on_the_template() {
        // The icosphere's vertices pushed off it radially come back to its surface (distance
        // to the nearest template face ~0), and each onto its own side.
        let sphere = crate::shapes::icosphere(2);
        let (mut m, surface) = setup(&sphere);
        for (v, p) in m.positions.iter_mut().enumerate() {
            let s = if v % 2 == 0 { 1.05 } else { 0.96 };
            *p = scale(*p, s);
        }
        project_all(&mut m, &surface);
        let on_surface = |p: Vec3| {
            sphere
                .faces
                .iter()
                .map(|f| {
                    let [a, b, c] = f.map(|v| to_f64(sphere.positions[v as usize]));
                    distance(p, crate::nearest::closest_on_triangle(p, a, b, c))
                })
                .fold(f64::INFINITY, f64::min)
        };
        for (v, p) in m.positions.iter().enumerate() {
            let original = to_f64(sphere.positions[v]);
            // Outside a convex surface a radial push comes back to the vertex itself; inside,
            // onto the faces next to it.
            let tolerance = if v % 2 == 0 { 1e-9 } else { 0.1 };
            assert!(
                distance(*p, original) < tolerance,
                "vertex {v}: {p:?} vs {original:?}"
            );
            assert!(on_surface(*p) < 1e-12);
        }
        // Boundary vertices of a grid pulled outwards return onto the boundary polyline.
        let grid = crate::shapes::bumpy_grid(6, 6);
        let (mut m, surface) = setup(&grid);
        m.positions[2][1] = -0.2; // (0.4, 0) pulled off the side y = 0
        project_all(&mut m, &surface);
        assert!(m.positions[2][1].abs() < 1e-9);
    }

    #[test]
    fn exact_count_both_ways() {
        for target in [300, 642, 700] {
            let sphere = crate::shapes::icosphere(3); // 642 vertices
            let (mut m, _) = setup(&sphere);
            reach_count(&mut m, target, f64::INFINITY).expect("reachable");
            assert_eq!(m.vertex_count(), target);
            assert!(manifold(&m));
        }
        // A tetrahedron cannot lose a vertex and stay a closed surface.
        let tetra = TriMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            faces: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
        };
        let (mut m, _) = setup(&tetra);
        assert!(matches!(
            reach_count(&mut m, 3, f64::INFINITY),
            Err(SimplifyError::TargetUnreachable {
                target: 3,
                reached: 4
            })
        ));
    }
}
