//! 3×3 helpers in f64: products, inverse, SVD (one-sided Jacobi), polar decomposition, and the
//! rotation log/exp maps between rotation matrices and axis-angle vectors.
//!
//! Index loops over 0..3 are the clearest form of 3×3 algebra, hence the clippy allowance.
//!
//! Matrices are row-major (`m[row][col]`). Rotation vectors ω = θ·a (unit axis a, angle θ)
//! act as `exp([ω]×)`, the right-handed rotation by θ about a.
#![allow(clippy::needless_range_loop)]

/// A 3-vector.
pub type Vec3 = [f64; 3];
/// A 3×3 matrix, row-major: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a · b` (matrix product).
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for (r, row) in m.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c];
        }
    }
    m
}

/// `a · v`.
pub fn mul_vec(a: &Mat3, v: Vec3) -> Vec3 {
    [dot(a[0], v), dot(a[1], v), dot(a[2], v)]
}

pub fn transpose(a: &Mat3) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for (r, row) in a.iter().enumerate() {
        for (c, &x) in row.iter().enumerate() {
            m[c][r] = x;
        }
    }
    m
}

pub fn det(a: &Mat3) -> f64 {
    dot(a[0], cross(a[1], a[2]))
}

/// Adds `s · a bᵀ` to `m`.
pub fn add_outer(m: &mut Mat3, s: f64, a: Vec3, b: Vec3) {
    for r in 0..3 {
        for c in 0..3 {
            m[r][c] += s * a[r] * b[c];
        }
    }
}

/// The inverse by cofactors, or `None` when `|det| ≤ 1e-300` or the result is not finite.
pub fn inverse(a: &Mat3) -> Option<Mat3> {
    let c0 = cross(a[1], a[2]);
    let c1 = cross(a[2], a[0]);
    let c2 = cross(a[0], a[1]);
    let d = dot(a[0], c0);
    if d.abs() <= 1e-300 {
        return None;
    }
    // Rows of the cofactor matrix are the columns of the inverse.
    let inv = [
        [c0[0] / d, c1[0] / d, c2[0] / d],
        [c0[1] / d, c1[1] / d, c2[1] / d],
        [c0[2] / d, c1[2] / d, c2[2] / d],
    ];
    inv.iter().flatten().all(|x| x.is_finite()).then_some(inv)
}

/// `a⁻ᵀ = cof(a)/det a` (rows are cross products of rows), or `None` when not finite.
fn inverse_transpose(a: &Mat3) -> Option<Mat3> {
    let c = [cross(a[1], a[2]), cross(a[2], a[0]), cross(a[0], a[1])];
    let inv_d = 1.0 / dot(a[0], c[0]);
    inv_d.is_finite().then(|| c.map(|row| scale(row, inv_d)))
}

/// Frobenius norm.
pub fn frobenius(a: &Mat3) -> f64 {
    a.iter().flatten().map(|x| x * x).sum::<f64>().sqrt()
}

/// The skew matrix `[ω]×` with `[ω]× v = ω × v`.
pub fn skew(w: Vec3) -> Mat3 {
    [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
}

/// A singular value decomposition `a = u · diag(sigma) · vᵀ`, `u` and `v` orthogonal (either
/// determinant), `sigma` non-negative and descending.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Svd {
    pub u: Mat3,
    pub sigma: Vec3,
    pub v: Mat3,
}

