//! Accessor decoding: VEC3 positions and scalar indices read element by element, sparse values
//! applied, with every offset, stride and count checked against the buffer view and its buffer.

use super::Source;
use crate::error::Result;
use crate::mesh::Point;
use gltf::json::accessor::sparse::Sparse;
use gltf::json::accessor::{
    Accessor, ComponentType, GenericComponentType, IndexComponentType, Type,
};
use gltf::json::validation::Checked;

/// `count` elements of `size` bytes, `stride` bytes apart, from the start of `data`; the
/// constructor ([`Source::elements`]) has checked that they all lie inside `data`.
#[derive(Clone, Copy)]
pub(super) struct Elements<'b> {
    data: &'b [u8],
    stride: usize,
    size: usize,
    count: usize,
}

impl<'b> Elements<'b> {
    pub(super) fn iter(self) -> impl Iterator<Item = &'b [u8]> {
        let Self {
            data,
            stride,
            size,
            count,
        } = self;
        (0..count).map(move |i| &data[i * stride..][..size])
    }
}

impl Source<'_> {
    fn accessor(&self, index: usize, what: &str) -> Result<&Accessor> {
        self.root
            .accessors
            .get(index)
            .ok_or_else(|| self.error(format!("{what}: accessor {index} does not exist")))
    }

    /// A VEC3 FLOAT accessor; `expected` = the count it must have (which also allows an accessor
    /// without a buffer view: zeros, possibly overridden by sparse values).
    pub(super) fn read_vec3(
        &self,
        index: usize,
        what: &str,
        expected: Option<usize>,
    ) -> Result<Vec<Point>> {
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
    pub(super) fn read_indices(&self, index: usize) -> Result<Vec<u32>> {
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
    pub(super) fn elements(
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
}

pub(super) fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_bits(u32_at(bytes, at))
}

pub(super) fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn checked_name<T: std::fmt::Debug>(value: &Checked<T>) -> String {
    match value {
        Checked::Valid(v) => format!("{v:?}"),
        Checked::Invalid => "an invalid type".into(),
    }
}
