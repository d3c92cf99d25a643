//! Synthetic mesh sets with known parameters: a capsule that bends and twists.
//!
//! The project's built-in data (for `meshvae synth`, `meshvae demo` and the fast tests of every
//! later stage): frames of one closed, genus-0 tube that share one connectivity and differ by a
//! deformation whose parameters are known exactly.
//!
//! - **Rest shape** ([`rest_capsule`]): a capsule along z — a cylinder of `length` plus two
//!   (scaled) hemispherical caps closed by one pole vertex each, outward-oriented triangles. Its
//!   cross-section is `ρ(α) = 1 + 0.15 cos 2α + 0.06 cos 3α` times a radius that tapers from
//!   `1.1 × radius` at the bottom to `0.9 × radius` at the top, so the shape has no rotational
//!   symmetry about its axis (a twist is visible whatever its angle) and no top/bottom symmetry.
//!   The cross-section's ring centroids stay on the axis, which makes the axis measurable.
//! - **Twist** (angle θ): each slice turns about the axis by an angle that grows linearly along
//!   the cylinder, from −θ/2 at its bottom end to +θ/2 at its top end; the caps turn rigidly with
//!   the ends, so the top cap is rotated by exactly θ relative to the bottom cap, for any θ
//!   (beyond ±π included; the default range is ±3π).
//! - **Bend** (angle β, azimuth φ): the whole axis, pole to pole, is mapped onto a circular arc of
//!   the same length turning by β, in the plane spanned by z and `(cos φ, sin φ, 0)`; slices
//!   stay perpendicular to the arc. The arc is centred on the axis' midpoint.
//!
//! [`deform`] applies the twist first and then the bend, so a [`ShapeParams`] with both set gives
//! a combined shape; [`generate`] uses one kind per frame, which is the frame's label.
//!
//! ```
//! use mesh_io::synth::{self, ShapeKind, ShapeParams, SynthConfig};
//! # fn main() -> Result<(), mesh_io::MeshIoError> {
//! let config = SynthConfig { meshes_per_label: 4, ..SynthConfig::default() };
//! let data = synth::generate(&config)?;
//! assert_eq!(data.set.len(), 8); // frame 0 is the rest capsule, labelled "bend"
//! assert_eq!(data.set.labels().unwrap()[..2], ["bend", "twist"]);
//! assert_eq!(data.params[0].bend, 0.0);
//! let report = mesh_io::QualityReport::of(&data.set);
//! assert_eq!((report.boundary_edges, report.euler_characteristic), (0, 2));
//!
//! // Deform the rest capsule yourself: two and a half turns.
//! let rest = synth::rest_capsule(&config);
//! let twist = ShapeParams { twist: 5.0 * std::f32::consts::PI, ..ShapeParams::rest() };
//! let twisted = synth::deform(&rest, &twist, &config);
//! assert_eq!(twisted.faces, rest.faces);
//! # Ok(()) }
//! ```

use crate::error::{MeshIoError, Result};
use crate::mesh::{Face, MeshSet, Point, TriMesh};
use serde::Serialize;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Weight of `cos 2α` in the cross-section (an elliptic component).
const CROSS_COS2: f64 = 0.15;
/// Weight of `cos 3α`: with the `cos 2α` term, it leaves no rotational symmetry.
const CROSS_COS3: f64 = 0.06;
/// The radius is `radius × (1 + TAPER)` at the bottom end, `radius × (1 − TAPER)` at the top.
const TAPER: f64 = 0.1;
/// Largest `max_bend × (widest half-width) / axis length` accepted: beyond 1 the inner side of
/// the bend folds over itself; 0.9 keeps a margin.
const MAX_BEND_COMPRESSION: f64 = 0.9;
/// Guards against configurations that would exhaust memory instead of failing cleanly.
const MAX_VERTICES: usize = 1 << 24;
const MAX_TOTAL_POSITIONS: usize = 1 << 27;

/// What [`generate`] makes: sizes of the capsule, how many frames and how strong the deformations.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthConfig {
    /// Seed of the amplitudes and azimuths; the same seed gives a bit-identical set.
    pub seed: u64,
    /// Frames per label ("bend", "twist"); the set has twice as many (frame 0, the rest capsule,
    /// counts as a bend).
    pub meshes_per_label: usize,
    /// Vertex rings of the cylinder, both end rings included (at least 2).
    pub rings: usize,
    /// Vertices per ring (at least 3).
    pub segments: usize,
    /// Rings of each cap strictly between the cylinder's end ring and the pole (may be 0).
    pub cap_rings: usize,
    /// Length of the cylinder part; the axis, pole to pole, is `length + 2 × radius`.
    pub length: f32,
    /// Mean radius (the tube tapers from 1.1 × radius at the bottom to 0.9 × radius at the top).
    pub radius: f32,
    /// Largest bend, radians (total turn of the axis); bends are drawn in `[-max, max]`.
    pub max_bend: f32,
    /// Largest twist, radians (top cap relative to bottom cap); twists are drawn in `[-max, max]`.
    pub max_twist: f32,
}

