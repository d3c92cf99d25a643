//! The Garland–Heckbert error quadric: a symmetric 4×4 matrix Q such that vᵀQv, with
//! v = (x, y, z, 1), is the sum of squared distances from a point to a set of planes.

use crate::geometry::{Vec3, dot};

/// A symmetric 4×4 quadric, in f64, stored as its upper triangle
/// `[a11, a12, a13, a14, a22, a23, a24, a33, a34, a44]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Quadric([f64; 10]);

impl Quadric {
    /// The quadric of the plane n·x + d = 0, times `weight`: `weight · (n·x + d)²` at x. With a
    /// unit `normal` this is the weighted squared distance to the plane.
    pub fn plane(normal: Vec3, d: f64, weight: f64) -> Self {
        let [a, b, c] = normal;
        let w = weight;
        Self([
            w * a * a,
            w * a * b,
            w * a * c,
            w * a * d,
            w * b * b,
            w * b * c,
            w * b * d,
            w * c * c,
            w * c * d,
            w * d * d,
        ])
    }

    /// The quadric of the plane through `point` with unit `normal`, times `weight`.
    pub fn plane_through(point: Vec3, normal: Vec3, weight: f64) -> Self {
        Self::plane(normal, -dot(normal, point), weight)
    }

    /// vᵀQv with v = (p, 1).
    pub fn error(&self, p: Vec3) -> f64 {
        let q = &self.0;
        let [x, y, z] = p;
        x * x * q[0]
            + y * y * q[4]
            + z * z * q[7]
            + 2.0 * (x * y * q[1] + x * z * q[2] + y * z * q[5])
            + 2.0 * (x * q[3] + y * q[6] + z * q[8])
            + q[9]
    }

    /// The point minimising [`Quadric::error`], or `None` when the 3×3 system A·p = −b is
    /// singular: |det A| ≤ 1e-12 · trace(A)³ (A is positive semi-definite, so its trace bounds
    /// its largest eigenvalue and the test is scale-free).
    pub fn minimizer(&self) -> Option<Vec3> {
        let q = &self.0;
        let (a11, a12, a13, a22, a23, a33) = (q[0], q[1], q[2], q[4], q[5], q[7]);
        let b = [-q[3], -q[6], -q[8]];
        // Cofactors of the symmetric matrix A.
        let c11 = a22 * a33 - a23 * a23;
        let c12 = a13 * a23 - a12 * a33;
        let c13 = a12 * a23 - a13 * a22;
        let c22 = a11 * a33 - a13 * a13;
        let c23 = a12 * a13 - a11 * a23;
        let c33 = a11 * a22 - a12 * a12;
        let det = a11 * c11 + a12 * c12 + a13 * c13;
        let trace = a11 + a22 + a33;
        // Written so that a NaN determinant also counts as singular.
        let regular = det.is_finite() && det.abs() > 1e-12 * trace * trace * trace;
        if !regular {
            return None;
        }
        let p = [
            (c11 * b[0] + c12 * b[1] + c13 * b[2]) / det,
            (c12 * b[0] + c22 * b[1] + c23 * b[2]) / det,
            (c13 * b[0] + c23 * b[1] + c33 * b[2]) / det,
        ];
        p.iter().all(|c| c.is_finite()).then_some(p)
    }

    /// The full symmetric matrix, row-major (for tests and debugging).
    pub fn to_matrix(&self) -> [[f64; 4]; 4] {
        let q = &self.0;
        [
            [q[0], q[1], q[2], q[3]],
            [q[1], q[4], q[5], q[6]],
            [q[2], q[5], q[7], q[8]],
            [q[3], q[6], q[8], q[9]],
        ]
    }
}

impl std::ops::Add for Quadric {
    type Output = Self;
    fn add(mut self, rhs: Self) -> Self {
        self += rhs;
        self
    }
}