/// SVD by one-sided Jacobi (Hestenes): rotate the columns of `a` until they are mutually
/// orthogonal. This keeps small singular values accurate to their own size (unlike an eigen
/// decomposition of aᵀa), which the polar decomposition of thin deformation gradients needs.
pub fn svd(a: &Mat3) -> Svd {
    let mut w = *a;
    let mut v = IDENTITY;
    for _sweep in 0..40 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
            for row in &w {
                alpha += row[p] * row[p];
                beta += row[q] * row[q];
                gamma += row[p] * row[q];
            }
            if gamma == 0.0 || gamma.abs() <= 1e-15 * (alpha * beta).sqrt() {
                continue;
            }
            rotated = true;
            let zeta = (beta - alpha) / (2.0 * gamma);
            // tan of the rotation angle, the smaller root; 1/(2ζ) where ζ² would overflow.
            let t = if zeta.abs() < 1e150 {
                zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt())
            } else {
                0.5 / zeta
            };
            let c = 1.0 / (1.0 + t * t).sqrt();
            let s = c * t;
            for m in [&mut w, &mut v] {
                for row in m.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - s * y;
                    row[q] = s * x + c * y;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let col_norm =
        |m: &Mat3, k: usize| (m[0][k] * m[0][k] + m[1][k] * m[1][k] + m[2][k] * m[2][k]).sqrt();
    let mut order = [0usize, 1, 2];
    let norms = [col_norm(&w, 0), col_norm(&w, 1), col_norm(&w, 2)];
    order.sort_by(|&i, &j| norms[j].total_cmp(&norms[i]));
    let sigma = [norms[order[0]], norms[order[1]], norms[order[2]]];
    let mut vs = [[0.0; 3]; 3];
    let mut us: [Vec3; 3] = [[0.0; 3]; 3]; // columns of u
    for (k, &o) in order.iter().enumerate() {
        for r in 0..3 {
            vs[r][k] = v[r][o];
        }
        us[k] = [w[0][o], w[1][o], w[2][o]];
    }
    // Columns with a (relatively) negligible singular value carry no direction: complete the
    // basis from the others instead of dividing by ~0.
    let tiny = 1e-13 * sigma[0];
    let unit = |x: Vec3| scale(x, 1.0 / norm(x));
    if sigma[0] <= f64::MIN_POSITIVE {
        return Svd {
            u: IDENTITY,
            sigma: [0.0; 3],
            v: vs,
        };
    }
    us[0] = unit(us[0]);
    if sigma[1] > tiny {
        us[1] = unit(us[1]);
    } else {
        us[1] = unit(any_perpendicular(us[0]));
    }
    if sigma[2] > tiny {
        us[2] = unit(us[2]);
    } else {
        us[2] = unit(cross(us[0], us[1]));
    }
    Svd {
        u: [
            [us[0][0], us[1][0], us[2][0]],
            [us[0][1], us[1][1], us[2][1]],
            [us[0][2], us[1][2], us[2][2]],
        ],
        sigma,
        v: vs,
    }
}

/// A non-zero vector perpendicular to `a` (which must be non-zero).
fn any_perpendicular(a: Vec3) -> Vec3 {
    let k = (0..3)
        .min_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[k] = 1.0;
    cross(a, e)
}

/// Polar decomposition `t = r · s`: `r` a proper rotation (det +1), `s` symmetric. When
/// det t < 0, `s` gets one negative eigenvalue (the one of smallest magnitude), so that `r`
/// stays a rotation and `r · s` is still exactly `t`.
///
/// Well-conditioned inputs with det > 0 (nearly all deformation gradients) use Higham's scaled
/// Newton iteration r ← ½(γ r + (γ r)⁻ᵀ), which converges quadratically in a few steps; the
/// rest (det ≤ 0, nearly singular, or no convergence) go through the SVD.
pub fn polar(t: &Mat3) -> (Mat3, Mat3) {
    newton_polar(t).unwrap_or_else(|| svd_polar(t))
}

