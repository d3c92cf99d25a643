//! glTF reader: JSON document, buffers, and accessors read with every offset, stride and length
//! checked against the bytes actually present.
//!
//! The document is deserialized with `gltf-json`'s types but not run through its validation,
//! which indexes arrays without bounds checks (a POSITION index past the accessors panics):
//! instead everything this reader touches is looked up with `get` and checked here.

use super::container::{decode_data_uri, has_scheme, percent_decode, split_glb};
use super::keys;
use crate::Loaded;
use crate::error::{MeshIoError, Result, Warning};
use crate::mesh::{Face, MeshSet, Point, TriMesh, check_finite};
use gltf::json::Root;
use gltf::json::accessor::sparse::Sparse;
use gltf::json::accessor::{
    Accessor, ComponentType, GenericComponentType, IndexComponentType, Type,
};
use gltf::json::mesh::{Mode, Primitive, Semantic};
use gltf::json::validation::Checked;
use serde::Deserialize;
use serde_json::Value;
use std::borrow::Cow;
use std::cell::OnceCell;
use std::path::{Path, PathBuf};

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

/// `count` elements of `size` bytes, `stride` bytes apart, from the start of `data`; the
/// constructor ([`Source::elements`]) has checked that they all lie inside `data`.
#[derive(Clone, Copy)]
struct Elements<'b> {
    data: &'b [u8],
    stride: usize,
    size: usize,
    count: usize,
}

