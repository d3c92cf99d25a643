//! Small synthetic meshes for tests (shared by unit and integration tests).
#![allow(dead_code)]

use mesh_io::{Face, Point};

/// An `nx × ny` vertex grid over [0, 1]², z = `bend`·((x − ½)² + (y − ½)²), alternating
/// diagonals. Has a boundary.
pub fn flat_grid(nx: usize, ny: usize, bend: f32) -> (Vec<Point>, Vec<Face>) {
    let mut positions = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let x = i as f32 / (nx - 1) as f32;
            let y = j as f32 / (ny - 1) as f32;
            // Jitter interior points a little so that not every ring is the same.
            let jitter = if i > 0 && j > 0 && i + 1 < nx && j + 1 < ny {
                0.07 * (((i * 7 + j * 13) % 5) as f32 - 2.0) / (nx as f32)
            } else {
                0.0
            };
            let (x, y) = (x + jitter, y - 0.5 * jitter);
            positions.push([x, y, bend * ((x - 0.5).powi(2) + (y - 0.5).powi(2))]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let v = |a: usize, b: usize| (b * nx + a) as u32;
            if (i + j) % 2 == 0 {
                faces.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                faces.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            } else {
                faces.push([v(i, j), v(i + 1, j), v(i, j + 1)]);
                faces.push([v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
    }
    (positions, faces)
}

/// A closed UV sphere of radius 1 with `rings` latitude rings and `segments` longitudes.
pub fn sphere(rings: usize, segments: usize) -> (Vec<Point>, Vec<Face>) {
    let mut positions = vec![[0.0, 0.0, 1.0]];
    for r in 1..=rings {
        let theta = std::f32::consts::PI * r as f32 / (rings + 1) as f32;
        for s in 0..segments {
            let phi =
                2.0 * std::f32::consts::PI * (s as f32 + 0.5 * (r % 2) as f32) / segments as f32;
            positions.push([
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ]);
        }
    }
    positions.push([0.0, 0.0, -1.0]);
    let south = (positions.len() - 1) as u32;
    let v = |r: usize, s: usize| (1 + (r - 1) * segments + s % segments) as u32;
    let mut faces = Vec::new();
    for s in 0..segments {
        faces.push([0, v(1, s), v(1, s + 1)]);
        faces.push([south, v(rings, s + 1), v(rings, s)]);
    }
    for r in 1..rings {
        for s in 0..segments {
            if r % 2 == 0 {
                // The lower ring is offset by half a step.
                faces.push([v(r, s), v(r + 1, s), v(r, s + 1)]);
                faces.push([v(r, s + 1), v(r + 1, s), v(r + 1, s + 1)]);
            } else {
                faces.push([v(r, s), v(r + 1, s), v(r + 1, s + 1)]);
                faces.push([v(r, s), v(r + 1, s + 1), v(r, s + 1)]);
            }
        }
    }
    (positions, faces)
}

/// An open tube (cylinder) around the z axis: `around` vertices per ring, `along` rings from
/// z = 0 to z = `length`. Neighbouring rings are offset by half a step, so the triangles are
/// nearly isosceles.
pub fn tube(around: usize, along: usize, radius: f32, length: f32) -> (Vec<Point>, Vec<Face>) {
    let mut positions = Vec::with_capacity(around * along);
    for k in 0..along {
        let z = length * k as f32 / (along - 1) as f32;
        for s in 0..around {
            let phi =
                2.0 * std::f32::consts::PI * (s as f32 + 0.5 * (k % 2) as f32) / around as f32;
            positions.push([radius * phi.cos(), radius * phi.sin(), z]);
        }
    }
    let v = |k: usize, s: usize| (k * around + s % around) as u32;
    let mut faces = Vec::new();
    for k in 0..along - 1 {
        for s in 0..around {
            if k % 2 == 0 {
                faces.push([v(k, s), v(k, s + 1), v(k + 1, s)]);
                faces.push([v(k, s + 1), v(k + 1, s + 1), v(k + 1, s)]);
            } else {
                faces.push([v(k, s), v(k + 1, s + 1), v(k + 1, s)]);
                faces.push([v(k, s), v(k, s + 1), v(k + 1, s + 1)]);
            }
        }
    }
    (positions, faces)
}

/// Each point rotated about the z axis by `total`·z/`length` (a twist along z).
pub fn twist(points: &[Point], total: f64, length: f64) -> Vec<Point> {
    points
        .iter()
        .map(|p| {
            let angle = total * p[2] as f64 / length;
            let (s, c) = angle.sin_cos();
            let (x, y) = (p[0] as f64, p[1] as f64);
            [(c * x - s * y) as f32, (s * x + c * y) as f32, p[2]]
        })
        .collect()
}
