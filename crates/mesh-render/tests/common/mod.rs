//! Helpers shared by the tests: simple meshes and pixel statistics.
#![allow(dead_code)]

use mesh_render::Image;

pub const WHITE: [u8; 3] = [255; 3];

/// An axis-aligned box from `lo` to `hi`: 8 vertices, 12 outward-facing triangles.
pub fn cuboid(lo: [f32; 3], hi: [f32; 3]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let positions = (0..8)
        .map(|i| std::array::from_fn(|k| if i >> k & 1 == 0 { lo[k] } else { hi[k] }))
        .collect();
    // Vertex i has x = bit 0, y = bit 1, z = bit 2.
    let quads: [[u32; 4]; 6] = [
        [0, 4, 6, 2], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [2, 6, 7, 3], // +y
        [0, 2, 3, 1], // -z
        [4, 5, 7, 6], // +z
    ];
    let faces = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    (positions, faces)
}

/// A small tetrahedron centred at `c`.
pub fn tetrahedron(c: [f32; 3], r: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let corners = [[1., 1., 1.], [1., -1., -1.], [-1., 1., -1.], [-1., -1., 1.]];
    let positions = corners
        .iter()
        .map(|d: &[f32; 3]| std::array::from_fn(|k| c[k] + r * d[k]))
        .collect();
    (positions, vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
}

/// Appends a mesh to another, offsetting its indices.
pub fn append(
    (p, f): &mut (Vec<[f32; 3]>, Vec<[u32; 3]>),
    (p2, f2): (Vec<[f32; 3]>, Vec<[u32; 3]>),
) {
    let base = p.len() as u32;
    p.extend(p2);
    f.extend(f2.into_iter().map(|t| t.map(|i| i + base)));
}

pub fn luminance(c: [u8; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Covered area in pixels of a shape of uniform colour `fill` on background `bg`: each pixel
/// counts by how far it is from the background towards `fill` (so anti-aliased edge pixels
/// count fractionally).
pub fn coverage(image: &Image, fill: [u8; 3], bg: [u8; 3]) -> f64 {
    let span = luminance(bg) - luminance(fill);
    assert!(span.abs() > 20.0, "fill {fill:?} too close to background");
    image
        .rgb
        .chunks_exact(3)
        .map(|p| ((luminance(bg) - luminance([p[0], p[1], p[2]])) / span).clamp(0.0, 1.0))
        .sum()
}

/// Bounding box `(x0, y0, x1, y1)` (inclusive) of the pixels for which `pred` holds.
pub fn bbox_of(image: &Image, pred: impl Fn([u8; 3]) -> bool) -> Option<(u32, u32, u32, u32)> {
    let mut b: Option<(u32, u32, u32, u32)> = None;
    for y in 0..image.height {
        for x in 0..image.width {
            if pred(image.pixel(x, y).unwrap()) {
                b = Some(match b {
                    None => (x, y, x, y),
                    Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
                });
            }
        }
    }
    b
}

/// Mean position of the pixels for which `pred` holds, and their count.
pub fn centroid(image: &Image, pred: impl Fn([u8; 3]) -> bool) -> Option<([f64; 2], usize)> {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for y in 0..image.height {
        for x in 0..image.width {
            if pred(image.pixel(x, y).unwrap()) {
                sx += x as f64;
                sy += y as f64;
                n += 1;
            }
        }
    }
    (n > 0).then(|| ([sx / n as f64, sy / n as f64], n))
}

/// Pixels for which `pred` holds inside the rectangle `[x0, x1) × [y0, y1)`.
pub fn count_in(
    image: &Image,
    (x0, y0, x1, y1): (u32, u32, u32, u32),
    pred: impl Fn([u8; 3]) -> bool,
) -> usize {
    (y0..y1.min(image.height))
        .flat_map(|y| (x0..x1.min(image.width)).map(move |x| (x, y)))
        .filter(|&(x, y)| pred(image.pixel(x, y).unwrap()))
        .count()
}

pub fn is_dark(c: [u8; 3]) -> bool {
    c.iter().all(|&v| v < 110)
}
