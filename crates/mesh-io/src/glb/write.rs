//! GLB writer: the base mesh, one morph target per later frame with displacements chosen so the
//! frames come back bit-exactly, corrections where no such displacement exists, and a `STEP`
//! animation of the morph weights.

use super::{FRAMES_PER_SECOND, keys};
use crate::mesh::{Face, Point, bbox};
use serde_json::{Map, Value, json};
use std::io::{self, Write};

/// What to write: frame-major positions of `positions.len() / vertex_count` frames (frame 0 is
/// the base), with names and labels for a set.
pub(super) struct Frames<'a> {
    pub faces: &'a [Face],
    pub vertex_count: usize,
    pub positions: &'a [Point],
    pub names: Option<&'a [String]>,
    pub labels: Option<&'a [String]>,
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const UNSIGNED_INT: u32 = 5125;
const FLOAT: u32 = 5126;
const TRIANGLES: u32 = 4;
/// How many neighbouring `f32` values on each side of the rounded difference are tried. The
/// rounded difference itself almost always works when anything does; this covers double rounding.
const SEARCH_STEPS: usize = 4;

/// The displacement `d` such that `base + d`, computed in `f32`, is `frame` bit for bit, and
/// whether it is exact. When no such `d` exists (`frame` needs finer precision than a `d` of that
/// size has), the nearest finite difference is returned with `false`.
pub(super) fn displacement(base: f32, frame: f32) -> (f32, bool) {
    let exact = |d: f32| (base + d).to_bits() == frame.to_bits();
    // x + (−0) is x for every x, signed zeros included; +0 would turn −0 into +0.
    if base.to_bits() == frame.to_bits() {
        return (-0.0, true);
    }
    // The f64 difference of two f32s is exact unless their exponents are far apart.
    let rounded = (frame as f64 - base as f64) as f32;
    let nearest = if rounded.is_finite() {
        rounded
    } else {
        f32::MAX.copysign(rounded)
    };
    if exact(nearest) {
        return (nearest, true);
    }
    let (mut up, mut down) = (nearest, nearest);
    for _ in 0..SEARCH_STEPS {
        up = up.next_up();
        down = down.next_down();
        for d in [up, down] {
            if d.is_finite() && exact(d) {
                return (d, true);
            }
        }
    }
    (nearest, false)
}

/// Morph-target displacements of frames 1.. relative to frame 0, each target's bounds, and the
/// corrections (frame, 3 × vertex + axis, value) for components no displacement reproduces.
struct Targets {
    displacements: Vec<Point>,
    bounds: Vec<(Point, Point)>,
    corrections: Vec<(u32, u32, f32)>,
}

fn targets(frames: &Frames) -> io::Result<Targets> {
    let v = frames.vertex_count;
    let base = &frames.positions[..v];
    let mut out = Targets {
        displacements: Vec::with_capacity(frames.positions.len() - v),
        bounds: Vec::new(),
        corrections: Vec::new(),
    };
    for (k, frame) in frames.positions.chunks_exact(v).enumerate().skip(1) {
        let start = out.displacements.len();
        for (i, (b, f)) in base.iter().zip(frame).enumerate() {
            let mut d = [0f32; 3];
            for axis in 0..3 {
                let (value, exact) = displacement(b[axis], f[axis]);
                d[axis] = value;
                if !exact {
                    let component = u32::try_from(3 * i + axis).map_err(|_| too_large())?;
                    let frame_index = u32::try_from(k).map_err(|_| too_large())?;
                    out.corrections.push((frame_index, component, f[axis]));
                }
            }
            out.displacements.push(d);
        }
        out.bounds
            .push(bbox(&out.displacements[start..]).unwrap_or_default());
    }
    Ok(out)
}

fn too_large() -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        "the mesh set is too large for one GLB file (4 GiB at most)",
    )
}

/// Buffer views and accessors, laid out back to back in the one buffer. Every part's length is
/// a multiple of 4 bytes, so every view starts 4-byte aligned as the spec asks.
#[derive(Default)]
struct Layout {
    views: Vec<Value>,
    accessors: Vec<Value>,
    length: u64,
}

impl Layout {
    /// Adds a view of `count` elements of `size` bytes and one accessor on it; returns the
    /// accessor's index.
    fn add(&mut self, count: usize, ty: &str, component: u32, target: Option<u32>) -> usize {
        let size = match ty {
            "VEC3" => 12,
            _ => 4,
        };
        let bytes = count as u64 * size;
        let mut view = json!({ "buffer": 0, "byteOffset": self.length, "byteLength": bytes });
        if let (Some(target), Value::Object(map)) = (target, &mut view) {
            map.insert("target".into(), json!(target));
        }
        self.length += bytes;
        self.views.push(view);
        self.accessors.push(json!({
            "bufferView": self.views.len() - 1,
            "componentType": component,
            "count": count,
            "type": ty,
        }));
        self.accessors.len() - 1
    }

