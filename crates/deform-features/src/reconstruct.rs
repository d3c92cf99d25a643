//! Features → positions: R_i = exp(ω_i), T_i = R_i S_i, then the positions minimising
//!
//! Σ_i Σ_{j ∈ N(i)} c_ij ‖(p'_i − p'_j) − T_i (p_i − p_j)‖²,
//!
//! whose normal equations are L p' = b with L the rest mesh's cotangent Laplacian (the same
//! clamped weights as the fit) and b_k = ½ Σ_j c_kj (T_k + T_j)(p_k − p_j). L is factorised once
//! per rest mesh (sparse Cholesky, one vertex per connected component pinned, since translation
//! is free), then each shape costs one solve with 3 right-hand sides.
//!
//! Translation: each component of the result is moved so that its centroid is the rest mesh's
//! (for a connected mesh: the result's centroid is the rest centroid). Error figures of a round
//! trip therefore align centroids first.

use crate::error::FeatureError;
use crate::features::{CHANNELS, FeatureSet, decode};
use crate::integrate::{Integrator, pin_one_per_component};
use crate::rest::RestMesh;
use crate::rotation::{Mat3, Vec3, add, sub};
use crate::sparse::Cholesky;
use faer::Mat;
use faer::sparse::Triplet;
use rayon::prelude::*;

/// The factorised Laplacian of one rest mesh.
#[derive(Debug)]
pub struct Reconstructor {
    rest: RestMesh,
    index: Vec<usize>,
    unknowns: usize,
    chol: Option<Cholesky>,
    rest_centroids: Vec<Vec3>,
}

impl Reconstructor {
    /// Builds and factorises the rest mesh's Laplacian.
    pub fn new(rest: &RestMesh) -> Result<Self, FeatureError> {
        let (index, unknowns) = pin_one_per_component(rest);
        let mut triplets = Vec::new();
        for (i, &ri) in index.iter().enumerate() {
            if ri == usize::MAX {
                continue;
            }
            let (ring, c) = rest.ring(i);
            triplets.push(Triplet::new(ri, ri, c.iter().sum::<f64>()));
            for (&j, &cij) in ring.iter().zip(c) {
                let rj = index[j as usize];
                if rj != usize::MAX && rj > ri {
                    triplets.push(Triplet::new(rj, ri, -cij));
                }
            }
        }
        let chol = if unknowns > 0 {
            Some(Cholesky::new(
                unknowns,
                &triplets,
                "cotangent Laplacian",
                None,
            )?)
        } else {
            None
        };
        Ok(Self {
            rest: rest.clone(),
            index,
            unknowns,
            chol,
            rest_centroids: rest.component_centroids(rest.positions()),
        })
    }

    pub fn rest(&self) -> &RestMesh {
        &self.rest
    }

    /// Positions whose edges best match the gradients `t` (one 3×3 matrix per vertex).
    pub fn positions_from_gradients(&self, t: &[Mat3]) -> Result<Vec<Vec3>, FeatureError> {
        let n = self.rest.vertex_count();
        if t.len() != n {
            return Err(FeatureError::shape("gradients", n, t.len()));
        }
        let b = Integrator::divergence(&self.rest, t);
        let mut x = Mat::<f64>::zeros(self.unknowns, 3);
        for (k, &r) in self.index.iter().enumerate() {
            if r != usize::MAX {
                for d in 0..3 {
                    x[(r, d)] = b[k][d];
                }
            }
        }
        if let Some(chol) = &self.chol {
            chol.solve_in_place(x.as_mut());
        }
        let mut p: Vec<Vec3> = self
            .index
            .iter()
            .map(|&r| match r {
                usize::MAX => [0.0; 3],
                r => [x[(r, 0)], x[(r, 1)], x[(r, 2)]],
            })
            .collect();
        let centroids = self.rest.component_centroids(&p);
        for (q, &c) in p.iter_mut().zip(self.rest.component()) {
            let c = c as usize;
            *q = add(sub(*q, centroids[c]), self.rest_centroids[c]);
        }
        Ok(p)
    }

