//! PLY, ASCII and binary. Filled in by the OFF/PLY work; see the signatures below.

use crate::error::{MeshIoError, Result};
use crate::{Loaded, TriMesh};
use std::path::Path;

/// How a PLY file stores its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// Reads a PLY file (any encoding).
pub fn read_ply(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_ply(&bytes, path)
}

/// Parses PLY bytes; `path` only names the source in errors.
pub fn parse_ply(_bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}

/// Writes a PLY file atomically.
pub fn write_ply(path: &Path, _mesh: &TriMesh, _encoding: PlyEncoding) -> Result<()> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}
