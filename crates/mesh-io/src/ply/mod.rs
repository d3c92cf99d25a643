//! PLY (Stanford polygon format): `ascii 1.0`, `binary_little_endian 1.0` and
//! `binary_big_endian 1.0`. Vertex order is kept exactly and unused vertices stay.
//!
//! Read: element `vertex` with scalar properties `x`, `y`, `z` of any type (other vertex
//! properties — normals, colours, … — skipped); element `face` with a list property
//! `vertex_indices` or `vertex_index` of integers (other face properties skipped); every other
//! element skipped, list properties included. Faces are triangles, or quads split along their
//! first diagonal with one warning. `comment` and `obj_info` lines are ignored.
//!
//! Robustness: element counts come from the file and may be anything; reservations are capped
//! by the bytes actually present, size arithmetic is checked, and no input makes the reader
//! panic. Errors name the header or ASCII data line; binary data errors name the byte offset.
//!
//! Write: `float` x y z and `list uchar int vertex_indices`, in any of the three encodings.

mod header;
mod source;
#[cfg(test)]
mod tests;

use crate::error::{MeshIoError, Result, Warning};
use crate::mesh::{Face, Point};
use crate::{Loaded, TriMesh};
use header::{Element, Kind, Use};
use source::{Ascii, Binary, Source};
use std::io::Write;
use std::path::Path;

/// How a PLY file stores its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    /// `format ascii 1.0`: whitespace-separated text.
    Ascii,
    /// `format binary_little_endian 1.0`.
    BinaryLittleEndian,
    /// `format binary_big_endian 1.0`.
    BinaryBigEndian,
}

/// Reads a PLY file (any encoding).
pub fn read_ply(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_ply(&bytes, path)
}

/// Parses PLY bytes (any encoding); `path` only names the source in errors and warnings.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    let header = header::parse_header(bytes, path)?;
    let (Some(vertex), Some(face)) = (header.vertex, header.face) else {
        return Err(MeshIoError::EmptyMesh { path: path.into() });
    };
    if header.elements[vertex].count == 0 || header.elements[face].count == 0 {
        return Err(MeshIoError::EmptyMesh { path: path.into() });
    }
    let start = header.data_start;
    match header.encoding {
        PlyEncoding::Ascii => {
            let mut source = Ascii::new(bytes, start, header.lines + 1, path);
            read_body(&mut source, &header.elements, vertex, path)
        }
        PlyEncoding::BinaryLittleEndian => read_body(
            &mut Binary::new(bytes, start, false, path),
            &header.elements,
            vertex,
            path,
        ),
        PlyEncoding::BinaryBigEndian => read_body(
            &mut Binary::new(bytes, start, true, path),
            &header.elements,
            vertex,
            path,
        ),
    }
}

/// Reads every element in file order; `vertex` indexes the vertex element in `elements`.
fn read_body(
    source: &mut impl Source,
    elements: &[Element],
    vertex: usize,
    path: &Path,
) -> Result<Loaded<TriMesh>> {
    let vertex_count = elements[vertex].count;
    let mut mesh = MeshBuilder {
        positions: Vec::new(),
        faces: Vec::new(),
        quads: 0,
        vertex_count,
        path,
    };
    for (index, element) in elements.iter().enumerate() {
        // An element without properties has no data, however many instances it claims.
        if element.properties.is_empty() {
            continue;
        }
        let is_vertex = index == vertex;
        // Every vertex takes at least 3 bytes (three 1-byte coordinates), every face at least
        // 4: the claimed counts cannot reserve more than the input could hold.
        if is_vertex {
            let n = element.count.min(source.remaining() / 3);
            mesh.positions.reserve(n);
        } else if element
            .properties
            .iter()
            .any(|p| p.usage == Use::FaceIndices)
        {
            let n = element.count.min(source.remaining() / 4);
            mesh.faces.reserve(n);
        }
        for instance in 0..element.count {
            mesh.read_instance(source, element, is_vertex)
                .map_err(|e| in_instance(e, element, instance))?;
        }
    }
    let mut warnings = Vec::new();
    if mesh.quads > 0 {
        warnings.push(Warning {
            path: path.into(),
            message: format!("{} quads split into triangles", mesh.quads),
        });
    }
    if let Some(message) = source.trailing() {
        warnings.push(Warning {
            path: path.into(),
            message,
        });
    }
    Ok(Loaded {
        value: TriMesh {
            positions: mesh.positions,
            faces: mesh.faces,
        },
        warnings,
    })
}

/// The mesh being read, and what is needed to check faces as they come.
struct MeshBuilder<'a> {
    positions: Vec<Point>,
    faces: Vec<Face>,
    quads: usize,
    /// Vertex count declared by the header; faces may come before the vertices in the file.
    vertex_count: usize,
    path: &'a Path,
}