impl<'b> Elements<'b> {
    fn iter(self) -> impl Iterator<Item = &'b [u8]> {
        let Self {
            data,
            stride,
            size,
            count,
        } = self;
        (0..count).map(move |i| &data[i * stride..][..size])
    }
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

    fn accessor(&self, index: usize, what: &str) -> Result<&Accessor> {
        self.root
            .accessors
            .get(index)
            .ok_or_else(|| self.error(format!("{what}: accessor {index} does not exist")))
    }

    /// A VEC3 FLOAT accessor; `expected` = the count it must have (which also allows an accessor
    /// without a buffer view: zeros, possibly overridden by sparse values).
    fn read_vec3(&self, index: usize, what: &str, expected: Option<usize>) -> Result<Vec<Point>> {
        let accessor = self.accessor(index, what)?;
        match (&accessor.type_, &accessor.component_type) {
            (
                Checked::Valid(Type::Vec3),
                Checked::Valid(GenericComponentType(ComponentType::F32)),
            ) => self.read_accessor(accessor, index, what, expected, 12, |e| {
                [f32_at(e, 0), f32_at(e, 4), f32_at(e, 8)]
            }),
            (ty, component) => Err(self.error(format!(
                "{what}: accessor {index} is {} of {}; expected VEC3 of FLOAT",
                checked_name(ty),
                checked_name(component)
            ))),
        }
    }

    /// A SCALAR accessor of unsigned bytes, shorts or ints.
    fn read_indices(&self, index: usize) -> Result<Vec<u32>> {
        let what = "indices";
        let accessor = self.accessor(index, what)?;
        let component = match &accessor.component_type {
            Checked::Valid(GenericComponentType(c)) => Some(*c),
            Checked::Invalid => None,
        };
        match (&accessor.type_, component) {
            (Checked::Valid(Type::Scalar), Some(ComponentType::U8)) => {
                self.read_accessor(accessor, index, what, None, 1, |e| e[0].into())
            }
            (Checked::Valid(Type::Scalar), Some(ComponentType::U16)) => {
                self.read_accessor(accessor, index, what, None, 2, |e| {
                    u16::from_le_bytes([e[0], e[1]]).into()
                })
            }
            (Checked::Valid(Type::Scalar), Some(ComponentType::U32)) => {
                self.read_accessor(accessor, index, what, None, 4, |e| u32_at(e, 0))
            }
            (ty, _) => Err(self.error(format!(
                "{what}: accessor {index} is {} of {}; expected SCALAR of UNSIGNED_BYTE, \
                 UNSIGNED_SHORT or UNSIGNED_INT",
                checked_name(ty),
                checked_name(&accessor.component_type)
            ))),
        }
    }

    /// Reads `accessor` as elements of `size` bytes decoded by `decode`, sparse values applied.
    fn read_accessor<T: Copy + Default>(
        &self,
        accessor: &Accessor,
        index: usize,
        what: &str,
        expected: Option<usize>,
        size: usize,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<Vec<T>> {
        let count = usize::try_from(accessor.count.0).unwrap_or(usize::MAX);
        if let Some(expected) = expected
            && count != expected
        {
            return Err(self.error(format!(
                "{what}: accessor {index} has {count} elements, expected {expected}"
            )));
        }
        let mut values = match (accessor.buffer_view, expected) {
            (Some(view), _) => {
                let offset = accessor.byte_offset.map_or(0, |o| o.0);
                let elements = self.elements(view.value(), offset, count, size, None, what)?;
                elements.iter().map(&decode).collect()
            }
            // The count was checked against `expected`, so this allocation is bounded.
            (None, Some(_)) => vec![T::default(); count],
            (None, None) => {
                return Err(self.error(format!("{what}: accessor {index} has no bufferView")));
            }
        };
        if let Some(sparse) = &accessor.sparse {
            self.apply_sparse(sparse, &mut values, size, &decode, what)?;
        }
        Ok(values)
    }

    /// Overwrites the elements a sparse accessor names with its values.
    fn apply_sparse<T>(
        &self,
        sparse: &Sparse,
        values: &mut [T],
        size: usize,
        decode: &impl Fn(&[u8]) -> T,
        what: &str,
    ) -> Result<()> {
        let count = usize::try_from(sparse.count.0).unwrap_or(usize::MAX);
        if count > values.len() {
            return Err(self.error(format!(
                "{what}: {count} sparse values for {} elements",
                values.len()
            )));
        }
        let (index_size, read_index): (usize, fn(&[u8]) -> u32) =
            match &sparse.indices.component_type {
                Checked::Valid(IndexComponentType(ComponentType::U8)) => (1, |e| e[0].into()),
                Checked::Valid(IndexComponentType(ComponentType::U16)) => {
                    (2, |e| u16::from_le_bytes([e[0], e[1]]).into())
                }
                Checked::Valid(IndexComponentType(ComponentType::U32)) => (4, |e| u32_at(e, 0)),
                _ => {
                    return Err(self.error(format!(
                        "{what}: sparse indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or \
                         UNSIGNED_INT"
                    )));
                }
            };
        let indices = &sparse.indices;
        let indices = self.elements(
            indices.buffer_view.value(),
            indices.byte_offset.0,
            count,
            index_size,
            Some(index_size),
            what,
        )?;
        let sparse_values = &sparse.values;
        let sparse_values = self.elements(
            sparse_values.buffer_view.value(),
            sparse_values.byte_offset.0,
            count,
            size,
            Some(size),
            what,
        )?;
        let len = values.len();
        for (i, value) in indices.iter().zip(sparse_values.iter()) {
            let i = read_index(i);
            let slot = values.get_mut(i as usize).ok_or_else(|| {
                self.error(format!(
                    "{what}: sparse index {i} is out of range ({len} elements)"
                ))
            })?;
            *slot = decode(value);
        }
        Ok(())
    }

    /// `count` elements of `size` bytes at `offset` in buffer view `view`, `stride` apart (else
    /// the view's `byteStride`, else tightly packed), checked to lie inside the view, the view
    /// inside its buffer and the buffer inside the bytes that exist.
    fn elements(
        &self,
        view: usize,
        offset: u64,
        count: usize,
        size: usize,
        stride: Option<usize>,
        what: &str,
    ) -> Result<Elements<'_>> {
        let buffer_view = self
            .root
            .buffer_views
            .get(view)
            .ok_or_else(|| self.error(format!("{what}: bufferView {view} does not exist")))?;
        let buffer_index = buffer_view.buffer.value();
        let buffer = self.buffer(buffer_index, what)?;
        let start = buffer_view.byte_offset.map_or(0, |o| o.0);
        let length = buffer_view.byte_length.0;
        let data = start
            .checked_add(length)
            .filter(|&end| end <= buffer.len() as u64)
            .map(|end| &buffer[start as usize..end as usize])
            .ok_or_else(|| {
                self.error(format!(
                    "{what}: bufferView {view} (offset {start}, length {length}) overruns \
                     buffer {buffer_index} of {} bytes",
                    buffer.len()
                ))
            })?;
        let stride = stride.unwrap_or_else(|| buffer_view.byte_stride.map_or(size, |s| s.0));
        if stride < size {
            return Err(self.error(format!(
                "{what}: byteStride {stride} of bufferView {view} is smaller than an element \
                 ({size} bytes)"
            )));
        }
        if count == 0 {
            return Ok(Elements {
                data: &[],
                stride,
                size,
                count,
            });
        }
        let needed = offset as u128 + (count as u128 - 1) * stride as u128 + size as u128;
        if needed > data.len() as u128 {
            return Err(self.error(format!(
                "{what}: {count} elements of {size} bytes, {stride} apart from offset {offset}, \
                 need {needed} bytes but bufferView {view} has {}",
                data.len()
            )));
        }
        Ok(Elements {
            data: &data[offset as usize..],
            stride,
            size,
            count,
        })
    }

    /// Buffer `index`, cut to its `byteLength`, loaded on first use.
    fn buffer(&self, index: usize, what: &str) -> Result<&[u8]> {
        let cell = self
            .buffers
            .get(index)
            .ok_or_else(|| self.error(format!("{what}: buffer {index} does not exist")))?;
        if let Some(data) = cell.get() {
            return Ok(data);
        }
        let data = self.load_buffer(index)?;
        Ok(cell.get_or_init(|| data))
    }

    fn load_buffer(&self, index: usize) -> Result<Cow<'a, [u8]>> {
        let Some(buffer) = self.root.buffers.get(index) else {
            return Err(self.error(format!("buffer {index} does not exist")));
        };
        let data: Cow<'a, [u8]> = match buffer.uri.as_deref() {
            None if index == 0 => Cow::Borrowed(self.bin.ok_or_else(|| {
                self.error("buffer 0 has no uri and there is no GLB BIN chunk".into())
            })?),
            None => return Err(self.error(format!("buffer {index} has no uri"))),
            Some(uri) if uri.starts_with("data:") => Cow::Owned(
                decode_data_uri(uri).map_err(|m| self.error(format!("buffer {index}: {m}")))?,
            ),
            Some(uri) if has_scheme(uri) => {
                return Err(self.error(format!(
                    "buffer {index}: unsupported URI {:?} (only relative file paths and \
                     data:…;base64, URIs are read)",
                    uri.chars().take(60).collect::<String>()
                )));
            }
            Some(uri) => {
                let relative =
                    percent_decode(uri).map_err(|m| self.error(format!("buffer {index}: {m}")))?;
                let file = self
                    .path
                    .parent()
                    .map_or_else(PathBuf::new, Path::to_path_buf)
                    .join(relative);
                Cow::Owned(std::fs::read(&file).map_err(|e| MeshIoError::io(&file, e))?)
            }
        };
        let length = buffer.byte_length.0;
        if (data.len() as u64) < length {
            return Err(self.error(format!(
                "buffer {index} declares {length} bytes but holds {}",
                data.len()
            )));
        }
        let length = length as usize;
        Ok(match data {
            Cow::Borrowed(bytes) => Cow::Borrowed(&bytes[..length]),
            Cow::Owned(mut bytes) => {
                bytes.truncate(length);
                Cow::Owned(bytes)
            }
        })
    }

    /// Value of `key` in the first mesh's `extras`.
    fn extra(&self, key: &str) -> Option<&Value> {
        self.json.pointer("/meshes/0/extras")?.get(key)
    }

    fn warn(&self, warnings: &mut Vec<Warning>, message: String) {
        warnings.push(Warning {
            path: self.path.into(),
            message,
        });
    }

    fn frame_names(&self, n: usize, warnings: &mut Vec<Warning>) -> Vec<String> {
        if let Some(value) = self.extra(keys::FRAME_NAMES) {
            match string_array(value, n) {
                Some(names) => return names,
                None => self.warn(
                    warnings,
                    format!("extras.{} is not {n} strings; ignored", keys::FRAME_NAMES),
                ),
            }
        }
        if let Some(value) = self.extra(keys::TARGET_NAMES) {
            match string_array(value, n - 1) {
                Some(names) => {
                    let base = self.json.pointer("/meshes/0/name").and_then(Value::as_str);
                    let mut all = vec![base.unwrap_or("base").to_string()];
                    all.extend(names);
                    return all;
                }
                None => self.warn(
                    warnings,
                    format!(
                        "extras.{} is not {} strings; ignored",
                        keys::TARGET_NAMES,
                        n - 1
                    ),
                ),
            }
        }
        (0..n).map(|k| format!("frame_{k:04}")).collect()
    }

    fn labels(&self, n: usize, warnings: &mut Vec<Warning>) -> Option<Vec<String>> {
        let value = self.extra(keys::LABELS)?;
        let labels = string_array(value, n);
        if labels.is_none() {
            self.warn(
                warnings,
                format!("extras.{} is not {n} strings; ignored", keys::LABELS),
            );
        }
        labels
    }

    /// Applies the writer's table of exact values (see the module documentation).
    fn apply_corrections(&self, positions: &mut [Point], n: usize, v: usize) -> Result<()> {
        let Some(table) = self.extra(keys::CORRECTIONS) else {
            return Ok(());
        };
        let what = format!("extras.{}", keys::CORRECTIONS);
        let field = |name: &str| {
            table
                .get(name)
                .and_then(Value::as_u64)
                .and_then(|x| usize::try_from(x).ok())
        };
        let (Some(view), Some(count)) = (field("bufferView"), field("count")) else {
            return Err(self.error(format!("{what} needs an integer bufferView and count")));
        };
        let size = keys::CORRECTION_SIZE;
        let records = self.elements(view, 0, count, size, Some(size), &what)?;
        for (i, record) in records.iter().enumerate() {
            let (frame, component) = (u32_at(record, 0) as usize, u32_at(record, 4) as usize);
            let slot = (frame < n && component < 3 * v)
                .then(|| positions.get_mut(frame * v + component / 3))
                .flatten()
                .ok_or_else(|| {
                    self.error(format!(
                        "{what}: record {i} names frame {frame}, component {component}, \
                         outside {n} frames of {v} vertices"
                    ))
                })?;
            slot[component % 3] = f32_at(record, 8);
        }
        Ok(())
    }
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_bits(u32_at(bytes, at))
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn checked_name<T: std::fmt::Debug>(value: &Checked<T>) -> String {
    match value {
        Checked::Valid(v) => format!("{v:?}"),
        Checked::Invalid => "an invalid type".into(),
    }
}

/// `value` as exactly `len` strings.
fn string_array(value: &Value, len: usize) -> Option<Vec<String>> {
    let array = value.as_array().filter(|a| a.len() == len)?;
    array.iter().map(|s| s.as_str().map(String::from)).collect()
}
