//! Per-vertex deformation gradients: T_i minimising
//!
//! Σ_j c_ij ‖(p'_i − p'_j) − T_i (p_i − p_j)‖² + w_i ‖m'_i − T_i m_i‖²
//!
//! over the one-ring j of i. The second term is the vertex-normal pair, as deformation transfer
//! adds a fourth vertex along the normal: without it the normal equations are singular on flat
//! one-rings and badly conditioned on nearly flat ones. m_i = √A_i n_i (rest unit normal scaled
//! by the square root of the ring area A_i), m'_i = √A'_i n'_i (the same in the deformed frame),
//! so the pair is exact for every similarity (rotation, uniform scale, translation): the fit then
//! returns that similarity's linear part. For other affine maps the normal target is only the
//! deformed surface normal, so on curved rings T_i differs slightly from the map (see
//! [`crate::integrate`] for the correction that makes the round trip exact anyway).
//!
//! w_i = `normal_weight` × (Σ_j c_ij |p_i − p_j|²) / (deg_i · A_i): the normal pair weighs as much
//! as an average edge of the ring when `normal_weight` = 1.
//!
//! The rest side of the normal equations, M_i = Σ_j c_ij e_ij e_ijᵀ + w_i m_i m_iᵀ, depends only on
//! the rest mesh and is inverted once. Rings where M_i is (nearly) singular anyway (no rest normal,
//! all edges collinear, isolated vertices) get a small extra term δ‖T_i − I‖², reported.

use crate::rest::RestMesh;
use crate::rotation::{Mat3, Vec3, add, add_outer, cross, inverse, mul, norm, scale, sub, svd};

/// A one-ring whose M_i has σ_min/σ_max below this is regularised towards the identity.
const MIN_CONDITION: f64 = 1e-9;

/// What the fit precomputes from the rest mesh.
#[derive(Debug, Clone)]
pub(crate) struct Fitter {
    /// M_i⁻¹.
    m_inv: Vec<Mat3>,
    /// w_i (0 where there is no rest normal).
    normal_weight: Vec<f64>,
    /// m_i = √A_i n_i.
    rest_normal: Vec<Vec3>,
    /// δ_i (0 for healthy rings).
    regularization: Vec<f64>,
    regularized: Vec<u32>,
}

impl Fitter {
    pub fn new(rest: &RestMesh, normal_weight: f64) -> Self {
        let n = rest.vertex_count();
        let p = rest.positions();
        let mut m_inv = Vec::with_capacity(n);
        let mut weights = Vec::with_capacity(n);
        let mut rest_normal = Vec::with_capacity(n);
        let mut regularization = Vec::with_capacity(n);
        let mut regularized = Vec::new();
        for i in 0..n {
            let (ring, c) = rest.ring(i);
            let mut m = [[0.0; 3]; 3];
            let mut edge_energy = 0.0;
            for (&j, &cij) in ring.iter().zip(c) {
                let e = sub(p[i], p[j as usize]);
                add_outer(&mut m, cij, e, e);
                edge_energy += cij * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
            }
            let area = rest.ring_areas()[i];
            let normal = rest.normals()[i];
            let has_normal = norm(normal) > 0.0 && area > 0.0 && !ring.is_empty();
            let (w, mi) = if has_normal {
                let w = normal_weight * edge_energy / (ring.len() as f64 * area);
                (w, scale(normal, area.sqrt()))
            } else {
                (0.0, [0.0; 3])
            };
            add_outer(&mut m, w, mi, mi);
            let sigma = svd(&m).sigma;
            let mut delta = 0.0;
            if sigma[2] <= MIN_CONDITION * sigma[0] || sigma[2].is_nan() {
                // Scale δ like the ring's own energy so the regularisation is dimensionless.
                delta = if sigma[0] > 0.0 { 1e-6 * sigma[0] } else { 1.0 };
                for (k, row) in m.iter_mut().enumerate() {
                    row[k] += delta;
                }
                regularized.push(i as u32);
            }
            // After regularisation M is SPD with condition ≤ ~1e6, so the inverse exists.
            m_inv.push(inverse(&m).unwrap_or(crate::rotation::IDENTITY));
            weights.push(w);
            rest_normal.push(mi);
            regularization.push(delta);
        }
        Self {
            m_inv,
            normal_weight: weights,
            rest_normal,
            regularization,
            regularized,
        }
    }