impl Default for SynthConfig {
    /// 2,498 vertices (48 segments × (40 + 2 × 6) rings + 2 poles), 40 meshes per label, bends
    /// up to ±150°, twists up to ±3π.
    fn default() -> Self {
        Self {
            seed: 0x5eed,
            meshes_per_label: 40,
            rings: 40,
            segments: 48,
            cap_rings: 6,
            length: 4.0,
            radius: 0.5,
            max_bend: 150f32.to_radians(),
            max_twist: 3.0 * std::f32::consts::PI,
        }
    }
}

impl SynthConfig {
    /// Vertices of the capsule: `2 + segments × (rings + 2 × cap_rings)` (saturating).
    pub fn vertex_count(&self) -> usize {
        self.cap_rings
            .saturating_mul(2)
            .saturating_add(self.rings)
            .saturating_mul(self.segments)
            .saturating_add(2)
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad = |argument: &'static str, message: String| {
            Err(MeshIoError::InvalidArgument { argument, message })
        };
        if self.meshes_per_label == 0 {
            return bad("meshes_per_label", "must be at least 1".into());
        }
        if self.rings < 2 {
            return bad(
                "rings",
                format!(
                    "{} rings; the cylinder needs at least 2 (its two ends)",
                    self.rings
                ),
            );
        }
        if self.segments < 3 {
            return bad(
                "segments",
                format!("{} segments; a ring needs at least 3", self.segments),
            );
        }
        for (argument, value) in [("length", self.length), ("radius", self.radius)] {
            if !(value.is_finite() && value > 0.0) {
                return bad(argument, format!("{value}; must be finite and positive"));
            }
        }
        for (argument, value) in [("max_bend", self.max_bend), ("max_twist", self.max_twist)] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(
                    argument,
                    format!("{value}; must be finite and non-negative"),
                );
            }
        }
        let dims = Dims::of(self);
        let compression = self.max_bend as f64 * dims.max_half_width() / dims.axis_length();
        if compression > MAX_BEND_COMPRESSION {
            return bad(
                "max_bend",
                format!(
                    "{} rad would fold the inner side of the tube (bend × half-width / axis \
                     length = {compression:.3}, limit {MAX_BEND_COMPRESSION})",
                    self.max_bend
                ),
            );
        }
        let vertices = self.vertex_count();
        if vertices > MAX_VERTICES {
            let largest = [
                ("rings", self.rings),
                ("cap_rings", self.cap_rings.saturating_mul(2)),
                ("segments", self.segments),
            ]
            .into_iter()
            .max_by_key(|&(_, n)| n)
            .map_or("segments", |(name, _)| name);
            return bad(
                largest,
                format!(
                    "{} segments × ({} + 2 × {} cap) rings make {vertices} vertices, more than \
                     {MAX_VERTICES}",
                    self.segments, self.rings, self.cap_rings
                ),
            );
        }
        if self
            .meshes_per_label
            .saturating_mul(2)
            .saturating_mul(vertices)
            > MAX_TOTAL_POSITIONS
        {
            return bad(
                "meshes_per_label",
                format!(
                    "{} × 2 frames of {vertices} vertices exceed {MAX_TOTAL_POSITIONS} positions",
                    self.meshes_per_label
                ),
            );
        }
        Ok(())
    }
}

/// The kind of deformation of a frame, which is also its label.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    Bend,
    Twist,
}

impl ShapeKind {
    /// The label string: `"bend"` or `"twist"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Bend => "bend",
            Self::Twist => "twist",
        }
    }
}

impl std::fmt::Display for ShapeKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The parameters of one frame (angles in radians). [`deform`] applies `twist`, then `bend`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ShapeParams {
    pub label: ShapeKind,
    /// Total turn of the axis (signed).
    pub bend: f32,
    /// Direction the axis bends toward, as an angle about z from +x.
    pub bend_azimuth: f32,
    /// Rotation of the top cap relative to the bottom cap (signed, right-handed about +z).
    pub twist: f32,
}

impl ShapeParams {
    /// The undeformed capsule, labelled as a bend of 0.
    pub fn rest() -> Self {
        Self {
            label: ShapeKind::Bend,
            bend: 0.0,
            bend_azimuth: 0.0,
            twist: 0.0,
        }
    }
}

/// A generated set and the parameters of each of its frames (`params[i]` made frame `i`).
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSet {
    /// Frames named `"0000"`, `"0001"`, …, labelled `"bend"` / `"twist"`.
    pub set: MeshSet,
    pub params: Vec<ShapeParams>,
}

