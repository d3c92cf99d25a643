//! glTF reader: JSON document, buffers, and accessors read with every offset, stride and length
//! checked against the bytes actually present.
//!
//! The document is deserialized with `gltf-json`'s types but not run through its validation,
//! which indexes arrays without bounds checks (a POSITION index past the accessors panics):
//! instead everything this reader touches is looked up with `get` and checked here.

mod accessors;
mod buffers;
mod extras;

use super::container::split_glb;
use crate::Loaded;
use crate::error::{MeshIoError, Result, Warning};
use crate::mesh::{Face, MeshSet, TriMesh, check_finite};
use gltf::json::Root;
use gltf::json::mesh::{Mode, Primitive, Semantic};
use gltf::json::validation::Checked;
use serde::Deserialize;
use serde_json::Value;
use std::borrow::Cow;
use std::cell::OnceCell;
use std::path::Path;

/// Most points (frames × vertices) a set may have: a small file can name one large accessor as
/// thousands of morph targets, which must not turn into an unbounded allocation.
const MAX_POINTS: usize = 1 << 28;

pub(super) fn parse_mesh(bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    let source = Source::open(bytes, path)?;
    let (primitive, warnings) = source.primitive()?;
    let value = source.base(primitive)?;
    Ok(Loaded { value, warnings })
}

pub(super) fn parse_set(bytes: &[u8], path: &Path) -> Result<Loaded<MeshSet>> {
    let source = Source::open(bytes, path)?;
    let (primitive, mut warnings) = source.primitive()?;
    let base = source.base(primitive)?;
    let targets = primitive.targets.as_deref().unwrap_or_default();
    let n = targets.len() + 1;
    if n < 2 {
        return Err(MeshIoError::TooFewMeshes {
            path: path.into(),
            count: 1,
        });
    }
    let v = base.vertex_count();
    if n.checked_mul(v).is_none_or(|points| points > MAX_POINTS) {
        return Err(source.error(format!(
            "{n} frames of {v} vertices is more than this reader accepts ({MAX_POINTS} points)"
        )));
    }
    let mut positions = Vec::with_capacity(n * v);
    positions.extend_from_slice(&base.positions);
    for (k, target) in targets.iter().enumerate() {
        let Some(accessor) = target.positions else {
            positions.extend_from_slice(&base.positions);
            continue;
        };
        let what = format!("morph target {k} POSITION");
        let d = source.read_vec3(accessor.value(), &what, Some(v))?;
        // Exactly what a viewer computes, and what the writer's displacements are chosen for.
        positions.extend(
            base.positions
                .iter()
                .zip(&d)
                .map(|(b, d)| [b[0] + d[0], b[1] + d[1], b[2] + d[2]]),
        );
    }
    source.apply_corrections(&mut positions, n, v)?;
    for frame in positions.chunks_exact(v) {
        check_finite(frame, path)?;
    }
    let names = source.frame_names(n, &mut warnings);
    let labels = source.labels(n, &mut warnings);
    let set = MeshSet::from_flat(base.faces, v, positions, names)?;
    let value = match labels {
        Some(labels) => set.with_labels(labels)?,
        None => set,
    };
    Ok(Loaded { value, warnings })
}

/// A parsed document with its buffers, loaded on first use.
struct Source<'a> {
    path: &'a Path,
    root: Root,
    /// The same document as plain JSON, for `extras` (which `gltf-json` drops without its
    /// `extras` feature) and names.
    json: Value,
    bin: Option<&'a [u8]>,
    buffers: Vec<OnceCell<Cow<'a, [u8]>>>,
}

