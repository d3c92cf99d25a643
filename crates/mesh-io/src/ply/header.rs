//! The PLY header: magic line, format, elements and their properties, each error naming its
//! line. Also decides what the reader does with each property (coordinate, face indices, skip).

use super::PlyEncoding;
use crate::error::{MeshIoError, Result};
use crate::off::lossy;
use std::path::Path;

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    /// Both the classic names (`uchar`) and the sized ones (`uint8`).
    fn from_name(name: &[u8]) -> Option<Self> {
        Some(match name {
            b"char" | b"int8" => Self::I8,
            b"uchar" | b"uint8" => Self::U8,
            b"short" | b"int16" => Self::I16,
            b"ushort" | b"uint16" => Self::U16,
            b"int" | b"int32" => Self::I32,
            b"uint" | b"uint32" => Self::U32,
            b"float" | b"float32" => Self::F32,
            b"double" | b"float64" => Self::F64,
            _ => return None,
        })
    }

    /// Size in bytes in the binary encodings.
    pub(super) fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// The values an integer type holds; `None` for floating-point types.
    pub(super) fn int_range(self) -> Option<(i64, i64)> {
        Some(match self {
            Self::I8 => (i8::MIN.into(), i8::MAX.into()),
            Self::U8 => (0, u8::MAX.into()),
            Self::I16 => (i16::MIN.into(), i16::MAX.into()),
            Self::U16 => (0, u16::MAX.into()),
            Self::I32 => (i32::MIN.into(), i32::MAX.into()),
            Self::U32 => (0, u32::MAX.into()),
            Self::F32 | Self::F64 => return None,
        })
    }

    pub(super) fn is_integer(self) -> bool {
        self.int_range().is_some()
    }
}

/// A property's storage: one scalar, or a count followed by that many items.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