/// The capsule's dimensions along the axis, in f64.
struct Dims {
    /// Half the cylinder's length: the cylinder spans `z ∈ [-half, half]`.
    half: f64,
    r_bottom: f64,
    r_top: f64,
}

impl Dims {
    fn of(config: &SynthConfig) -> Self {
        let radius = config.radius as f64;
        Self {
            half: config.length as f64 / 2.0,
            r_bottom: radius * (1.0 + TAPER),
            r_top: radius * (1.0 - TAPER),
        }
    }

    /// Pole-to-pole length of the axis.
    fn axis_length(&self) -> f64 {
        2.0 * self.half + self.r_bottom + self.r_top
    }

    /// Midpoint of the axis (not 0: the caps differ in size).
    fn axis_mid(&self) -> f64 {
        ((self.half + self.r_top) - (self.half + self.r_bottom)) / 2.0
    }

    /// Largest distance of the surface from the axis.
    fn max_half_width(&self) -> f64 {
        self.r_bottom * (1.0 + CROSS_COS2 + CROSS_COS3)
    }
}

/// Cross-section radius factor at angle `alpha`.
fn cross_section(alpha: f64) -> f64 {
    1.0 + CROSS_COS2 * (2.0 * alpha).cos() + CROSS_COS3 * (3.0 * alpha).cos()
}

/// The undeformed capsule of `config`.
///
/// Vertex order: bottom pole, then rings of `segments` vertices from bottom to top (bottom cap,
/// cylinder, top cap; within a ring counter-clockwise seen from +z, starting on +x), then the
/// top pole. The config should be valid ([`SynthConfig::validate`]); out-of-range counts are
/// clamped (at least 2 rings, 3 segments) rather than panicking.
pub fn rest_capsule(config: &SynthConfig) -> TriMesh {
    let rings = config.rings.max(2);
    let segments = config.segments.max(3);
    let dims = Dims::of(config);

    // (z, radius scale) of every ring, bottom to top.
    let latitude = |j: usize| j as f64 * FRAC_PI_2 / (config.cap_rings + 1) as f64;
    let mut ring_zs: Vec<(f64, f64)> = Vec::with_capacity(rings + 2 * config.cap_rings);
    for j in (1..=config.cap_rings).rev() {
        let g = latitude(j);
        ring_zs.push((
            -dims.half - dims.r_bottom * g.sin(),
            dims.r_bottom * g.cos(),
        ));
    }
    for i in 0..rings {
        let t = i as f64 / (rings - 1) as f64;
        let r = dims.r_bottom + t * (dims.r_top - dims.r_bottom);
        ring_zs.push((-dims.half + t * 2.0 * dims.half, r));
    }
    for j in 1..=config.cap_rings {
        let g = latitude(j);
        ring_zs.push((dims.half + dims.r_top * g.sin(), dims.r_top * g.cos()));
    }

    let unit_ring: Vec<(f64, f64)> = (0..segments)
        .map(|m| {
            let alpha = TAU * m as f64 / segments as f64;
            let rho = cross_section(alpha);
            (rho * alpha.cos(), rho * alpha.sin())
        })
        .collect();
    let mut positions: Vec<Point> = Vec::with_capacity(2 + segments * ring_zs.len());
    positions.push([0.0, 0.0, (-dims.half - dims.r_bottom) as f32]);
    for &(z, r) in &ring_zs {
        positions.extend(
            unit_ring
                .iter()
                .map(|&(x, y)| [(r * x) as f32, (r * y) as f32, z as f32]),
        );
    }
    positions.push([0.0, 0.0, (dims.half + dims.r_top) as f32]);

    TriMesh {
        faces: capsule_faces(ring_zs.len(), segments),
        positions,
    }
}