fn newton_polar(t: &Mat3) -> Option<(Mat3, Mat3)> {
    let size = frobenius(t);
    let d = det(t);
    if d.is_nan() || d <= 1e-6 * size * size * size {
        return None;
    }
    let mut x = *t;
    let mut scaled = true;
    for _ in 0..30 {
        let inv_t = inverse_transpose(&x)?;
        // Scaling speeds up the first steps of far-from-orthogonal inputs; near convergence γ → 1.
        let gamma = if scaled {
            (frobenius(&inv_t) / frobenius(&x)).sqrt()
        } else {
            1.0
        };
        let (g, inv_g) = (0.5 * gamma, 0.5 / gamma);
        let mut change = 0.0;
        for r in 0..3 {
            for c in 0..3 {
                let next = g * x[r][c] + inv_g * inv_t[r][c];
                change += (next - x[r][c]).powi(2);
                x[r][c] = next;
            }
        }
        scaled = change > 1e-6;
        if change < 1e-14 {
            // Quadratic convergence: the error is now ~1e-14, one more plain step reaches
            // rounding level.
            let inv_t = inverse_transpose(&x)?;
            for r in 0..3 {
                for c in 0..3 {
                    x[r][c] = 0.5 * (x[r][c] + inv_t[r][c]);
                }
            }
            let mut s = mul(&transpose(&x), t);
            for r in 0..3 {
                for c in r + 1..3 {
                    let m = 0.5 * (s[r][c] + s[c][r]);
                    s[r][c] = m;
                    s[c][r] = m;
                }
            }
            return Some((x, s));
        }
    }
    None
}

fn svd_polar(t: &Mat3) -> (Mat3, Mat3) {
    let Svd { u, sigma, v } = svd(t);
    let d = if det(&u) * det(&v) < 0.0 { -1.0 } else { 1.0 };
    let sig = [sigma[0], sigma[1], d * sigma[2]];
    let mut r = [[0.0; 3]; 3];
    let mut s = [[0.0; 3]; 3];
    let dd = [1.0, 1.0, d];
    for a in 0..3 {
        for b in 0..3 {
            r[a][b] = (0..3).map(|k| u[a][k] * dd[k] * v[b][k]).sum();
            s[a][b] = (0..3).map(|k| v[a][k] * sig[k] * v[b][k]).sum();
        }
    }
    (r, s)
}

/// The principal rotation vector of a rotation matrix: angle in [0, π].
pub fn log_rotation(r: &Mat3) -> Vec3 {
    let w = [
        0.5 * (r[2][1] - r[1][2]),
        0.5 * (r[0][2] - r[2][0]),
        0.5 * (r[1][0] - r[0][1]),
    ];
    let s = norm(w);
    let c = (0.5 * (r[0][0] + r[1][1] + r[2][2] - 1.0)).clamp(-1.0, 1.0);
    let theta = s.atan2(c);
    if c > 0.0 {
        // θ < π/2: the skew part gives the axis accurately; θ/sin θ → 1 + θ²/6 near 0.
        let f = if s < 1e-8 {
            1.0 + theta * theta / 6.0
        } else {
            theta / s
        };
        return scale(w, f);
    }
    // θ ≥ π/2: sin θ may be tiny near π, so read the axis off the symmetric part,
    // (r + rᵀ)/2 = cos θ·I + (1 − cos θ)·a aᵀ, and take its sign from the skew part.
    let one_minus_c = 1.0 - c;
    let diag = [
        (r[0][0] - c) / one_minus_c,
        (r[1][1] - c) / one_minus_c,
        (r[2][2] - c) / one_minus_c,
    ];
    let k = (0..3)
        .max_by(|&i, &j| diag[i].total_cmp(&diag[j]))
        .unwrap_or(0);
    let ak = diag[k].max(0.0).sqrt();
    let mut axis = [0.0; 3];
    for (j, x) in axis.iter_mut().enumerate() {
        *x = if j == k {
            ak
        } else {
            0.5 * (r[j][k] + r[k][j]) / (one_minus_c * ak)
        };
    }
    let axis = scale(axis, 1.0 / norm(axis));
    let sign = if dot(axis, w) < 0.0 { -1.0 } else { 1.0 };
    scale(axis, sign * theta)
}