    /// Sets an accessor's `min` and `max`.
    fn bounds(&mut self, accessor: usize, min: Value, max: Value) {
        if let Some(Value::Object(map)) = self.accessors.get_mut(accessor) {
            map.insert("min".into(), min);
            map.insert("max".into(), max);
        }
    }
}

/// Writes the whole GLB: header, JSON chunk (space-padded), BIN chunk (zero-padded, though every
/// part already has a length that is a multiple of 4).
pub(super) fn write_glb(w: &mut impl Write, frames: &Frames) -> io::Result<()> {
    let v = frames.vertex_count;
    let frame_count = frames.positions.len() / v.max(1);
    let targets = targets(frames)?;
    let base = &frames.positions[..v];
    let mut layout = Layout::default();

    let position = layout.add(v, "VEC3", FLOAT, Some(ARRAY_BUFFER));
    let (lo, hi) = bbox(base).unwrap_or_default();
    layout.bounds(position, json!(lo), json!(hi));
    let indices = layout.add(3 * frames.faces.len(), "SCALAR", UNSIGNED_INT, None);
    if let Some(Value::Object(view)) = layout.views.last_mut() {
        view.insert("target".into(), json!(ELEMENT_ARRAY_BUFFER));
    }
    let mut target_objects = Vec::new();
    for (lo, hi) in &targets.bounds {
        let accessor = layout.add(v, "VEC3", FLOAT, Some(ARRAY_BUFFER));
        layout.bounds(accessor, json!(lo), json!(hi));
        target_objects.push(json!({ "POSITION": accessor }));
    }

    let mut primitive = json!({
        "attributes": { "POSITION": position },
        "indices": indices,
        "mode": TRIANGLES,
    });
    let mut mesh = Map::new();
    mesh.insert("name".into(), json!("meshvae"));
    let mut root = Map::new();
    if frame_count > 1 {
        if let Value::Object(map) = &mut primitive {
            map.insert("targets".into(), Value::Array(target_objects));
        }
        mesh.insert("weights".into(), json!(vec![0.0f32; frame_count - 1]));
        root.insert(
            "animations".into(),
            json!([animation(&mut layout, frame_count)]),
        );
    }
    mesh.insert("primitives".into(), json!([primitive]));
    if let Some(extras) = extras(frames, &mut layout, &targets.corrections) {
        mesh.insert("extras".into(), extras);
    }
    root.insert(
        "asset".into(),
        json!({ "version": "2.0", "generator": "meshvae mesh-io" }),
    );
    root.insert("scene".into(), json!(0));
    root.insert("scenes".into(), json!([{ "nodes": [0] }]));
    root.insert("nodes".into(), json!([{ "mesh": 0, "name": "meshvae" }]));
    root.insert("meshes".into(), json!([mesh]));
    root.insert("buffers".into(), json!([{ "byteLength": layout.length }]));
    root.insert("bufferViews".into(), Value::Array(layout.views));
    root.insert("accessors".into(), Value::Array(layout.accessors));

    let mut json = serde_json::to_vec(&Value::Object(root))?;
    json.resize(json.len().next_multiple_of(4), b' ');
    let bin_length = layout.length.next_multiple_of(4);
    let total = 12 + 8 + json.len() as u64 + 8 + bin_length;
    let total = u32::try_from(total).map_err(|_| too_large())?;
    w.write_all(b"glTF")?;
    w.write_all(&2u32.to_le_bytes())?;
    w.write_all(&total.to_le_bytes())?;
    w.write_all(&(json.len() as u32).to_le_bytes())?;
    w.write_all(b"JSON")?;
    w.write_all(&json)?;
    w.write_all(&(bin_length as u32).to_le_bytes())?;
    w.write_all(b"BIN\0")?;

    // The parts, in the order `layout` placed them.
    let floats = |points: &[Point]| {
        points
            .iter()
            .flatten()
            .map(|x| x.to_le_bytes())
            .collect::<Vec<_>>()
    };
    write_words(w, floats(base).into_iter())?;
    write_words(w, frames.faces.iter().flatten().map(|i| i.to_le_bytes()))?;
    for target in targets.displacements.chunks_exact(v.max(1)) {
        write_words(w, floats(target).into_iter())?;
    }
    if frame_count > 1 {
        write_words(w, keyframe_times(frame_count).map(f32::to_le_bytes))?;
        let weights = (0..frame_count)
            .flat_map(|k| (0..frame_count - 1).map(move |t| if k == t + 1 { 1f32 } else { 0f32 }));
        write_words(w, weights.map(f32::to_le_bytes))?;
    }
    if frames.names.is_some() {
        let records = targets
            .corrections
            .iter()
            .flat_map(|&(frame, component, value)| {
                [
                    frame.to_le_bytes(),
                    component.to_le_bytes(),
                    value.to_le_bytes(),
                ]
            });
        write_words(w, records)?;
    }
    w.write_all(&vec![0u8; (bin_length - layout.length) as usize])
}