    /// Vertices whose fit is regularised towards the identity.
    pub fn regularized(&self) -> &[u32] {
        &self.regularized
    }

    /// T_i for every vertex of one deformed frame.
    #[cfg(test)]
    pub fn fit(&self, rest: &RestMesh, frame: &[Vec3]) -> Vec<Mat3> {
        self.fit_with_areas(rest, frame).0
    }

    /// T_i for every vertex of one deformed frame, and the frame's ring areas.
    pub fn fit_with_areas(&self, rest: &RestMesh, frame: &[Vec3]) -> (Vec<Mat3>, Vec<f64>) {
        let (normals, areas) = area_normals(rest, frame);
        let p = rest.positions();
        let t = (0..rest.vertex_count())
            .map(|i| {
                let (ring, c) = rest.ring(i);
                let mut b = [[0.0; 3]; 3];
                for (&j, &cij) in ring.iter().zip(c) {
                    let j = j as usize;
                    add_outer(&mut b, cij, sub(frame[i], frame[j]), sub(p[i], p[j]));
                }
                let w = self.normal_weight[i];
                if w > 0.0 {
                    let len = norm(normals[i]);
                    let target = if len > 0.0 {
                        scale(normals[i], areas[i].sqrt() / len)
                    } else {
                        [0.0; 3]
                    };
                    add_outer(&mut b, w, target, self.rest_normal[i]);
                }
                let d = self.regularization[i];
                for (k, row) in b.iter_mut().enumerate() {
                    row[k] += d;
                }
                mul(&b, &self.m_inv[i])
            })
            .collect();
        (t, areas)
    }
}

