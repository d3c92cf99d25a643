//! Spiral sequences (Gong et al. 2019, SpiralNet++): for every vertex, a fixed-length list of
//! vertices that starts at the vertex, goes once round its one-ring, then round the next rings,
//! ring after ring. A spiral convolution gathers the features along it and applies one dense
//! layer, so the order only has to be the same for every mesh of a set (it is: it depends on the
//! connectivity alone).
//!
//! The rings follow SpiralNet++'s construction: ring k + 1 lists, for each vertex of ring k in
//! order, its neighbours (in the orientation order round it) that are in no earlier ring. A
//! vertex's one-ring starts at its neighbour of smallest index (a boundary vertex's at the
//! neighbour where its fan begins) and runs counter-clockwise with the faces' orientation.
//! Where the mesh holds fewer vertices within reach than the length asks (a tiny component),
//! the spiral is instead the `length` vertices nearest to the centre in space, itself first, as
//! SpiralNet++ falls back to a k-d tree query. With `dilation` d, the spiral is the first
//! `length · d` vertices of the sequence, every d-th one.

use crate::HierarchyError;
use mesh_io::{Face, Point};

/// The spirals of every vertex of a mesh: `length` vertex indices per vertex, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Spirals {
    pub length: usize,
    pub indices: Vec<u32>,
}

impl Spirals {
    /// The spiral of vertex `v`.
    pub fn of(&self, v: usize) -> &[u32] {
        &self.indices[v * self.length..(v + 1) * self.length]
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.indices.len() / self.length.max(1)
    }
}

/// The spirals of length `length` (with `dilation`) of the mesh `positions`/`faces`.
///
/// Errors: a zero length or dilation, or a face with an index out of range.
pub fn spirals(
    positions: &[Point],
    faces: &[Face],
    length: usize,
    dilation: usize,
) -> Result<Spirals, HierarchyError> {
    if length == 0 || dilation == 0 {
        return Err(HierarchyError::InvalidArgument {
            argument: "spiral length",
            message: format!("length {length} and dilation {dilation} must be at least 1"),
        });
    }
    let n = positions.len();
    let rings = one_rings(n, faces)?;
    let want = length * dilation;
    let mut indices = Vec::with_capacity(n * length);
    let mut seen = vec![false; n];
    for v in 0..n {
        let mut sequence = vec![v as u32];
        seen[v] = true;
        let mut ring: Vec<u32> = Vec::new();
        for &u in &rings[v] {
            if !seen[u as usize] {
                seen[u as usize] = true;
                ring.push(u);
            }
        }
        while !ring.is_empty() && sequence.len() < want {
            sequence.extend_from_slice(&ring);
            let mut next = Vec::new();
            for &r in &ring {
                for &u in &rings[r as usize] {
                    if !seen[u as usize] {
                        seen[u as usize] = true;
                        next.push(u);
                    }
                }
            }
            ring = next;
        }
        for &u in sequence.iter().chain(&ring) {
            seen[u as usize] = false;
        }
        if sequence.len() < want {
            sequence = nearest(positions, v, want);
        }
        indices.extend(sequence.iter().take(want).step_by(dilation));
        // Fewer vertices in the whole mesh than the spiral's length: repeat the centre.
        while indices.len() < (v + 1) * length {
            indices.push(v as u32);
        }
    }
    Ok(Spirals { length, indices })
}

/// The `k` vertices nearest to `v` in space, `v` first (ties by index).
fn nearest(positions: &[Point], v: usize, k: usize) -> Vec<u32> {
    let p = positions[v];
    let d2 = |q: &Point| (0..3).map(|i| ((q[i] - p[i]) as f64).powi(2)).sum::<f64>();
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_by(|&a, &b| {
        let key = |i: u32| (i != v as u32, d2(&positions[i as usize]));
        let (ka, kb) = (key(a), key(b));
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1)).then(a.cmp(&b))
    });
    order.truncate(k);
    order
}

/// Each vertex's neighbours in the orientation order round it (see the module doc).
fn one_rings(n: usize, faces: &[Face]) -> Result<Vec<Vec<u32>>, HierarchyError> {
    // For vertex v, each face (v, a, b) in counter-clockwise order links a → b round v.
    let mut links: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
    for (f, face) in faces.iter().enumerate() {
        if face.iter().any(|&i| i as usize >= n) {
            return Err(HierarchyError::InvalidArgument {
                argument: "faces",
                message: format!("face {f} {face:?} has a vertex beyond {n}"),
            });
        }
        for k in 0..3 {
            let (v, a, b) = (face[k], face[(k + 1) % 3], face[(k + 2) % 3]);
            links[v as usize].push((a, b));
        }
    }
    Ok(links.into_iter().map(|l| ordered_ring(&l)).collect())
}