/// Faces of a capsule with `ring_count` rings of `segments` vertices between two poles, laid out
/// as in [`rest_capsule`], oriented outward.
fn capsule_faces(ring_count: usize, segments: usize) -> Vec<Face> {
    let top_pole = (1 + ring_count * segments) as u32;
    let v = |ring: usize, m: usize| (1 + ring * segments + m % segments) as u32;
    let mut faces = Vec::with_capacity(2 * segments * ring_count);
    for m in 0..segments {
        faces.push([0, v(0, m + 1), v(0, m)]);
    }
    for k in 0..ring_count - 1 {
        for m in 0..segments {
            let (a, b) = (v(k, m), v(k, m + 1));
            let (c, d) = (v(k + 1, m + 1), v(k + 1, m));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    for m in 0..segments {
        faces.push([v(ring_count - 1, m), v(ring_count - 1, m + 1), top_pole]);
    }
    faces
}

/// `rest` (normally [`rest_capsule`] of the same config) deformed by `params`: twist about the
/// z axis, then bend. Both are maps of space defined by the config's dimensions, so any mesh can
/// be deformed; the faces are copied. Non-finite parameters give non-finite positions.
pub fn deform(rest: &TriMesh, params: &ShapeParams, config: &SynthConfig) -> TriMesh {
    let dims = Dims::of(config);
    let positions = rest
        .positions
        .iter()
        .map(|p| {
            let q = twist_point(p.map(f64::from), params.twist as f64, &dims);
            bend_point(q, params.bend as f64, params.bend_azimuth as f64, &dims).map(|c| c as f32)
        })
        .collect();
    TriMesh {
        positions,
        faces: rest.faces.clone(),
    }
}

/// Rotation about z by `theta × (t − ½)`, `t` the point's position along the cylinder clamped to
/// [0, 1]: the caps turn rigidly with the cylinder's ends.
fn twist_point(p: [f64; 3], theta: f64, dims: &Dims) -> [f64; 3] {
    let t = ((p[2] + dims.half) / (2.0 * dims.half)).clamp(0.0, 1.0);
    let (sin, cos) = (theta * (t - 0.5)).sin_cos();
    [cos * p[0] - sin * p[1], sin * p[0] + cos * p[1], p[2]]
}

/// Maps the z axis onto an arc of the same length turning by `angle` toward azimuth `phi`,
/// keeping each point's offset from the axis in the slice perpendicular to the arc.
fn bend_point(p: [f64; 3], angle: f64, phi: f64, dims: &Dims) -> [f64; 3] {
    let kappa = angle / dims.axis_length();
    if kappa == 0.0 {
        return p;
    }
    let (ds, dc) = phi.sin_cos();
    let u = dc * p[0] + ds * p[1]; // toward the centre of curvature
    let w = -ds * p[0] + dc * p[1]; // out of the bending plane
    let s = p[2] - dims.axis_mid();
    let a = kappa * s;
    let (sin, cos) = a.sin_cos();
    // Arc point: (1 − cos a)/κ toward d, sin a/κ along z — written without cancellation.
    let along_d = 2.0 * (a / 2.0).sin().powi(2) / kappa + u * cos;
    let along_z = dims.axis_mid() + sin / kappa - u * sin;
    [dc * along_d - ds * w, ds * along_d + dc * w, along_z]
}

/// splitmix64 (Steele, Lea & Flood 2014): tiny, fast, and plenty for drawing amplitudes.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `0..n` (`n > 0`), by multiply-shift.
    fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }
}

/// `n` values in `[-max, max]`, one per equal-width stratum (so both extremes are approached),
/// jittered within it and shuffled.
fn stratified(rng: &mut SplitMix64, n: usize, max: f64) -> Vec<f64> {
    let mut values: Vec<f64> = (0..n)
        .map(|i| -max + 2.0 * max * (i as f64 + rng.uniform()) / n as f64)
        .collect();
    for i in (1..n).rev() {
        values.swap(i, rng.below(i + 1));
    }
    values
}

/// The frames' parameters: rest capsule first, then bends and twists alternating.
fn sample_params(config: &SynthConfig) -> Vec<ShapeParams> {
    let m = config.meshes_per_label;
    let mut rng = SplitMix64(config.seed);
    let bends = stratified(&mut rng, m - 1, config.max_bend as f64);
    let twists = stratified(&mut rng, m, config.max_twist as f64);
    let mut bend_params = vec![ShapeParams::rest()];
    for bend in bends {
        bend_params.push(ShapeParams {
            label: ShapeKind::Bend,
            bend: bend as f32,
            bend_azimuth: (rng.uniform() * PI) as f32,
            twist: 0.0,
        });
    }
    bend_params
        .into_iter()
        .zip(twists)
        .flat_map(|(bend, twist)| {
            let twist = ShapeParams {
                label: ShapeKind::Twist,
                twist: twist as f32,
                ..ShapeParams::rest()
            };
            [bend, twist]
        })
        .collect()
}

/// Generates `2 × meshes_per_label` frames: frame 0 is the rest capsule (a bend of 0), then bends
/// and twists alternate, their amplitudes spread over `[-max, max]` and drawn from `seed`.
pub fn generate(config: &SynthConfig) -> Result<SynthSet> {
    config.validate()?;
    let rest = rest_capsule(config);
    let params = sample_params(config);
    let vertex_count = rest.vertex_count();
    let mut positions = Vec::with_capacity(params.len() * vertex_count);
    for p in &params {
        positions.extend(deform(&rest, p, config).positions);
    }
    let names = (0..params.len()).map(|i| format!("{i:04}")).collect();
    let labels = params.iter().map(|p| p.label.as_str().to_owned()).collect();
    let set =
        MeshSet::from_flat(rest.faces, vertex_count, positions, names)?.with_labels(labels)?;
    Ok(SynthSet { set, params })
}

#[cfg(test)]
mod tests;