impl<'a> Source<'a> {
    fn open(bytes: &'a [u8], path: &'a Path) -> Result<Self> {
        let error = |message: String| MeshIoError::Gltf {
            path: path.into(),
            message,
        };
        let (json, bin) = if bytes.starts_with(b"glTF") {
            split_glb(bytes).map_err(error)?
        } else {
            (bytes, None)
        };
        // Tolerated: a byte-order mark, and NUL padding from writers that pad the wrong way.
        let json = json.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(json);
        let end = json.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
        let json: Value = serde_json::from_slice(&json[..end])
            .map_err(|e| error(format!("invalid glTF JSON: {e}")))?;
        let root = Root::deserialize(&json)
            .map_err(|e| error(format!("not a valid glTF 2.0 document: {e}")))?;
        if !root.asset.version.starts_with("2.") {
            return Err(error(format!(
                "glTF version {:?} is not supported (2.x only)",
                root.asset.version
            )));
        }
        let buffers = root.buffers.iter().map(|_| OnceCell::new()).collect();
        Ok(Self {
            path,
            root,
            json,
            bin,
            buffers,
        })
    }

    fn error(&self, message: String) -> MeshIoError {
        MeshIoError::Gltf {
            path: self.path.into(),
            message,
        }
    }

    /// The first mesh's first primitive, which must be triangles; warnings for what is ignored.
    fn primitive(&self) -> Result<(&Primitive, Vec<Warning>)> {
        let mesh = self
            .root
            .meshes
            .first()
            .ok_or_else(|| self.error("the file has no mesh".into()))?;
        let primitive = mesh
            .primitives
            .first()
            .ok_or_else(|| self.error("mesh 0 has no primitive".into()))?;
        let mut warnings = Vec::new();
        let mut warn = |message: String| {
            warnings.push(Warning {
                path: self.path.into(),
                message,
            })
        };
        if self.root.meshes.len() > 1 {
            warn(format!(
                "{} meshes: only the first is read",
                self.root.meshes.len()
            ));
        }
        if mesh.primitives.len() > 1 {
            warn(format!(
                "{} primitives: only the first is read",
                mesh.primitives.len()
            ));
        }
        let mode = match &primitive.mode {
            Checked::Valid(Mode::Triangles) => return Ok((primitive, warnings)),
            Checked::Valid(Mode::Points) => "POINTS",
            Checked::Valid(Mode::Lines) => "LINES",
            Checked::Valid(Mode::LineLoop) => "LINE_LOOP",
            Checked::Valid(Mode::LineStrip) => "LINE_STRIP",
            Checked::Valid(Mode::TriangleStrip) => "TRIANGLE_STRIP",
            Checked::Valid(Mode::TriangleFan) => "TRIANGLE_FAN",
            Checked::Invalid => "invalid",
        };
        Err(self.error(format!(
            "the first primitive's mode is {mode}; only TRIANGLES is supported"
        )))
    }

    /// The primitive's base positions and triangles, validated.
    fn base(&self, primitive: &Primitive) -> Result<TriMesh> {
        let position = primitive
            .attributes
            .get(&Checked::Valid(Semantic::Positions))
            .ok_or_else(|| self.error("the first primitive has no POSITION attribute".into()))?;
        let positions = self.read_vec3(position.value(), "POSITION", None)?;
        check_finite(&positions, self.path)?;
        let n = positions.len();
        let corners: Vec<u32> = match primitive.indices {
            Some(indices) => self.read_indices(indices.value())?,
            None => {
                let n = u32::try_from(n)
                    .map_err(|_| self.error(format!("{n} vertices are too many")))?;
                (0..n).collect()
            }
        };
        if !corners.len().is_multiple_of(3) {
            return Err(self.error(format!(
                "{} triangle corners is not a multiple of 3",
                corners.len()
            )));
        }
        if let Some(&index) = corners.iter().find(|&&i| i as usize >= n) {
            return Err(MeshIoError::IndexOutOfRange {
                path: self.path.into(),
                line: 0,
                index: index.into(),
                vertices: n,
            });
        }
        let faces: Vec<Face> = corners
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let mesh = TriMesh { positions, faces };
        mesh.validate(self.path)?;
        Ok(mesh)
    }
}