/// Area-weighted (unnormalised) vertex normals and ring areas of one frame.
pub(crate) fn area_normals(rest: &RestMesh, frame: &[Vec3]) -> (Vec<Vec3>, Vec<f64>) {
    let n = rest.vertex_count();
    let mut normals = vec![[0.0; 3]; n];
    let mut areas = vec![0.0; n];
    for f in rest.faces() {
        let p = f.map(|i| frame[i as usize]);
        let c = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let area = 0.5 * norm(c);
        for &i in f {
            normals[i as usize] = add(normals[i as usize], c);
            areas[i as usize] += area;
        }
    }
    (normals, areas)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::{IDENTITY, exp_rotation, frobenius, mul_vec};
    use crate::testmesh::{flat_grid, sphere};

    fn apply(a: &Mat3, t: Vec3, points: &[Vec3]) -> Vec<Vec3> {
        points.iter().map(|&p| add(mul_vec(a, p), t)).collect()
    }

    fn max_err(ts: &[Mat3], a: &Mat3) -> f64 {
        ts.iter()
            .map(|t| frobenius(&sub_m(t, a)))
            .fold(0.0, f64::max)
    }

    fn sub_m(a: &Mat3, b: &Mat3) -> Mat3 {
        let mut m = *a;
        for r in 0..3 {
            m[r] = sub(a[r], b[r]);
        }
        m
    }

    /// Reference: the weighted normal equations solved densely from scratch (with the
    /// normal pair), for one vertex.
    fn reference_fit(rest: &RestMesh, frame: &[Vec3], i: usize, normal_weight: f64) -> Mat3 {
        let p = rest.positions();
        let (ring, c) = rest.ring(i);
        let (mut m, mut b) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
        let mut energy = 0.0;
        for (&j, &cij) in ring.iter().zip(c) {
            let e = sub(p[i], p[j as usize]);
            let e2 = sub(frame[i], frame[j as usize]);
            for r in 0..3 {
                for s in 0..3 {
                    m[r][s] += cij * e[r] * e[s];
                    b[r][s] += cij * e2[r] * e[s];
                }
            }
            energy += cij * crate::rotation::dot(e, e);
        }
        let (nn, aa) = area_normals(rest, frame);
        let a0 = rest.ring_areas()[i];
        let w = normal_weight * energy / (ring.len() as f64 * a0);
        let m0 = scale(rest.normals()[i], a0.sqrt());
        let m1 = scale(nn[i], aa[i].sqrt() / norm(nn[i]));
        for r in 0..3 {
            for s in 0..3 {
                m[r][s] += w * m0[r] * m0[s];
                b[r][s] += w * m1[r] * m0[s];
            }
        }
        mul(&b, &inverse(&m).unwrap())
    }

    #[test]
    fn matches_dense_reference_on_a_random_deformation() {
        let (pos, faces) = sphere(6, 10);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let fitter = Fitter::new(&rest, 1.0);
        let frame: Vec<Vec3> = rest
            .positions()
            .iter()
            .map(|p| {
                [
                    p[0] + 0.3 * p[1] * p[1],
                    p[1] * (1.0 + 0.2 * p[2]),
                    p[2] + 0.1 * p[0],
                ]
            })
            .collect();
        let ts = fitter.fit(&rest, &frame);
        for i in [0, 5, 17, 33, 40] {
            let r = reference_fit(&rest, &frame, i, 1.0);
            assert!(frobenius(&sub_m(&ts[i], &r)) < 1e-12, "vertex {i}");
        }
    }

    #[test]
    fn rest_frame_gives_identity_and_similarities_are_exact() {
        let (pos, faces) = sphere(8, 12);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let fitter = Fitter::new(&rest, 1.0);
        assert!(fitter.regularized().is_empty());
        assert!(max_err(&fitter.fit(&rest, rest.positions()), &IDENTITY) < 1e-12);
        for (w, s) in [
            ([0.0, 0.0, 3.0], 1.0),
            ([1.0, -2.0, 0.5], 2.5),
            ([-0.1, 0.2, 0.05], 0.3),
        ] {
            let mut a = exp_rotation(w);
            a.iter_mut().flatten().for_each(|x| *x *= s);
            let frame = apply(&a, [4.0, -1.0, 2.0], rest.positions());
            assert!(max_err(&fitter.fit(&rest, &frame), &a) < 1e-11 * s);
        }
    }

    #[test]
    fn flat_grid_is_well_posed_and_exact_for_affine_maps() {
        // A flat one-ring alone cannot tell how the normal maps; the normal pair does.
        let (pos, faces) = flat_grid(6, 5, 0.0);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let fitter = Fitter::new(&rest, 1.0);
        assert!(fitter.regularized().is_empty());
        // In-plane affine maps (x, y) → A (x, y): exact, normal unchanged.
        let a = [[1.3, 0.4, 0.0], [-0.2, 0.8, 0.0], [0.0, 0.0, 1.0]];
        let frame = apply(&a, [0.5, 0.5, 0.0], rest.positions());
        let ts = fitter.fit(&rest, &frame);
        for t in &ts {
            // The in-plane columns are exactly A's (edges are in-plane).
            for r in 0..3 {
                for c in 0..2 {
                    assert!((t[r][c] - a[r][c]).abs() < 1e-12);
                }
            }
            assert!(t.iter().flatten().all(|x| x.is_finite()));
        }
        // A rigid motion of the flat grid: exactly the rotation, normal column included.
        let r = exp_rotation([0.4, 1.0, -0.7]);
        let ts = fitter.fit(&rest, &apply(&r, [1.0, 2.0, 3.0], rest.positions()));
        assert!(max_err(&ts, &r) < 1e-12);
    }

    #[test]
    fn boundary_vertices_fit_exactly_too() {
        // A curved open patch: corner and boundary vertices have partial rings.
        let (pos, faces) = flat_grid(7, 6, 0.4);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let fitter = Fitter::new(&rest, 1.0);
        let r = exp_rotation([2.0, -1.0, 0.5]);
        let ts = fitter.fit(&rest, &apply(&r, [0.0, 1.0, 0.0], rest.positions()));
        assert!(max_err(&ts, &r) < 1e-11);
        // A non-affine bend: the corner vertex still matches the dense reference.
        let frame: Vec<Vec3> = rest
            .positions()
            .iter()
            .map(|p| [p[0], p[1] + 0.2 * p[0] * p[0], p[2]])
            .collect();
        let ts = fitter.fit(&rest, &frame);
        let r0 = reference_fit(&rest, &frame, 0, 1.0);
        assert!(frobenius(&sub_m(&ts[0], &r0)) < 1e-12);
    }
}
