//! glTF 2.0: binary `.glb` and JSON `.gltf`, one mesh or a whole set as morph targets.
//!
//! **Reading** takes the first mesh's first primitive, which must be `TRIANGLES`: `POSITION`
//! (VEC3 FLOAT) and indices (unsigned byte, short or int; without indices, consecutive vertex
//! triples are the triangles). Buffers come from the GLB `BIN` chunk, from `.bin` files named by
//! URIs relative to the file, or from `data:…;base64,` URIs. Sparse accessors are supported.
//! Every accessor is bounds-checked (offset, stride, count, component type, buffer view and
//! buffer lengths), so a malformed file gives a [`MeshIoError::Gltf`], never a panic or an
//! over-read.
//!
//! As a **set**, frame 0 is the base positions and frame k is the base plus the `POSITION`
//! displacements of morph target k−1, added in `f32` as a viewer does. Frame names come from
//! the mesh's `extras.meshvae_frame_names` (N strings), else from `extras.targetNames` (the
//! base is then named after the mesh, or `base`), else `frame_0000`, `frame_0001`, …; labels
//! from `extras.meshvae_labels` (N strings).
//!
//! **Writing** a set gives one GLB with one mesh, one primitive (u32 indices), the base = frame
//! 0, one morph target per later frame, a node, a scene, and an animation of the node's
//! `weights` with `STEP` interpolation at [`FRAMES_PER_SECOND`]: keyframe 0 has all weights 0
//! and keyframe k ≥ 1 weight 1 on target k−1 only, so the sequence plays in Blender or any glTF
//! viewer.
//!
//! **Exactness.** Each displacement component `d` is chosen so that `base + d` in `f32` is the
//! frame's value bit for bit. No such `d` exists when the frame's value needs finer precision
//! than `d` can carry (typically a coordinate near 0 in the frame but not in the base; about 4%
//! of the horse-gallop components): the nearest `d` is written (what a viewer shows is then off
//! by at most half an ulp of `d`), and the exact value goes into a correction table that this
//! reader applies: `extras.meshvae_corrections = {"bufferView": i, "count": n}`, n records of
//! 12 bytes (u32 frame, u32 `3 × vertex + axis`, f32 value; little-endian). So OBJ → GLB →
//! [`MeshSet`] reproduces every `f32` exactly.

mod container;
mod read;
mod write;

use crate::error::{MeshIoError, Result};
use crate::{Loaded, MeshSet, TriMesh};
use std::io::Write;
use std::path::Path;

/// Playback rate of the written animation: keyframe k is at time k / 24 s.
pub const FRAMES_PER_SECOND: f32 = 24.0;

/// Reads the first mesh primitive's base positions and triangles (morph targets are ignored).
pub fn read_gltf_mesh(path: &Path) -> Result<Loaded<TriMesh>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_gltf_mesh(&bytes, path)
}

/// Parses a `.glb` or `.gltf` held in memory as one mesh. `path` names the source in errors and
/// locates external buffers (relative to its folder).
pub fn parse_gltf_mesh(bytes: &[u8], path: &Path) -> Result<Loaded<TriMesh>> {
    read::parse_mesh(bytes, path)
}

/// Reads a multi-frame glTF/GLB: the base mesh is frame 0 and each morph target is one more frame.
/// A file without morph targets is [`MeshIoError::TooFewMeshes`].
pub fn read_gltf_set(path: &Path) -> Result<Loaded<MeshSet>> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_gltf_set(&bytes, path)
}

/// Parses a `.glb` or `.gltf` held in memory as a set; `path` as in [`parse_gltf_mesh`].
pub fn parse_gltf_set(bytes: &[u8], path: &Path) -> Result<Loaded<MeshSet>> {
    read::parse_set(bytes, path)
}

/// Writes one mesh as GLB atomically. The mesh must be valid ([`TriMesh::validate`]).
pub fn write_glb_mesh(path: &Path, mesh: &TriMesh) -> Result<()> {
    mesh.validate(path)?;
    crate::atomic::write_atomic(path, |w| write_glb_mesh_to(w, mesh))
}

/// Writes one mesh as GLB to any writer; an invalid mesh is an `InvalidInput` I/O error.
pub fn write_glb_mesh_to(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    mesh.validate(Path::new("<mesh>"))
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
    write::write_glb(
        w,
        &write::Frames {
            faces: &mesh.faces,
            vertex_count: mesh.vertex_count(),
            positions: &mesh.positions,
            names: None,
            labels: None,
        },
    )
}

/// Writes a whole set as one GLB: frame 0 is the base mesh, every later frame is a morph target,
/// and an animation steps through the frames so the sequence plays in any glTF viewer. A set of
/// one frame is written as a plain mesh (readable by [`read_gltf_mesh`], not as a set).
pub fn write_glb_set(path: &Path, set: &MeshSet) -> Result<()> {
    crate::atomic::write_atomic(path, |w| write_glb_set_to(w, set))
}

/// Writes a whole set as GLB to any writer (see [`write_glb_set`]). Fails with an `InvalidInput`
/// I/O error only when the set does not fit the format (more than 4 GiB).
pub fn write_glb_set_to(w: &mut impl Write, set: &MeshSet) -> std::io::Result<()> {
    write::write_glb(
        w,
        &write::Frames {
            faces: set.faces(),
            vertex_count: set.vertex_count(),
            positions: set.positions(),
            names: Some(set.names()),
            labels: set.labels(),
        },
    )
}

/// Names shared by the reader and the writer.
mod keys {
    pub const FRAME_NAMES: &str = "meshvae_frame_names";
    pub const LABELS: &str = "meshvae_labels";
    pub const CORRECTIONS: &str = "meshvae_corrections";
    pub const TARGET_NAMES: &str = "targetNames";
    /// Bytes of one correction record: u32 frame, u32 component, f32 value.
    pub const CORRECTION_SIZE: usize = 12;
}