impl MeshBuilder<'_> {
    /// Reads one instance of `element`: one vertex, one face, or one skipped record.
    fn read_instance(
        &mut self,
        source: &mut impl Source,
        element: &Element,
        is_vertex: bool,
    ) -> Result<()> {
        let mut point: Point = [0.0; 3];
        for property in &element.properties {
            match (property.usage, property.kind) {
                (Use::Coordinate(axis), Kind::Scalar(ty)) => {
                    let value = source.real(ty)? as f32;
                    if !value.is_finite() {
                        return Err(source.non_finite(self.positions.len(), value));
                    }
                    point[axis] = value;
                }
                (Use::FaceIndices, Kind::List { count, item }) => {
                    self.read_face(source, count, item)?;
                }
                (_, Kind::Scalar(ty)) => source.skip(ty, 1)?,
                (_, Kind::List { count, item }) => {
                    let n = source.integer(count)?;
                    let n = usize::try_from(n)
                        .map_err(|_| source.error(format!("negative list length {n}")))?;
                    source.skip(item, n)?;
                }
            }
        }
        if is_vertex {
            self.positions.push(point);
        }
        Ok(())
    }

    fn read_face(
        &mut self,
        source: &mut impl Source,
        count: header::Scalar,
        item: header::Scalar,
    ) -> Result<()> {
        let arity = source.integer(count)?;
        if arity != 3 && arity != 4 {
            return Err(MeshIoError::NonTriangleFace {
                path: self.path.into(),
                line: source.line(),
                arity: usize::try_from(arity)
                    .map_err(|_| source.error(format!("negative list length {arity}")))?,
            });
        }
        let mut corners = [0u32; 4];
        for corner in corners.iter_mut().take(arity as usize) {
            let index = source.integer(item)?;
            *corner = u32::try_from(index)
                .ok()
                .filter(|&i| (i as usize) < self.vertex_count)
                .ok_or_else(|| MeshIoError::IndexOutOfRange {
                    path: self.path.into(),
                    line: source.line(),
                    index,
                    vertices: self.vertex_count,
                })?;
        }
        self.faces.push([corners[0], corners[1], corners[2]]);
        if arity == 4 {
            self.faces.push([corners[0], corners[2], corners[3]]);
            self.quads += 1;
        }
        Ok(())
    }
}

/// Names the element instance in a parse error's message.
fn in_instance(error: MeshIoError, element: &Element, instance: usize) -> MeshIoError {
    match error {
        MeshIoError::Parse {
            path,
            line,
            message,
        } => MeshIoError::Parse {
            path,
            line,
            message: format!("{} {instance}: {message}", element.name),
        },
        other => other,
    }
}

/// Writes a mesh as PLY in `encoding`, atomically. ASCII coordinates are printed in their
/// shortest form that reads back to the same `f32`, so every encoding round-trips bit-exactly.
pub fn write_ply(path: &Path, mesh: &TriMesh, encoding: PlyEncoding) -> Result<()> {
    crate::atomic::write_atomic(path, |w| write_ply_to(w, mesh, encoding))
}

/// Writes PLY to any writer. Fails (with `InvalidInput`) on a face index above `i32::MAX`,
/// which the `int` index type cannot hold.
pub fn write_ply_to(
    w: &mut impl Write,
    mesh: &TriMesh,
    encoding: PlyEncoding,
) -> std::io::Result<()> {
    if let Some(&index) = mesh
        .faces
        .iter()
        .flatten()
        .find(|&&i| i32::try_from(i).is_err())
    {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("face index {index} does not fit PLY's int index type"),
        ));
    }
    let format = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
    };
    write!(
        w,
        "ply\nformat {format} 1.0\ncomment written by meshvae\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.vertex_count(),
        mesh.face_count()
    )?;
    let big_endian = match encoding {
        PlyEncoding::Ascii => {
            for p in &mesh.positions {
                writeln!(w, "{} {} {}", p[0], p[1], p[2])?;
            }
            for f in &mesh.faces {
                writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
            }
            return Ok(());
        }
        PlyEncoding::BinaryLittleEndian => false,
        PlyEncoding::BinaryBigEndian => true,
    };
    let mut record = [0u8; 13];
    for p in &mesh.positions {
        for (k, c) in p.iter().enumerate() {
            let b = if big_endian {
                c.to_be_bytes()
            } else {
                c.to_le_bytes()
            };
            record[4 * k..4 * k + 4].copy_from_slice(&b);
        }
        w.write_all(&record[..12])?;
    }
    record[0] = 3;
    for f in &mesh.faces {
        for (k, &i) in f.iter().enumerate() {
            // In range: checked above.
            let i = i as i32;
            let b = if big_endian {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            };
            record[1 + 4 * k..5 + 4 * k].copy_from_slice(&b);
        }
        w.write_all(&record)?;
    }
    Ok(())
}
