//! OFF (Object File Format), ASCII. Filled in by the OFF/PLY work; see the signatures below.

use crate::error::{MeshIoError, Result};
use crate::{Loaded, TriMesh};
use std::path::Path;

/// Reads an ASCII OFF file.
pub fn read_off(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_off(&bytes, path)
}

/// Parses OFF text; `path` only names the source in errors.
pub fn parse_off(_bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}

/// Writes an ASCII OFF file atomically.
pub fn write_off(path: &Path, _mesh: &TriMesh) -> Result<()> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}