/// The rotation matrix `exp([ω]×)` (Rodrigues), for any |ω|.
pub fn exp_rotation(w: Vec3) -> Mat3 {
    let t2 = dot(w, w);
    let t = t2.sqrt();
    // sin θ/θ and (1 − cos θ)/θ², by their series where the closed forms lose digits.
    let (a, b) = if t < 1e-4 {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        (t.sin() / t, (1.0 - t.cos()) / t2)
    };
    let k = skew(w);
    let k2 = mul(&k, &k);
    let mut r = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] += a * k[i][j] + b * k2[i][j];
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator for test matrices (xorshift).
    pub(crate) struct Rng(pub u64);
    impl Rng {
        pub fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
        pub fn mat(&mut self) -> Mat3 {
            let mut m = [[0.0; 3]; 3];
            m.iter_mut().flatten().for_each(|x| *x = self.next());
            m
        }
        pub fn vec(&mut self) -> Vec3 {
            [self.next(), self.next(), self.next()]
        }
    }

    fn max_diff(a: &Mat3, b: &Mat3) -> f64 {
        (0..9)
            .map(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs())
            .fold(0.0, f64::max)
    }

    fn is_rotation(r: &Mat3, tol: f64) -> bool {
        max_diff(&mul(&transpose(r), r), &IDENTITY) < tol && (det(r) - 1.0).abs() < tol
    }

    #[test]
    fn inverse_matches_product() {
        let mut rng = Rng(7);
        for _ in 0..100 {
            let a = rng.mat();
            let inv = inverse(&a).unwrap();
            assert!(max_diff(&mul(&a, &inv), &IDENTITY) < 1e-9 * (1.0 + frobenius(&inv)));
        }
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }

    #[test]
    fn svd_reconstructs_random_and_rank_deficient_matrices() {
        let mut rng = Rng(11);
        let mut cases: Vec<Mat3> = (0..200).map(|_| rng.mat()).collect();
        cases.push([[0.0; 3]; 3]);
        cases.push([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [3.0, 6.0, 9.0]]); // rank 1
        cases.push([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]); // rank 2
        cases.push([[1.0, 1e-9, 0.0], [0.0, 1e-12, 0.0], [0.0, 0.0, 1e-30]]);
        for a in cases {
            let Svd { u, sigma, v } = svd(&a);
            assert!(sigma[0] >= sigma[1] && sigma[1] >= sigma[2] && sigma[2] >= 0.0);
            for m in [&u, &v] {
                assert!(max_diff(&mul(&transpose(m), m), &IDENTITY) < 1e-12);
            }
            let us = [
                [u[0][0] * sigma[0], u[0][1] * sigma[1], u[0][2] * sigma[2]],
                [u[1][0] * sigma[0], u[1][1] * sigma[1], u[1][2] * sigma[2]],
                [u[2][0] * sigma[0], u[2][1] * sigma[1], u[2][2] * sigma[2]],
            ];
            let back = mul(&us, &transpose(&v));
            assert!(max_diff(&back, &a) < 1e-13 * (1.0 + frobenius(&a)), "{a:?}");
        }
    }

    #[test]
    fn svd_keeps_small_singular_values_accurate() {
        // diag(1, 1e-6, 1e-10) turned by two rotations: relative accuracy of the small ones.
        let q1 = exp_rotation([0.3, -1.2, 0.7]);
        let q2 = exp_rotation([-2.0, 0.1, 0.4]);
        let d = [[1.0, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-10]];
        let a = mul(&mul(&q1, &d), &transpose(&q2));
        let s = svd(&a).sigma;
        assert!((s[1] / 1e-6 - 1.0).abs() < 1e-8, "{s:?}");
        assert!((s[2] / 1e-10 - 1.0).abs() < 1e-4, "{s:?}");
    }

    #[test]
    fn polar_gives_rotation_and_symmetric_factor() {
        let mut rng = Rng(3);
        for k in 0..300 {
            let mut t = rng.mat();
            if k % 3 == 0 {
                t = [
                    add(t[0], [2.0, 0.0, 0.0]),
                    add(t[1], [0.0, 2.0, 0.0]),
                    add(t[2], [0.0, 0.0, 2.0]),
                ];
            }
            let (r, s) = polar(&t);
            assert!(is_rotation(&r, 1e-12));
            assert!(max_diff(&s, &transpose(&s)) < 1e-14);
            assert!(max_diff(&mul(&r, &s), &t) < 1e-12);
            if det(&t) > 0.0 {
                // Positive definite stretch: the usual polar factor, unique.
                let Svd { sigma, .. } = svd(&s);
                assert!(sigma.iter().all(|&x| x >= 0.0));
                assert!(dot(mul_vec(&s, [1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]) > 0.0);
            }
        }
        // Singular and reflected inputs still factor exactly.
        for t in [
            [[0.0; 3]; 3],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]],
        ] {
            let (r, s) = polar(&t);
            assert!(is_rotation(&r, 1e-12));
            assert!(max_diff(&mul(&r, &s), &t) < 1e-14);
        }
    }

    #[test]
    fn newton_and_svd_polar_factors_agree() {
        let mut rng = Rng(17);
        let mut used_newton = 0;
        for _ in 0..300 {
            let mut t = rng.mat();
            for (k, row) in t.iter_mut().enumerate() {
                row[k] += 1.5;
            }
            let (r1, s1) = svd_polar(&t);
            if let Some((r2, s2)) = newton_polar(&t) {
                used_newton += 1;
                assert!(max_diff(&r1, &r2) < 1e-12 && max_diff(&s1, &s2) < 1e-12);
            }
        }
        assert!(used_newton > 250);
    }

    #[test]
    fn exp_matches_a_series_and_log_inverts_it() {
        let mut rng = Rng(5);
        for _ in 0..200 {
            let w = scale(rng.vec(), 1.7);
            // Reference: the matrix exponential's power series.
            let k = skew(w);
            let mut term = IDENTITY;
            let mut sum = IDENTITY;
            for n in 1..40 {
                term = mul(&term, &k);
                term.iter_mut().flatten().for_each(|x| *x /= n as f64);
                sum.iter_mut()
                    .flatten()
                    .zip(term.iter().flatten())
                    .for_each(|(s, t)| *s += t);
            }
            let r = exp_rotation(w);
            assert!(max_diff(&r, &sum) < 1e-13);
            assert!(is_rotation(&r, 1e-13));
            if norm(w) < std::f64::consts::PI {
                let back = log_rotation(&r);
                assert!(norm(sub(back, w)) < 1e-12, "{w:?} {back:?}");
            }
        }
    }

    #[test]
    fn log_is_accurate_near_zero_and_near_pi() {
        let pi = std::f64::consts::PI;
        let axis = scale([1.0, -2.0, 0.5], 1.0 / norm([1.0, -2.0, 0.5]));
        for theta in [
            0.0,
            1e-12,
            1e-7,
            1e-3,
            1.0,
            pi / 2.0,
            3.0,
            pi - 1e-6,
            pi - 1e-10,
        ] {
            let w = scale(axis, theta);
            let back = log_rotation(&exp_rotation(w));
            assert!(norm(sub(back, w)) < 1e-9, "θ = {theta}: {back:?}");
        }
        // Exactly π: either axis sign is right; the angle must be π.
        let back = log_rotation(&exp_rotation(scale(axis, pi)));
        assert!((norm(back) - pi).abs() < 1e-12);
        assert!(dot(back, axis).abs() > pi - 1e-9);
        // Angles past π come back as the principal representative (2π − θ about −a).
        let back = log_rotation(&exp_rotation(scale(axis, 4.0)));
        assert!(norm(sub(back, scale(axis, 4.0 - 2.0 * pi))) < 1e-12);
    }
}
