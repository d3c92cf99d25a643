//! The last pass: faces that point against the template ([`Surface::is_flipped`]) are fixed
//! locally whenever that lowers the number of such faces around and squashes no face: an edge
//! of theirs flipped, a corner moved, or, as a last resort, an edge of theirs collapsed and the
//! longest edge elsewhere split (the vertex count stays exact). The passes before compare a
//! face only with its own previous state, so a face can turn over by small steps, mostly where
//! the template is thinner than an edge (an ear); this pass compares with the template.

use super::editable::{Editable, Scratch};
use super::passes::{MIN_QUALITY, collapse_plan, project};
use super::surface::{Surface, THIN_PART};
use crate::geometry::{Vec3, add, area_vector, distance, quality_with_normal, scale};
use rayon::prelude::*;

/// Sweeps over the flipped faces at most this many times per measure.
const SWEEPS: usize = 6;

/// Repairs what it can, first by the strict measure (no margin for thin parts) with flips and
/// moves only, then by the measure every face must pass; returns how many faces that measure
/// still calls flipped.
pub(crate) fn repair_flips(m: &mut Editable, surface: &Surface) -> usize {
    // Judge the positions the output will have (f32), so that its report agrees.
    for p in &mut m.positions {
        *p = snap(*p);
    }
    // A face flipped with the margin is flipped without it: one scan finds every suspect.
    let suspects = flipped_faces(m, surface, 0.0);
    let suspects = sweep(m, surface, suspects, 0.0, false);
    sweep(m, surface, suspects, THIN_PART, true).len()
}

/// Fixes the faces of `suspects` that measure `thin` calls flipped, re-examining the faces
/// around every edit; returns the faces still flipped. Faces away from the edits keep their
/// state, so no others can have turned.
fn sweep(
    m: &mut Editable,
    surface: &Surface,
    mut suspects: Vec<u32>,
    thin: f64,
    collapses: bool,
) -> Vec<u32> {
    let mut scratch = Scratch::default();
    let mut longest = Vec::new();
    for _ in 0..SWEEPS {
        suspects.retain(|&f| m.is_face_alive(f) && is_flipped(m, surface, f, thin));
        let mut touched = Vec::new();
        for &f in &suspects {
            if !m.is_face_alive(f) || !is_flipped(m, surface, f, thin) {
                continue;
            }
            let fixed = flip_an_edge(m, surface, f, thin)
                .or_else(|| move_a_corner(m, surface, f, thin))
                .or_else(|| {
                    collapses.then(|| {
                        collapse_and_split(m, surface, f, thin, &mut scratch, &mut longest)
                    })?
                });
            touched.extend(fixed.into_iter().flatten());
        }
        if touched.is_empty() {
            break;
        }
        suspects.extend(faces_around(m, &touched));
        suspects.sort_unstable();
        suspects.dedup();
    }
    suspects.retain(|&f| m.is_face_alive(f) && is_flipped(m, surface, f, thin));
    suspects
}

/// `p` rounded to the f32 the output stores.
fn snap(p: Vec3) -> Vec3 {
    p.map(|x| f64::from(x as f32))
}

/// The live faces that measure `thin` calls flipped, ascending.
pub(crate) fn flipped_faces(m: &Editable, surface: &Surface, thin: f64) -> Vec<u32> {
    let faces: Vec<u32> = m.live_faces().map(|(f, _)| f).collect();
    faces
        .into_par_iter()
        .filter(|&f| is_flipped(m, surface, f, thin))
        .collect()
}

fn is_flipped(m: &Editable, surface: &Surface, f: u32, thin: f64) -> bool {
    let [a, b, c] = m.face(f).map(|v| m.positions[v as usize]);
    surface.is_flipped(a, b, c, thin)
}

/// The distinct live faces around `vertices`.
fn faces_around(m: &Editable, vertices: &[u32]) -> Vec<u32> {
    let mut faces: Vec<u32> = vertices
        .iter()
        .flat_map(|&v| m.faces_around(v).iter().copied())
        .collect();
    faces.sort_unstable();
    faces.dedup();
    faces
}

/// How many of `faces` point against the template, and the worst shape quality among them, with
/// the vertices of `moved` displaced; faces holding both `gone` vertices are left out (they
/// vanish in a collapse).
fn assess(
    m: &Editable,
    surface: &Surface,
    faces: &[u32],
    thin: f64,
    moved: &[(u32, Vec3)],
    gone: Option<[u32; 2]>,
) -> (usize, f64) {
    let corner = |v: u32| {
        moved
            .iter()
            .find(|(w, _)| *w == v)
            .map_or(m.positions[v as usize], |(_, p)| *p)
    };
    let mut flipped = 0;
    let mut worst = f64::INFINITY;
    for &f in faces {
        let face = m.face(f);
        if gone.is_some_and(|[a, b]| face.contains(&a) && face.contains(&b)) {
            continue;
        }
        let [a, b, c] = face.map(corner);
        worst = worst.min(quality_with_normal(a, b, c, area_vector(a, b, c)));
        flipped += usize::from(surface.is_flipped(a, b, c, thin));
    }
    (flipped, worst)
}

/// Whether the state after an edit is better: fewer flipped faces, no face squashed below
/// [`MIN_QUALITY`] unless one already was that bad.
fn better(before: (usize, f64), after: (usize, f64)) -> bool {
    after.0 < before.0 && after.1 >= MIN_QUALITY.min(before.1)
}

