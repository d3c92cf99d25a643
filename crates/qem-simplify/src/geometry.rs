//! Small f64 vector helpers and the point–triangle distance.

/// A point or vector in f64.
pub(crate) type Vec3 = [f64; 3];

pub(crate) fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn distance(a: Vec3, b: Vec3) -> f64 {
    norm(sub(a, b))
}

/// Twice the area vector of triangle (a, b, c): its direction is the face normal.
pub(crate) fn area_vector(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    cross(sub(b, a), sub(c, a))
}

/// Shape quality 4√3·area / (sum of squared edge lengths): 1 for an equilateral triangle, 0 for a
/// degenerate one. Scale-invariant, so one threshold fits every mesh.
#[cfg(test)]
pub(crate) fn triangle_quality(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    quality_with_normal(a, b, c, area_vector(a, b, c))
}

/// [`triangle_quality`] given `n` = `area_vector(a, b, c)`.
pub(crate) fn quality_with_normal(a: Vec3, b: Vec3, c: Vec3, n: Vec3) -> f64 {
    let squares = dot(sub(b, a), sub(b, a)) + dot(sub(c, b), sub(c, b)) + dot(sub(a, c), sub(a, c));
    if squares <= 0.0 {
        return 0.0;
    }
    // 4√3 · (|n| / 2) = 2√3 · |n|.
    2.0 * 3f64.sqrt() * norm(n) / squares
}

pub(crate) fn to_f64(p: [f32; 3]) -> Vec3 {
    p.map(f64::from)
}

/// The closest point of triangle (a, b, c) to `p`, by the Voronoi regions of the corners and
/// sides; a degenerate triangle (segment, point) gives the nearest point of its three sides.
pub(crate) fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return add(a, scale(ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return add(a, scale(ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let bc = sub(c, b);
        return add(b, scale(bc, (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = va + vb + vc;
    if denom.abs() <= f64::MIN_POSITIVE {
        // Degenerate triangle not caught above (all three regions empty): nearest of the edges.
        return [
            closest_on_segment(p, a, b),
            closest_on_segment(p, b, c),
            closest_on_segment(p, c, a),
        ]
        .into_iter()
        .min_by(|x, y| dot(sub(p, *x), sub(p, *x)).total_cmp(&dot(sub(p, *y), sub(p, *y))))
        .unwrap_or(a);
    }
    let v = vb / denom;
    let w = vc / denom;
    add(a, add(scale(ab, v), scale(ac, w)))
}

fn closest_on_segment(p: Vec3, a: Vec3, b: Vec3) -> Vec3 {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    if len2 <= 0.0 {
        return a;
    }
    let t = (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0);
    add(a, scale(ab, t))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference: the minimum over a dense barycentric sampling of the triangle.
    fn sampled_distance_squared(p: Vec3, a: Vec3, b: Vec3, c: Vec3, n: usize) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                let q = add(a, add(scale(sub(b, a), u), scale(sub(c, a), v)));
                best = best.min(dot(sub(p, q), sub(p, q)));
            }
        }
        best
    }

    fn point_triangle_distance_squared(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f64 {
        let d = sub(p, closest_point_on_triangle(p, a, b, c));
        dot(d, d)
    }

    #[test]
    fn point_triangle_distance_matches_dense_sampling() {
        // A deterministic spread of points around a few triangles, every Voronoi region hit.
        let triangles = [
            ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            ([0.2, -0.3, 0.1], [1.1, 0.4, -0.2], [-0.5, 0.9, 0.7]),
            ([0.0, 0.0, 0.0], [3.0, 0.1, 0.0], [1.5, 0.05, 0.02]),
        ];
        let n = 300;
        for (a, b, c) in triangles {
            for k in 0..60 {
                let t = k as f64;
                let p = [
                    1.7 * (0.37 * t).sin(),
                    1.5 * (0.61 * t + 1.0).cos(),
                    (0.23 * t).sin() * 0.8,
                ];
                let exact = point_triangle_distance_squared(p, a, b, c).sqrt();
                let sampled = sampled_distance_squared(p, a, b, c, n).sqrt();
                // Sampling can only over-estimate, by at most the sample spacing.
                assert!(exact <= sampled + 1e-12, "{exact} > {sampled} at {p:?}");
                assert!(sampled - exact < 0.02, "{exact} vs {sampled} at {p:?}");
            }
        }
    }

    #[test]
    fn degenerate_triangles_reduce_to_segments_and_points() {
        let (a, b) = ([0.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        let d = point_triangle_distance_squared([1.0, 1.0, 0.0], a, b, [1.0, 0.0, 0.0]);
        assert!((d - 1.0).abs() < 1e-12);
        let d = point_triangle_distance_squared([3.0, 4.0, 0.0], a, a, a);
        assert!((d - 25.0).abs() < 1e-12);
    }

    #[test]
    fn quality_is_one_for_equilateral_and_zero_for_collinear() {
        let q = triangle_quality([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.75f64.sqrt(), 0.0]);
        assert!((q - 1.0).abs() < 1e-12);
        assert_eq!(
            triangle_quality([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]),
            0.0
        );
    }
}