/// What the reader does with a property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Use {
    /// Coordinate 0, 1 or 2 (x, y, z) of a vertex.
    Coordinate(usize),
    /// The vertex indices of a face.
    FaceIndices,
    Skip,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Property {
    pub name: String,
    pub kind: Kind,
    pub usage: Use,
    pub line: usize,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Element {
    pub name: String,
    pub count: usize,
    pub properties: Vec<Property>,
    pub line: usize,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Header {
    pub encoding: PlyEncoding,
    pub elements: Vec<Element>,
    /// Byte offset of the data: just after the `end_header` line.
    pub data_start: usize,
    /// Number of header lines; ASCII data line numbers continue from here.
    pub lines: usize,
    /// Index in `elements` of the `vertex` element, when there is one.
    pub vertex: Option<usize>,
    /// Index in `elements` of the `face` element, when there is one.
    pub face: Option<usize>,
}

/// Parses the header. The binary data after `end_header` is never looked at.
pub(super) fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    let err = |line: usize, message: String| MeshIoError::parse(path, line, message);
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if pos >= bytes.len() {
            let message = if line_no == 0 {
                "empty file (expected a PLY header)"
            } else {
                "unexpected end of file in the header (no end_header line)"
            };
            return Err(err(line_no.max(1), message.into()));
        }
        let rest = &bytes[pos..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        pos = pos.saturating_add(end + 1).min(bytes.len());
        line_no += 1;
        let line = rest[..end].strip_suffix(b"\r").unwrap_or(&rest[..end]);
        let mut t = line
            .split(u8::is_ascii_whitespace)
            .filter(|t| !t.is_empty());
        if line_no == 1 {
            if t.next() != Some(&b"ply"[..]) || t.next().is_some() {
                return Err(err(
                    1,
                    "not a PLY file (the first line must be `ply`)".into(),
                ));
            }
            continue;
        }
        let Some(keyword) = t.next() else {
            continue;
        };
        match keyword {
            b"comment" | b"obj_info" => {}
            b"format" => {
                if encoding.is_some() {
                    return Err(err(line_no, "second format line".into()));
                }
                let name = t.next().unwrap_or_default();
                encoding = Some(match name {
                    b"ascii" => PlyEncoding::Ascii,
                    b"binary_little_endian" => PlyEncoding::BinaryLittleEndian,
                    b"binary_big_endian" => PlyEncoding::BinaryBigEndian,
                    _ => return Err(err(line_no, format!("unknown format {:?}", lossy(name)))),
                });
                match (t.next(), t.next()) {
                    (Some(b"1.0"), None) => {}
                    _ => return Err(err(line_no, "expected `format <encoding> 1.0`".into())),
                }
            }
            b"element" => {
                let (Some(name), Some(count), None) = (t.next(), t.next(), t.next()) else {
                    return Err(err(line_no, "expected `element <name> <count>`".into()));
                };
                let count = std::str::from_utf8(count)
                    .ok()
                    .and_then(|s| s.parse::<usize>().ok())
                    .ok_or_else(|| err(line_no, format!("bad element count {:?}", lossy(count))))?;
                elements.push(Element {
                    name: lossy(name),
                    count,
                    properties: Vec::new(),
                    line: line_no,
                });
            }
            b"property" => {
                let property = parse_property(t).map_err(|m| err(line_no, m))?;
                let Some(element) = elements.last_mut() else {
                    return Err(err(line_no, "property before any element".into()));
                };
                let name = lossy(property.1);
                if element.properties.iter().any(|p| p.name == name) {
                    return Err(err(line_no, format!("duplicate property {name:?}")));
                }
                element.properties.push(Property {
                    name,
                    kind: property.0,
                    usage: Use::Skip,
                    line: line_no,
                });
            }
            b"end_header" => {
                if t.next().is_some() {
                    return Err(err(line_no, "unexpected text after end_header".into()));
                }
                break;
            }
            other => {
                return Err(err(
                    line_no,
                    format!("unknown header keyword {:?}", lossy(other)),
                ));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| err(line_no, "the header has no format line".into()))?;
    let (vertex, face) = assign_roles(&mut elements, path)?;
    Ok(Header {
        encoding,
        elements,
        data_start: pos,
        lines: line_no,
        vertex,
        face,
    })
}

/// `property <type> <name>` or `property list <count type> <item type> <name>`, after the
/// keyword.
fn parse_property<'a>(
    mut t: impl Iterator<Item = &'a [u8]>,
) -> std::result::Result<(Kind, &'a [u8]), String> {
    let scalar = |name: Option<&[u8]>| {
        let name = name.unwrap_or_default();
        Scalar::from_name(name).ok_or_else(|| format!("unknown property type {:?}", lossy(name)))
    };
    let first = t.next();
    let kind = if first == Some(&b"list"[..]) {
        let count = scalar(t.next())?;
        let item = scalar(t.next())?;
        if !count.is_integer() {
            return Err("a list's count type must be an integer type".into());
        }
        Kind::List { count, item }
    } else {
        Kind::Scalar(scalar(first)?)
    };
    match (t.next(), t.next()) {
        (Some(name), None) => Ok((kind, name)),
        _ => Err(
            "expected `property <type> <name>` or `property list <count type> <item type> \
                  <name>`"
                .into(),
        ),
    }
}

/// Finds the `vertex` and `face` elements and marks the properties the reader uses.
fn assign_roles(elements: &mut [Element], path: &Path) -> Result<(Option<usize>, Option<usize>)> {
    let err = |line: usize, message: String| MeshIoError::parse(path, line, message);
    let (mut vertex, mut face) = (None, None);
    for (index, element) in elements.iter_mut().enumerate() {
        let slot = match element.name.as_str() {
            "vertex" => &mut vertex,
            "face" => &mut face,
            _ => continue,
        };
        if slot.is_some() {
            return Err(err(
                element.line,
                format!("second {} element", element.name),
            ));
        }
        *slot = Some(index);
        if element.name == "vertex" {
            for (axis, name) in ["x", "y", "z"].into_iter().enumerate() {
                let property = element
                    .properties
                    .iter_mut()
                    .find(|p| p.name == name)
                    .ok_or_else(|| err(element.line, format!("element vertex has no {name}")))?;
                if !matches!(property.kind, Kind::Scalar(_)) {
                    return Err(err(
                        property.line,
                        format!("vertex {name} must not be a list"),
                    ));
                }
                property.usage = Use::Coordinate(axis);
            }
        } else {
            let property = element
                .properties
                .iter_mut()
                .find(|p| p.name == "vertex_indices" || p.name == "vertex_index")
                .ok_or_else(|| {
                    err(
                        element.line,
                        "element face has no vertex_indices list".into(),
                    )
                })?;
            match property.kind {
                Kind::List { item, .. } if item.is_integer() => {}
                _ => {
                    return Err(err(
                        property.line,
                        format!("{} must be a list of integers", property.name),
                    ));
                }
            }
            property.usage = Use::FaceIndices;
        }
    }
    Ok((vertex, face))
}
