//! The software rasterizer: orthographic z-buffer rendering of a triangle mesh with Lambert
//! shading, 2× supersampled.
//!
//! Deferred: the first pass (parallel over horizontal bands of the supersampled image, each with
//! the faces binned to it) keeps, per sample, the nearest face and its barycentric coordinates;
//! the second pass (parallel over output rows) shades each sample once and box-filters 2×2
//! samples into a pixel.

use crate::camera::{Bounds, Projection, View};
use crate::error::RenderError;
use crate::image::Image;
use rayon::prelude::*;

/// How to render: picture size, view, framing and background.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub view: View,
    /// The box to frame; `None` frames the mesh's own bounding box. Give several renders one
    /// frame (e.g. [`Bounds::of`] all their frames) to draw them at one scale.
    pub frame: Option<Bounds>,
    pub background: [u8; 3],
}

impl Default for RenderOptions {
    /// 512 × 512, the automatic view ([`View::resolve`]), the mesh's own box, white.
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            view: View::Auto,
            frame: None,
            background: [255; 3],
        }
    }
}

/// Colour of meshes rendered without per-vertex colours: a light, slightly cool grey.
pub const NEUTRAL_GREY: [u8; 3] = [196, 199, 204];
/// Samples per pixel along each axis.
pub const SUPERSAMPLING: u32 = 2;
/// Largest `width × height` of a render (the supersampled buffers take 64 bytes per pixel).
pub const MAX_RENDER_PIXELS: u64 = 1 << 23;

/// Rows of supersampled pixels per band of the first pass.
const BAND_ROWS: usize = 16;
/// Key light, in camera axes (right, up, toward the viewer): a headlight from slightly above left.
const LIGHT: [f32; 3] = [-0.30, 0.42, 0.86];
/// A weaker fill light from the lower right, so that silhouettes away from the key light do not
/// sink into flat ambient grey.
const FILL: [f32; 3] = [0.65, -0.39, 0.65];
/// Shading = albedo × (AMBIENT + DIFFUSE × max(0, n·l) + FILL_WEIGHT × max(0, n·f))
/// + SPECULAR × (n·h)^SHININESS.
const AMBIENT: f32 = 0.25;
const DIFFUSE: f32 = 0.65;
const FILL_WEIGHT: f32 = 0.2;
const SPECULAR: f32 = 0.12;
const SHININESS: i32 = 32;
/// Back faces (the inside of an open mesh) are drawn darker so that holes read as holes.
const BACK_FACE_ALBEDO: f32 = 0.72;
/// A vertex normal further than this (cosine, 45°) from the face normal is a crease: the corner
/// uses the face normal, so a cube stays flat-shaded while smooth surfaces are shaded smoothly.
const CREASE_COS: f32 = 0.7;

/// Shaded z-buffer rendering of a triangle mesh; `colors` per vertex (interpolated), or `None`
/// for [`NEUTRAL_GREY`].
///
/// Orthographic camera from `options.view` ([`View::Auto`] resolved against the framed box),
/// framing `options.frame` (or the mesh's bounding box) with a [`crate::MARGIN`] on the limiting
/// axis, aspect kept. Both sides of every face are shaded (open meshes show their inside,
/// darker). Errors: empty positions or faces, a non-finite
/// coordinate, a face index out of range, colours of the wrong length, a zero or too large size,
/// a bad frame.
pub fn render(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    colors: Option<&[[u8; 3]]>,
    options: &RenderOptions,
) -> Result<Image, RenderError> {
    validate(positions, faces, colors, options)?;
    let bounds = match options.frame {
        Some(b) => b,
        None => Bounds::of(&[positions]).ok_or(RenderError::Empty {
            argument: "positions",
        })?,
    };
    let (w, h) = (
        (options.width * SUPERSAMPLING) as usize,
        (options.height * SUPERSAMPLING) as usize,
    );
    let projection = Projection::new(options.view, &bounds, w as u32, h as u32);
    let screen: Vec<[f32; 3]> = positions
        .par_iter()
        .map(|&p| projection.project(p))
        .collect();
    let geometry = Geometry::new(positions, faces, &screen, &projection);
    let samples = rasterize(faces, &screen, w, h);
    let shader = Shader {
        faces,
        geometry: &geometry,
        colors,
        background: options.background,
    };
    let mut rgb = vec![0u8; 3 * options.width as usize * options.height as usize];
    let s = SUPERSAMPLING as usize;
    rgb.par_chunks_mut(3 * options.width as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.chunks_exact_mut(3).enumerate() {
                let mut sum = [0f32; 3];
                for sy in 0..s {
                    for sx in 0..s {
                        let c = shader.shade(&samples[(y * s + sy) * w + x * s + sx]);
                        (0..3).for_each(|k| sum[k] += c[k]);
                    }
                }
                let n = (s * s) as f32;
                for k in 0..3 {
                    px[k] = (sum[k] / n).round().clamp(0.0, 255.0) as u8;
                }
            }
        });
    Ok(Image {
        width: options.width,
        height: options.height,
        rgb,
    })
}

