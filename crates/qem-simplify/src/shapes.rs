//! Small meshes generated in code, with known topology, for tests, examples and benches.

use mesh_io::{Face, Point, TriMesh};
use std::collections::HashMap;

/// The unit icosphere: an icosahedron subdivided `levels` times (10·4^levels + 2 vertices,
/// genus 0, closed), vertices on the sphere.
pub fn icosphere(levels: u32) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut positions: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut faces: Vec<Face> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, positions: &mut Vec<[f64; 3]>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let (p, q) = (positions[a as usize], positions[b as usize]);
                positions.push([0, 1, 2].map(|k| 0.5 * (p[k] + q[k])));
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let positions = positions
        .into_iter()
        .map(|p| {
            let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            p.map(|x| (x / n) as f32)
        })
        .collect();
    TriMesh { positions, faces }
}

/// A torus (genus 1, Euler characteristic 0) with `major` × `minor` vertices, radii `big` and
/// `small`.
pub fn torus(major: u32, minor: u32, big: f32, small: f32) -> TriMesh {
    let mut positions: Vec<Point> = Vec::new();
    for i in 0..major {
        let u = i as f32 / major as f32 * std::f32::consts::TAU;
        for j in 0..minor {
            let v = j as f32 / minor as f32 * std::f32::consts::TAU;
            let r = big + small * v.cos();
            positions.push([r * u.cos(), r * u.sin(), small * v.sin()]);
        }
    }
    let id = |i: u32, j: u32| (i % major) * minor + (j % minor);
    let mut faces = Vec::new();
    for i in 0..major {
        for j in 0..minor {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    TriMesh { positions, faces }
}

/// A height field z = 0.15·sin(2x)·cos(3y) on the unit square, `nx` × `ny` vertices: an open
/// disc (one boundary loop, Euler characteristic 1). Diagonals alternate, so the grid has
/// vertices of valence 4 and 8.
pub fn bumpy_grid(nx: u32, ny: u32) -> TriMesh {
    let mut positions: Vec<Point> = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let x = i as f32 / (nx - 1).max(1) as f32;
            let y = j as f32 / (ny - 1).max(1) as f32;
            positions.push([x, y, 0.15 * (2.0 * x).sin() * (3.0 * y).cos()]);
        }
    }
    let id = |i: u32, j: u32| j * nx + i;
    let mut faces = Vec::new();
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    TriMesh { positions, faces }
}
