//! File formats by extension, and format-independent single-mesh read/write.

use crate::error::{MeshIoError, Result};
use crate::{Loaded, TriMesh, glb, obj, off, ply};
use std::path::Path;

/// A single-mesh file format, known by its extension (case-insensitive).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    Obj,
    Off,
    Ply,
    /// Binary glTF (`.glb`) or JSON glTF (`.gltf`) with its buffers.
    Gltf,
}

impl MeshFormat {
    /// The format of `path` by its extension, or `None` when it is not a mesh file.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(Self::Obj),
            "off" => Some(Self::Off),
            "ply" => Some(Self::Ply),
            "glb" | "gltf" => Some(Self::Gltf),
            _ => None,
        }
    }
}

/// Reads one mesh of any supported format. For glTF: the first primitive's base positions.
pub fn read_mesh(path: &Path) -> Result<Loaded<TriMesh>> {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Obj) => obj::read_obj(path),
        Some(MeshFormat::Off) => off::read_off(path),
        Some(MeshFormat::Ply) => ply::read_ply(path),
        Some(MeshFormat::Gltf) => glb::read_gltf_mesh(path),
        None => Err(MeshIoError::UnsupportedFormat { path: path.into() }),
    }
}

/// Writes one mesh in the format named by the extension of `path`, atomically.
pub fn write_mesh(path: &Path, mesh: &TriMesh) -> Result<()> {
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Obj) => obj::write_obj(path, mesh),
        Some(MeshFormat::Off) => off::write_off(path, mesh),
        Some(MeshFormat::Ply) => ply::write_ply(path, mesh, ply::PlyEncoding::BinaryLittleEndian),
        Some(MeshFormat::Gltf) => glb::write_glb_mesh(path, mesh),
        None => Err(MeshIoError::UnsupportedFormat { path: path.into() }),
    }
}