    /// Positions from one frame of raw (de-normalised) features, a flat [V, 9] slice.
    pub fn reconstruct(&self, features: &[f32]) -> Result<Vec<Vec3>, FeatureError> {
        let n = self.rest.vertex_count();
        if features.len() != n * CHANNELS {
            return Err(FeatureError::shape(
                "features of one frame",
                format!("{n} × {CHANNELS} values"),
                features.len(),
            ));
        }
        let mut t = Vec::with_capacity(n);
        for (v, chunk) in features.chunks_exact(CHANNELS).enumerate() {
            let mut f = [0.0; CHANNELS];
            for (x, &y) in f.iter_mut().zip(chunk) {
                *x = y as f64;
            }
            if !f.iter().all(|x| x.is_finite()) {
                return Err(FeatureError::input(
                    "features",
                    format!("vertex {v} has a non-finite value"),
                ));
            }
            t.push(decode(&f));
        }
        self.positions_from_gradients(&t)
    }

    /// Positions of every frame of `features` (raw, de-normalised), in parallel over frames.
    pub fn reconstruct_all(&self, features: &FeatureSet) -> Result<Vec<Vec<Vec3>>, FeatureError> {
        if features.vertices() != self.rest.vertex_count() {
            return Err(FeatureError::shape(
                "feature set",
                format!("{} vertices", self.rest.vertex_count()),
                format!("{} vertices", features.vertices()),
            ));
        }
        (0..features.frames())
            .into_par_iter()
            .map(|f| self.reconstruct(features.frame(f)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::{exp_rotation, mul_vec, norm};
    use crate::testmesh::sphere;

    #[test]
    fn identity_gradients_give_the_rest_mesh_and_rotations_a_rotated_one() {
        let (pos, faces) = sphere(6, 9);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let rec = Reconstructor::new(&rest).unwrap();
        let n = rest.vertex_count();
        let p = rec
            .positions_from_gradients(&vec![crate::rotation::IDENTITY; n])
            .unwrap();
        for (a, b) in p.iter().zip(rest.positions()) {
            assert!(norm(sub(*a, *b)) < 1e-12);
        }
        let r = exp_rotation([0.0, 2.0, 1.0]);
        let p = rec.positions_from_gradients(&vec![r; n]).unwrap();
        // Rotated about the rest centroid.
        let c = rest.component_centroids(rest.positions())[0];
        for (a, b) in p.iter().zip(rest.positions()) {
            let expected = add(mul_vec(&r, sub(*b, c)), c);
            assert!(norm(sub(*a, expected)) < 1e-12);
        }
    }

    #[test]
    fn solution_satisfies_the_normal_equations() {
        // Compare with the dense normal equations: L p = b on the pinned system.
        let (pos, faces) = sphere(4, 7);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let rec = Reconstructor::new(&rest).unwrap();
        let n = rest.vertex_count();
        let t: Vec<Mat3> = (0..n)
            .map(|i| {
                let x = i as f64 * 0.37;
                [
                    [1.0 + 0.1 * x.sin(), 0.2, 0.0],
                    [0.0, 1.0, 0.3 * x.cos()],
                    [0.1, 0.0, 0.9],
                ]
            })
            .collect();
        let p = rec.positions_from_gradients(&t).unwrap();
        let b = Integrator::divergence(&rest, &t);
        let lp = Integrator::laplacian(&rest, &p);
        for k in 0..n {
            assert!(norm(sub(b[k], lp[k])) < 1e-11, "vertex {k}");
        }
    }

    #[test]
    fn wrong_sizes_and_nan_are_errors() {
        let (pos, faces) = sphere(3, 5);
        let rest = RestMesh::new(&pos, &faces).unwrap();
        let rec = Reconstructor::new(&rest).unwrap();
        assert!(rec.reconstruct(&[0.0; 9]).is_err());
        let mut f = vec![0.0f32; rest.vertex_count() * 9];
        f[4] = f32::NAN;
        assert!(rec.reconstruct(&f).is_err());
    }
}