fn validate(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    colors: Option<&[[u8; 3]]>,
    options: &RenderOptions,
) -> Result<(), RenderError> {
    crate::image::check_size("options.width/height", options.width, options.height)?;
    if u64::from(options.width) * u64::from(options.height) > MAX_RENDER_PIXELS {
        return Err(RenderError::Size {
            argument: "options.width/height",
            width: options.width.into(),
            height: options.height.into(),
            message: format!("renders are limited to {MAX_RENDER_PIXELS} pixels"),
        });
    }
    if positions.is_empty() {
        return Err(RenderError::Empty {
            argument: "positions",
        });
    }
    if faces.is_empty() {
        return Err(RenderError::Empty { argument: "faces" });
    }
    for (index, p) in positions.iter().enumerate() {
        if let Some(&value) = p.iter().find(|c| !c.is_finite()) {
            return Err(RenderError::NonFinite {
                argument: "positions",
                index,
                value,
            });
        }
    }
    let n = positions.len();
    for (face, f) in faces.iter().enumerate() {
        if let Some(&index) = f.iter().find(|&&i| i as usize >= n) {
            return Err(RenderError::FaceIndex {
                face,
                index,
                vertices: n,
            });
        }
    }
    if let Some(c) = colors
        && c.len() != n
    {
        return Err(RenderError::Length {
            argument: "colors",
            expected: n,
            found: c.len(),
        });
    }
    if let Some(frame) = &options.frame {
        frame.validate("options.frame")?;
    }
    Ok(())
}

/// What the first pass keeps per sample: the nearest face so far, its depth and the barycentric
/// weights of the face's 2nd and 3rd vertices (in the face's own order).
#[derive(Debug, Clone, Copy)]
struct Sample {
    depth: f32,
    face: u32,
    b1: f32,
    b2: f32,
}

const NO_FACE: u32 = u32::MAX;

/// First pass: the nearest face at every sample centre of a `w × h` grid.
fn rasterize(faces: &[[u32; 3]], screen: &[[f32; 3]], w: usize, h: usize) -> Vec<Sample> {
    let bands = h.div_ceil(BAND_ROWS);
    // Bin faces by the bands their rows touch; faces off screen or without area are dropped.
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (fi, f) in faces.iter().enumerate() {
        let [a, b, c] = f.map(|i| screen[i as usize]);
        let area = edge(a, b, c);
        if area == 0.0 || !area.is_finite() {
            continue;
        }
        let (y_lo, y_hi) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
        let (x_lo, x_hi) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
        if y_hi < 0.0 || x_hi < 0.0 || y_lo > h as f32 || x_lo > w as f32 {
            continue;
        }
        let first = (first_sample(y_lo) / BAND_ROWS).min(bands - 1);
        let last = (last_sample(y_hi, h) / BAND_ROWS).min(bands - 1);
        for bin in &mut bins[first..=last] {
            bin.push(fi as u32);
        }
    }
    let empty = Sample {
        depth: f32::NEG_INFINITY,
        face: NO_FACE,
        b1: 0.0,
        b2: 0.0,
    };
    let mut samples = vec![empty; w * h];
    samples
        .par_chunks_mut(BAND_ROWS * w)
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(band, (buf, bin))| {
            let y0 = band * BAND_ROWS;
            let rows = buf.len() / w;
            for &fi in bin {
                draw_face(buf, w, y0, rows, fi, faces[fi as usize], screen);
            }
        });
    samples
}