/// The mesh's `extras` (frame names, target names, labels, corrections) for a set; `None` for a
/// lone mesh. Adds the corrections' buffer view to `layout`.
fn extras(frames: &Frames, layout: &mut Layout, corrections: &[(u32, u32, f32)]) -> Option<Value> {
    let names = frames.names?;
    let mut extras = Map::new();
    extras.insert(keys::FRAME_NAMES.into(), json!(names));
    if names.len() > 1 {
        extras.insert(keys::TARGET_NAMES.into(), json!(names[1..]));
    }
    if let Some(labels) = frames.labels {
        extras.insert(keys::LABELS.into(), json!(labels));
    }
    if !corrections.is_empty() {
        let bytes = (corrections.len() * keys::CORRECTION_SIZE) as u64;
        layout
            .views
            .push(json!({ "buffer": 0, "byteOffset": layout.length, "byteLength": bytes }));
        layout.length += bytes;
        extras.insert(
            keys::CORRECTIONS.into(),
            json!({ "bufferView": layout.views.len() - 1, "count": corrections.len() }),
        );
    }
    Some(Value::Object(extras))
}

/// Keyframe k at k / [`FRAMES_PER_SECOND`] seconds.
fn keyframe_times(frame_count: usize) -> impl Iterator<Item = f32> {
    (0..frame_count).map(|k| (k as f64 / FRAMES_PER_SECOND as f64) as f32)
}

/// The animation of the node's morph weights: STEP keyframes, keyframe k showing frame k.
fn animation(layout: &mut Layout, frame_count: usize) -> Value {
    let input = layout.add(frame_count, "SCALAR", FLOAT, None);
    let last = keyframe_times(frame_count).last().unwrap_or(0.0);
    layout.bounds(input, json!([0.0f32]), json!([last]));
    let output = layout.add(frame_count * (frame_count - 1), "SCALAR", FLOAT, None);
    json!({
        "name": "frames",
        "samplers": [{ "input": input, "output": output, "interpolation": "STEP" }],
        "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }],
    })
}

/// Writes 4-byte words through a 64 KiB staging buffer.
fn write_words(w: &mut impl Write, words: impl Iterator<Item = [u8; 4]>) -> io::Result<()> {
    let mut buf = Vec::with_capacity(1 << 16);
    for word in words {
        buf.extend_from_slice(&word);
        if buf.len() >= 1 << 16 {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(base: f32, frame: f32) -> bool {
        let (d, exact) = displacement(base, frame);
        assert!(d.is_finite());
        assert_eq!(exact, (base + d).to_bits() == frame.to_bits());
        exact
    }

    #[test]
    fn displacement_is_exact_in_ordinary_cases() {
        // Same sign and |base| ≤ 2 |frame|: then |d| ≤ |frame|, so d is at least as fine as the
        // frame's value and an exact d always exists (found whatever the naive result).
        let values = [0.1f32, 0.3, -0.7, 1.0, 1e-3, 12345.678, -0.0, 0.0, 2.5e-5];
        for &b in &values {
            for &f in &values {
                if f.signum() == b.signum() && b.abs() <= 2.0 * f.abs()
                    || f.to_bits() == b.to_bits()
                {
                    assert!(check(b, f), "base {b:e} frame {f:e}");
                }
            }
        }
    }

    #[test]
    fn displacement_preserves_negative_zero() {
        assert!(check(-0.0, -0.0));
        assert!(check(0.0, 0.0));
        assert!(check(5.0, 5.0));
        // +0 → −0 cannot be reached by an addition under round-to-nearest.
        assert!(!check(0.0, -0.0));
        assert!(!check(0.5, -0.0));
    }

    #[test]
    fn impossible_cases_are_reported_with_the_nearest_displacement() {
        // A frame value much finer than the displacement's precision.
        let (b, f) = (1.0f32, 1.2345e-3);
        let (d, exact) = displacement(b, f);
        assert!(!exact);
        assert_eq!(d, (f as f64 - b as f64) as f32);
        // A difference beyond the f32 range is clamped to a finite value.
        let (d, exact) = displacement(-3e38, 3e38);
        assert!(!exact);
        assert_eq!(d, f32::MAX);
    }

    #[test]
    fn brute_force_agrees_on_random_pairs() {
        // Exhaustive check over every f32 near the rounded difference: if any d within ±64 ulps
        // works, the search must have found one.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..2000 {
            let b = (next() as i32 as f32) * 1e-9;
            let f = b * (1.0 + ((next() % 2001) as f32 - 1000.0) * 1e-3);
            let (_, exact) = displacement(b, f);
            let mut d = (f as f64 - b as f64) as f32;
            for _ in 0..64 {
                d = d.next_down();
            }
            let any = (0..129).any(|_| {
                let ok = (b + d).to_bits() == f.to_bits();
                d = d.next_up();
                ok
            });
            assert_eq!(exact, any, "base {b:e} frame {f:e}");
        }
    }
}
