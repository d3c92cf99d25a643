//! Cotangent edge weights of the rest mesh, clamped so that every weight is positive and finite.
//!
//! The weight of edge (i, j) is c_ij = ½ (cot α + cot β), α and β the angles opposite the edge in
//! its (one or two, or more at non-manifold edges) triangles. Two kinds of triangle break this:
//! - obtuse triangles give a negative cotangent, and an edge can end up with c_ij ≤ 0 (where the
//!   opposite angles sum to more than π). A negative weight would turn the deformation-gradient fit
//!   into something that is not a least-squares problem and can make the Laplacian indefinite.
//! - degenerate triangles (zero area: collinear or coincident corners) give infinite cotangents.
//!
//! The choice made here: a triangle whose area is at most 1e-12 × its longest edge² is
//! *degenerate* and contributes nothing (it is reported); every other triangle contributes its
//! exact cotangents; then each edge weight is clamped to [`WeightClamp::min`, `WeightClamp::max`]
//! (default [1e-3, 1e3]). The same clamped weights are used by the fit and by the reconstruction,
//! so that the two least-squares problems are the same problem (which is what makes the rest mesh
//! and every affine map round-trip exactly).

use crate::rotation::{Vec3, cross, dot, norm, sub};
use mesh_io::Face;

/// Bounds applied to every cotangent edge weight (weights are dimensionless).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WeightClamp {
    /// Smallest weight an edge keeps (obtuse configurations would give ≤ 0). Must be > 0.
    pub min: f64,
    /// Largest weight (needle triangles give cotangents → ∞). Must be ≥ `min`.
    pub max: f64,
}

impl Default for WeightClamp {
    fn default() -> Self {
        Self {
            min: 1e-3,
            max: 1e3,
        }
    }
}

/// A triangle is degenerate when its area is at most this times its longest edge squared.
pub const DEGENERATE_AREA_RATIO: f64 = 1e-12;

/// The undirected edges of a face list with their clamped cotangent weights.
#[derive(Debug, Clone, Default)]
pub(crate) struct EdgeWeights {
    /// `(i, j, c_ij)` with `i < j`, sorted, one entry per edge.
    pub edges: Vec<(u32, u32, f64)>,
    /// Indices (into the face list) of the faces skipped as degenerate.
    pub degenerate_faces: Vec<usize>,
    /// Edges whose raw weight was below `min` (obtuse neighbourhoods, or only degenerate faces).
    pub clamped_low: usize,
    /// Edges whose raw weight was above `max`.
    pub clamped_high: usize,
}

/// Whether a triangle with these corners has (numerically) no area.
pub(crate) fn is_degenerate(a: Vec3, b: Vec3, c: Vec3) -> bool {
    let (ab, bc, ca) = (sub(b, a), sub(c, b), sub(a, c));
    let longest = dot(ab, ab).max(dot(bc, bc)).max(dot(ca, ca));
    0.5 * norm(cross(ab, sub(c, a))) <= DEGENERATE_AREA_RATIO * longest
}

/// Cotangent weights of every edge of `faces` (faces must have three distinct, in-range indices).
pub(crate) fn cotan_weights(positions: &[Vec3], faces: &[Face], clamp: WeightClamp) -> EdgeWeights {
    let mut contributions: Vec<(u32, u32, f64)> = Vec::with_capacity(faces.len() * 3);
    let mut degenerate_faces = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        let p = face.map(|i| positions[i as usize]);
        let degenerate = is_degenerate(p[0], p[1], p[2]);
        if degenerate {
            degenerate_faces.push(f);
        }
        for k in 0..3 {
            // Corner k is opposite the edge (k+1, k+2).
            let (i, j) = (face[(k + 1) % 3], face[(k + 2) % 3]);
            let half_cot = if degenerate {
                0.0
            } else {
                let u = sub(p[(k + 1) % 3], p[k]);
                let v = sub(p[(k + 2) % 3], p[k]);
                0.5 * dot(u, v) / norm(cross(u, v))
            };
            contributions.push((i.min(j), i.max(j), half_cot));
        }
    }
    contributions.sort_unstable_by_key(|c| (c.0, c.1));
    let mut out = EdgeWeights {
        degenerate_faces,
        ..Default::default()
    };
    for run in contributions.chunk_by(|a, b| (a.0, a.1) == (b.0, b.1)) {
        let raw: f64 = run.iter().map(|c| c.2).sum();
        let w = if raw < clamp.min {
            out.clamped_low += 1;
            clamp.min
        } else if raw > clamp.max {
            out.clamped_high += 1;
            clamp.max
        } else {
            raw
        };
        out.edges.push((run[0].0, run[0].1, w));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_and_right_triangles_have_known_weights() {
        // Two triangles sharing edge (0,1): an equilateral one above, a right isoceles below.
        let h = 3f64.sqrt() / 2.0;
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, h, 0.0],
            [0.5, -0.5, 0.0],
        ];
        let faces = [[0, 1, 2], [1, 0, 3]];
        let w = cotan_weights(&positions, &faces, WeightClamp::default());
        let get = |i, j| w.edges.iter().find(|e| (e.0, e.1) == (i, j)).unwrap().2;
        let cot60 = 1.0 / 3f64.sqrt();
        // Edge (0,1): opposite angles 60° (equilateral) and 90° (right angle at 3).
        assert!((get(0, 1) - 0.5 * (cot60 + 0.0)).abs() < 1e-15);
        // Boundary edges of the equilateral triangle: one 60° angle each.
        assert!((get(0, 2) - 0.5 * cot60).abs() < 1e-15);
        // Edge (0,3) of the right triangle: opposite angle 45° → ½.
        assert!((get(0, 3) - 0.5).abs() < 1e-15);
        assert_eq!(w.edges.len(), 5);
        assert!(w.degenerate_faces.is_empty());
    }

    #[test]
    fn obtuse_edges_are_clamped_to_the_minimum() {
        // Two very flat triangles on either side of edge (0,1): both opposite angles ≈ 180°.
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 0.01, 0.0],
            [0.5, -0.01, 0.0],
        ];
        let faces = [[0, 1, 2], [1, 0, 3]];
        let clamp = WeightClamp::default();
        let w = cotan_weights(&positions, &faces, clamp);
        let e01 = w.edges.iter().find(|e| (e.0, e.1) == (0, 1)).unwrap().2;
        assert_eq!(e01, clamp.min);
        // The other edges see needle angles (cot ≈ 50) and stay unclamped but large.
        assert!(w.edges.iter().all(|e| e.2 >= clamp.min && e.2 <= clamp.max));
        assert_eq!(w.clamped_low, 1);
    }

    #[test]
    fn degenerate_faces_contribute_nothing_and_weights_stay_finite() {
        // Face 1 is collinear, face 2 has two coincident corners (vertices 1 and 4).
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ];
        let faces = [[0, 1, 2], [0, 1, 3], [1, 4, 2]];
        let w = cotan_weights(&positions, &faces, WeightClamp::default());
        assert_eq!(w.degenerate_faces, vec![1, 2]);
        assert!(w.edges.iter().all(|e| e.2.is_finite() && e.2 > 0.0));
        // Edge (1,3) only belongs to the collinear face: clamped to the minimum.
        let e13 = w.edges.iter().find(|e| (e.0, e.1) == (1, 3)).unwrap().2;
        assert_eq!(e13, WeightClamp::default().min);
    }
}