/// Signed doubled area of `(a, b, p)` in pixel coordinates.
fn edge(a: [f32; 3], b: [f32; 3], p: [f32; 3]) -> f32 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Index of the first sample whose centre (`i + 0.5`) is at or after `lo`.
fn first_sample(lo: f32) -> usize {
    (lo - 0.5).ceil().max(0.0) as usize
}

/// Index of the last sample (below `n`) whose centre is at or before `hi`.
fn last_sample(hi: f32, n: usize) -> usize {
    ((hi - 0.5).floor().max(0.0) as usize).min(n - 1)
}

/// Tie rule for samples exactly on an edge: of the two faces sharing an edge (which run it in
/// opposite directions once both are oriented positively), exactly one owns it.
fn owns_edge(a: [f32; 3], b: [f32; 3]) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    dy > 0.0 || (dy == 0.0 && dx < 0.0)
}

fn draw_face(
    buf: &mut [Sample],
    w: usize,
    y0: usize,
    rows: usize,
    fi: u32,
    face: [u32; 3],
    screen: &[[f32; 3]],
) {
    let [p0, p1, p2] = face.map(|i| screen[i as usize]);
    // Orient positively; `swapped` maps the weights back to the face's own vertex order.
    let swapped = edge(p0, p1, p2) < 0.0;
    let (q1, q2) = if swapped { (p2, p1) } else { (p1, p2) };
    let area = edge(p0, q1, q2);
    let x_lo = first_sample(p0[0].min(q1[0]).min(q2[0]));
    let x_hi = last_sample(p0[0].max(q1[0]).max(q2[0]), w);
    let y_lo = first_sample(p0[1].min(q1[1]).min(q2[1])).max(y0);
    let y_hi = last_sample(p0[1].max(q1[1]).max(q2[1]), y0 + rows).min(y0 + rows - 1);
    if x_lo > x_hi || y_lo > y_hi {
        return;
    }
    let own = [owns_edge(q1, q2), owns_edge(q2, p0), owns_edge(p0, q1)];
    let inv_area = 1.0 / area;
    for y in y_lo..=y_hi {
        let row = &mut buf[(y - y0) * w..][..w];
        let py = y as f32 + 0.5;
        for (x, sample) in row.iter_mut().enumerate().take(x_hi + 1).skip(x_lo) {
            let p = [x as f32 + 0.5, py, 0.0];
            let e = [edge(q1, q2, p), edge(q2, p0, p), edge(p0, q1, p)];
            let inside = (0..3).all(|k| e[k] > 0.0 || (e[k] == 0.0 && own[k]));
            if !inside {
                continue;
            }
            let (w1, w2) = (e[1] * inv_area, e[2] * inv_area);
            let depth = p0[2] + w1 * (q1[2] - p0[2]) + w2 * (q2[2] - p0[2]);
            if depth > sample.depth {
                let (b1, b2) = if swapped { (w2, w1) } else { (w1, w2) };
                *sample = Sample {
                    depth,
                    face: fi,
                    b1,
                    b2,
                };
            }
        }
    }
}

