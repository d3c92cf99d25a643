//! glTF 2.0 / GLB. Filled in by the glTF work; see the signatures below.

use crate::error::{MeshIoError, Result};
use crate::{Loaded, MeshSet, TriMesh};
use std::path::Path;

/// Reads the first mesh primitive's base positions and triangles.
pub fn read_gltf_mesh(path: &Path) -> Result<Loaded<TriMesh>> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}

/// Reads a multi-frame glTF/GLB: the base mesh is frame 0 and each morph target is one more frame.
pub fn read_gltf_set(path: &Path) -> Result<Loaded<MeshSet>> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}

/// Writes one mesh as GLB atomically.
pub fn write_glb_mesh(path: &Path, _mesh: &TriMesh) -> Result<()> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}

/// Writes a whole set as one GLB: frame 0 is the base mesh, every frame is a morph target, and
/// an animation steps through the frames so the sequence plays in any glTF viewer.
pub fn write_glb_set(path: &Path, _set: &MeshSet) -> Result<()> {
    Err(MeshIoError::UnsupportedFormat { path: path.into() })
}