impl std::ops::AddAssign for Quadric {
    fn add_assign(&mut self, rhs: Self) {
        for (a, b) in self.0.iter_mut().zip(rhs.0) {
            *a += b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{norm, scale};

    fn dense_error(m: &[[f64; 4]; 4], p: Vec3) -> f64 {
        let v = [p[0], p[1], p[2], 1.0];
        (0..4)
            .map(|i| (0..4).map(|j| v[i] * m[i][j] * v[j]).sum::<f64>())
            .sum()
    }

    fn unit(v: Vec3) -> Vec3 {
        scale(v, 1.0 / norm(v))
    }

    /// Three weighted planes in general position, plus a fourth to make it least-squares.
    fn sample() -> (Quadric, Vec<(Vec3, f64, f64)>) {
        let planes = vec![
            (unit([1.0, 0.2, -0.1]), 0.3, 1.0),
            (unit([-0.3, 1.0, 0.4]), -0.7, 2.0),
            (unit([0.1, -0.2, 1.0]), 0.05, 0.5),
            (unit([1.0, 1.0, 1.0]), -0.4, 1.5),
        ];
        let q = planes.iter().fold(Quadric::default(), |q, &(n, d, w)| {
            q + Quadric::plane(n, d, w)
        });
        (q, planes)
    }

    #[test]
    fn error_is_the_weighted_sum_of_squared_plane_distances_and_the_dense_form() {
        let (q, planes) = sample();
        for p in [[0.0, 0.0, 0.0], [0.3, -1.2, 2.0], [5.0, 1.0, -3.0]] {
            let direct: f64 = planes
                .iter()
                .map(|&(n, d, w)| w * (dot(n, p) + d).powi(2))
                .sum();
            assert!((q.error(p) - direct).abs() < 1e-12 * (1.0 + direct));
            assert!((dense_error(&q.to_matrix(), p) - direct).abs() < 1e-12 * (1.0 + direct));
        }
    }

    #[test]
    fn minimizer_has_zero_gradient_and_beats_every_nearby_point() {
        let (q, _) = sample();
        let p = q.minimizer().expect("planes in general position");
        let e = q.error(p);
        // Central finite differences of the error: the gradient vanishes at the optimum.
        let h = 1e-5;
        for k in 0..3 {
            let (mut plus, mut minus) = (p, p);
            plus[k] += h;
            minus[k] -= h;
            let g = (q.error(plus) - q.error(minus)) / (2.0 * h);
            assert!(g.abs() < 1e-7, "gradient {g} along axis {k}");
        }
        // Brute force over a small lattice around it: nothing is lower.
        for i in -3..=3 {
            for j in -3..=3 {
                for k in -3..=3 {
                    let x = [
                        p[0] + 0.01 * i as f64,
                        p[1] + 0.01 * j as f64,
                        p[2] + 0.01 * k as f64,
                    ];
                    assert!(q.error(x) >= e - 1e-12);
                }
            }
        }
    }

    #[test]
    fn three_planes_meet_at_their_intersection_with_zero_error() {
        let q = Quadric::plane_through([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], 1.0)
            + Quadric::plane_through([1.0, 2.0, 3.0], [0.0, 1.0, 0.0], 1.0)
            + Quadric::plane_through([1.0, 2.0, 3.0], [0.0, 0.0, 1.0], 1.0);
        let p = q.minimizer().unwrap();
        for (a, b) in p.iter().zip([1.0, 2.0, 3.0]) {
            assert!((a - b).abs() < 1e-12);
        }
        assert!(q.error(p).abs() < 1e-12);
    }

    #[test]
    fn coplanar_planes_are_singular() {
        let q =
            Quadric::plane([0.0, 0.0, 1.0], 0.5, 1.0) + Quadric::plane([0.0, 0.0, 1.0], 0.5, 3.0);
        assert_eq!(q.minimizer(), None);
        assert_eq!(Quadric::default().minimizer(), None);
    }
}