/// Flips the first edge of face `f` whose flip helps (undoing the others); returns the four
/// vertices of the flip.
fn flip_an_edge(m: &mut Editable, surface: &Surface, f: u32, thin: f64) -> Option<Vec<u32>> {
    let face = m.face(f);
    for (a, b) in [(face[0], face[1]), (face[1], face[2]), (face[2], face[0])] {
        let Some([c, d]) = m.can_flip(a, b) else {
            continue;
        };
        let around = faces_around(m, &[a, b]);
        let before = assess(m, surface, &around, thin, &[], None);
        let Some(undo) = m.flip(a, b) else {
            continue;
        };
        if better(before, assess(m, surface, &around, thin, &[], None)) {
            return Some(vec![a, b, c, d]);
        }
        m.unflip(undo);
    }
    None
}

/// The sum of the normals of the faces in `faces` that are not flipped: the way the surface
/// around faces, for projecting onto the right side of a thin part.
fn consensus(m: &Editable, surface: &Surface, faces: &[u32], thin: f64) -> Vec3 {
    faces
        .iter()
        .filter(|&&g| !is_flipped(m, surface, g, thin))
        .fold([0.0; 3], |s, &g| add(s, m.normal_with(g, &[])))
}

/// Moves the first inner corner of face `f` that can help to where it helps: the middle of its
/// neighbours or its own place, projected onto the side of the template the faces around face,
/// or the middle projected onto the closest point. Returns the corner.
fn move_a_corner(m: &mut Editable, surface: &Surface, f: u32, thin: f64) -> Option<Vec<u32>> {
    let mut neighbours = Vec::new();
    for v in m.face(f) {
        if m.is_boundary(v) {
            continue;
        }
        let around = faces_around(m, &[v]);
        let before = assess(m, surface, &around, thin, &[], None);
        m.neighbours(v, &mut neighbours);
        let middle = scale(
            neighbours
                .iter()
                .fold([0.0; 3], |s, &w| add(s, m.positions[w as usize])),
            1.0 / neighbours.len().max(1) as f64,
        );
        let facing = consensus(m, surface, &around, thin);
        let old = m.positions[v as usize];
        let candidates = [
            project(m, surface, v, middle, facing),
            project(m, surface, v, old, facing),
            project(m, surface, v, middle, [0.0; 3]),
        ]
        .map(snap);
        for p in candidates {
            if better(before, assess(m, surface, &around, thin, &[(v, p)], None)) {
                m.positions[v as usize] = p;
                return Some(vec![v]);
            }
        }
    }
    None
}

/// Collapses the first edge of face `f` whose collapse helps (into its planned point, or that
/// point projected onto the template), then splits the longest edge elsewhere whose split turns
/// nothing over. Returns the vertices around both edits.
fn collapse_and_split(
    m: &mut Editable,
    surface: &Surface,
    f: u32,
    thin: f64,
    scratch: &mut Scratch,
    longest: &mut Vec<[u32; 2]>,
) -> Option<Vec<u32>> {
    let face = m.face(f);
    let mut sides = [(face[0], face[1]), (face[1], face[2]), (face[2], face[0])];
    let length = |&(a, b): &(u32, u32)| distance(m.positions[a as usize], m.positions[b as usize]);
    sides.sort_by(|x, y| length(x).total_cmp(&length(y)));
    for (a, b) in sides {
        let (from, into, planned) = collapse_plan(m, a, b);
        if !m.can_collapse(from, into, scratch) {
            continue;
        }
        let around = faces_around(m, &[from, into]);
        let before = assess(m, surface, &around, thin, &[], None);
        let facing = consensus(m, surface, &around, thin);
        let projected = project(m, surface, into, planned, facing);
        for p in [planned, projected].map(snap) {
            let moved = [(from, p), (into, p)];
            let after = assess(m, surface, &around, thin, &moved, Some([from, into]));
            if !better(before, after) {
                continue;
            }
            let mut nearby: Vec<u32> = around.iter().flat_map(|&g| m.face(g)).collect();
            nearby.sort_unstable();
            m.collapse(from, into, p);
            let mut touched = vec![into];
            touched.extend(split_longest(m, surface, thin, longest, &nearby));
            return Some(touched);
        }
    }
    None
}

/// Splits the longest edge (not touching the vertices `keep_off`, ascending) whose split, with the new vertex projected
/// onto the template, turns over or squashes no face; returns its ends and the new vertex.
/// `longest` caches the edges by decreasing length (built on first use, consumed as it goes).
fn split_longest(
    m: &mut Editable,
    surface: &Surface,
    thin: f64,
    longest: &mut Vec<[u32; 2]>,
    keep_off: &[u32],
) -> Vec<u32> {
    if longest.is_empty() {
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
        // Shortest first, so that popping takes the longest.
        edges.sort_by(|x, y| x.0.total_cmp(&y.0).then(y.1.cmp(&x.1)));
        *longest = edges.into_iter().map(|(_, e)| e).collect();
    }
    let near = |v: u32| keep_off.binary_search(&v).is_ok();
    while let Some([a, b]) = longest.pop() {
        if m.edge_faces(a, b).count == 0 || near(a) || near(b) {
            continue;
        }
        let v = m.split(a, b, snap(m.midpoint(a, b)));
        let around = faces_around(m, &[v]);
        let normal = around
            .iter()
            .fold([0.0; 3], |s, &g| add(s, m.normal_with(g, &[])));
        let p = snap(project(m, surface, v, m.positions[v as usize], normal));
        let after = assess(m, surface, &around, thin, &[(v, p)], None);
        if after.0 == 0 && after.1 >= MIN_QUALITY {
            m.positions[v as usize] = p;
            return vec![a, b, v];
        }
        m.unsplit_last();
    }
    Vec::new()
}