/// Normals in camera axes: per vertex (weighted by the corner angles, so that the triangulation
/// of a flat region does not tilt them; unit) and per face (unit), plus which faces turn their
/// front to the camera.
struct Geometry {
    vertex_normals: Vec<[f32; 3]>,
    face_normals: Vec<[f32; 3]>,
    front: Vec<bool>,
}

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        v.map(|c| c / len)
    } else {
        [0.0; 3]
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Geometry {
    fn new(
        positions: &[[f32; 3]],
        faces: &[[u32; 3]],
        screen: &[[f32; 3]],
        projection: &Projection,
    ) -> Geometry {
        let raw: Vec<[f32; 3]> = faces
            .par_iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| positions[i as usize]);
                let (u, v) = (sub(b, a), sub(c, a));
                projection.rotate([
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ])
            })
            .collect();
        let face_normals: Vec<[f32; 3]> = raw.into_par_iter().map(normalize).collect();
        let angles: Vec<[f32; 3]> = faces
            .par_iter()
            .map(|f| {
                let p = f.map(|i| positions[i as usize]);
                std::array::from_fn(|c| {
                    let u = normalize(sub(p[(c + 1) % 3], p[c]));
                    let v = normalize(sub(p[(c + 2) % 3], p[c]));
                    dot(u, v).clamp(-1.0, 1.0).acos()
                })
            })
            .collect();
        let mut vertex_normals = vec![[0f32; 3]; positions.len()];
        for ((f, n), a) in faces.iter().zip(&face_normals).zip(&angles) {
            for (&i, &angle) in f.iter().zip(a) {
                let acc = &mut vertex_normals[i as usize];
                (0..3).for_each(|k| acc[k] += angle * n[k]);
            }
        }
        vertex_normals
            .par_iter_mut()
            .for_each(|n| *n = normalize(*n));
        // Front-facing = counter-clockwise as seen by the viewer = negative area with y down.
        let front = faces
            .par_iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| screen[i as usize]);
                edge(a, b, c) < 0.0
            })
            .collect();
        Geometry {
            vertex_normals,
            face_normals,
            front,
        }
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

struct Shader<'a> {
    faces: &'a [[u32; 3]],
    geometry: &'a Geometry,
    colors: Option<&'a [[u8; 3]]>,
    background: [u8; 3],
}

impl Shader<'_> {
    /// The colour of one sample (0..=255 per channel, unrounded).
    fn shade(&self, s: &Sample) -> [f32; 3] {
        if s.face == NO_FACE {
            return self.background.map(f32::from);
        }
        let fi = s.face as usize;
        let face = self.faces[fi];
        let weights = [1.0 - s.b1 - s.b2, s.b1, s.b2];
        let face_normal = self.geometry.face_normals[fi];
        let mut n = [0f32; 3];
        for (&v, &wt) in face.iter().zip(&weights) {
            let vn = self.geometry.vertex_normals[v as usize];
            let corner = if dot(vn, face_normal) >= CREASE_COS {
                vn
            } else {
                face_normal
            };
            (0..3).for_each(|k| n[k] += wt * corner[k]);
        }
        let mut n = normalize(n);
        let front = self.geometry.front[fi];
        if !front {
            n = n.map(|c| -c);
        }
        let albedo = match self.colors {
            Some(colors) => {
                let mut c = [0f32; 3];
                for (&v, &wt) in face.iter().zip(&weights) {
                    let vc = colors[v as usize];
                    (0..3).for_each(|k| c[k] += wt * f32::from(vc[k]));
                }
                c
            }
            None => NEUTRAL_GREY.map(f32::from),
        };
        let diffuse = dot(n, LIGHT).max(0.0);
        let half = normalize([LIGHT[0], LIGHT[1], LIGHT[2] + 1.0]);
        let specular = if front {
            SPECULAR * 255.0 * dot(n, half).max(0.0).powi(SHININESS)
        } else {
            0.0
        };
        let albedo_scale = if front { 1.0 } else { BACK_FACE_ALBEDO };
        let light = AMBIENT + DIFFUSE * diffuse + FILL_WEIGHT * dot(n, FILL).max(0.0);
        albedo.map(|c| (c * albedo_scale * light + specular).min(255.0))
    }
}