/// The fan's vertices in link order, from the fan's start on a boundary, else from the
/// smallest neighbour; a fan that is not one chain (a non-manifold vertex) ends with the
/// neighbours the walk missed, by index.
fn ordered_ring(links: &[(u32, u32)]) -> Vec<u32> {
    let mut neighbours: Vec<u32> = links.iter().flat_map(|&(a, b)| [a, b]).collect();
    neighbours.sort_unstable();
    neighbours.dedup();
    let Some(&smallest) = neighbours.first() else {
        return Vec::new();
    };
    let next = |a: u32| links.iter().find(|l| l.0 == a).map(|l| l.1);
    let start = links
        .iter()
        .map(|l| l.0)
        .find(|&a| !links.iter().any(|l| l.1 == a))
        .unwrap_or(smallest);
    let mut ring = vec![start];
    let mut at = start;
    while let Some(b) = next(at) {
        if ring.contains(&b) {
            break;
        }
        ring.push(b);
        at = b;
    }
    for u in neighbours {
        if !ring.contains(&u) {
            ring.push(u);
        }
    }
    ring
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A (w × h)-vertex grid of unit squares split into two triangles each, counter-clockwise
    /// seen from +z.
    fn grid(w: usize, h: usize) -> (Vec<Point>, Vec<Face>) {
        let id = |x: usize, y: usize| (y * w + x) as u32;
        let positions = (0..h)
            .flat_map(|y| (0..w).map(move |x| [x as f32, y as f32, 0.0]))
            .collect();
        let mut faces = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                faces.push([id(x, y), id(x + 1, y), id(x + 1, y + 1)]);
                faces.push([id(x, y), id(x + 1, y + 1), id(x, y + 1)]);
            }
        }
        (positions, faces)
    }

    #[test]
    fn a_spiral_is_the_vertex_its_ring_in_order_then_the_next_ring() {
        let (p, f) = grid(7, 7);
        let centre = 3 * 7 + 3;
        let s = spirals(&p, &f, 9, 1).unwrap();
        let spiral = s.of(centre);
        assert_eq!(spiral[0], centre as u32);
        // The one-ring of an interior grid vertex has 6 neighbours here (the diagonal split).
        let ring: Vec<u32> = spiral[1..7].to_vec();
        let mut sorted = ring.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, [16, 17, 23, 25, 31, 32]);
        assert_eq!(ring[0], 16, "starts at the smallest neighbour");
        // Consecutive ring vertices are neighbours: it goes round, counter-clockwise.
        let pos = |i: u32| p[i as usize];
        for w in ring.windows(2) {
            let (a, b) = (pos(w[0]), pos(w[1]));
            let d = (a[0] - b[0]).abs().max((a[1] - b[1]).abs());
            assert_eq!(d, 1.0, "{w:?}");
        }
        let c = pos(centre as u32);
        let angle = |i: u32| (pos(i)[1] - c[1]).atan2(pos(i)[0] - c[0]);
        let turn = |a: u32, b: u32| {
            let d = angle(b) - angle(a);
            d.sin() > 0.0
        };
        assert!(ring.windows(2).all(|w| turn(w[0], w[1])), "{ring:?}");
        // The last two entries begin ring 2, which is at grid distance 2.
        for &u in &spiral[7..] {
            let q = pos(u);
            let d = (q[0] - c[0]).abs().max((q[1] - c[1]).abs());
            assert_eq!(d, 2.0);
        }
        // Every spiral has distinct vertices and the requested length.
        for v in 0..p.len() {
            let mut sp = s.of(v).to_vec();
            assert_eq!(sp[0], v as u32);
            sp.sort_unstable();
            sp.dedup();
            assert_eq!(sp.len(), 9, "vertex {v}");
        }
    }

    #[test]
    fn dilation_takes_every_other_vertex_and_tiny_meshes_fall_back_to_the_nearest() {
        let (p, f) = grid(7, 7);
        let plain = spirals(&p, &f, 18, 1).unwrap();
        let dilated = spirals(&p, &f, 9, 2).unwrap();
        for v in 0..p.len() {
            let every_other: Vec<u32> = plain.of(v).iter().copied().step_by(2).collect();
            assert_eq!(dilated.of(v), every_other.as_slice());
        }
        // One triangle: three vertices within reach, a spiral of 5 takes the nearest and then
        // repeats the centre.
        let tri = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let s = spirals(&tri, &[[0, 1, 2]], 5, 1).unwrap();
        assert_eq!(s.of(2), &[2, 0, 1, 2, 2]);
        assert!(spirals(&tri, &[[0, 1, 3]], 5, 1).is_err());
        assert!(spirals(&tri, &[[0, 1, 2]], 0, 1).is_err());
    }
}
