//! One-file storage of a [`Hierarchy`], written atomically and checked on load so that nothing
//! is recomputed and nothing inconsistent is returned.
//!
//! **Version 2** (written by [`Hierarchy::save`]): a safetensors file of the workspace's
//! convention (`mesh_io::stamped`: metadata `format` = `meshvae-hierarchy`, `version` = `2`,
//! `writer`, and `checksum`, the CRC-32 of the tensor data, verified on loading). Floats are
//! stored as they are held (F32 positions, F64 matrix values), so they come back bit for bit;
//! integer arrays (`uint` below) in the narrowest of U16, U32 and U64 that holds their largest
//! value, which is lossless and halves the index arrays of meshes under 65,536 vertices. `i`
//! is the level or the pooling step:
//! - `level.i.faces` uint [F, 3], `level.i.positions` F32 [V, 3];
//! - `level.i.laplacian.indptr` uint [rows + 1], `….indices` uint [nnz], `….values` F64 [nnz];
//! - `pooling.i.pool.*` and `pooling.i.depool.*`: the same three arrays;
//! - `pooling.i.clusters.offsets` uint [m + 1] and `pooling.i.clusters.members` uint [n]:
//!   cluster c is `members[offsets[c]..offsets[c + 1]]`; only for steps that have clusters.
//!
//! Metadata `hierarchy` holds the rest as JSON: `{"config": <HierarchyConfig>, "levels":
//! [{"vertex_count", "laplacian": {"rows", "cols"}}], "pooling": [{"kind", "pool": {"rows",
//! "cols"}, "depool": {…}, "clusters": <bool>}]}`.
//!
//! **Version 1** (still read, written by [`Hierarchy::save_json`]): JSON
//! `{"format": "meshvae-hierarchy", "version": 1, "hierarchy": <Hierarchy>}`, over twice as
//! large (numbers as decimal text). [`Hierarchy::load`] tells the two apart by content.

mod binary;
mod json;

use crate::error::HierarchyError;
use crate::hierarchy::Hierarchy;
use std::path::Path;

/// The file's `format` (metadata entry of version 2, field of version 1).
pub const FORMAT: &str = "meshvae-hierarchy";
/// The file layout version [`Hierarchy::save`] writes; [`Hierarchy::load`] reads it and
/// version 1.
pub const VERSION: u32 = 2;

impl Hierarchy {
    /// Writes the hierarchy to `path` (version 2, safetensors; a temporary file renamed into
    /// place).
    pub fn save(&self, path: &Path) -> Result<(), HierarchyError> {
        binary::write(self, path)
    }

    /// Writes the hierarchy to `path` in the version-1 JSON layout, for tools that predate
    /// version 2 (a temporary file renamed into place).
    pub fn save_json(&self, path: &Path) -> Result<(), HierarchyError> {
        json::write(self, path)
    }

    /// Reads a hierarchy written by [`Hierarchy::save`] or [`Hierarchy::save_json`], checking
    /// the format, the version, the checksum (version 2), every sparse matrix's invariants and
    /// every operator's shape against its levels.
    pub fn load(path: &Path) -> Result<Self, HierarchyError> {
        let bytes = std::fs::read(path).map_err(|e| HierarchyError::file(path, e.to_string()))?;
        let hierarchy = if is_json(&bytes) {
            json::read(&bytes, path)?
        } else {
            binary::read(&bytes, path)?
        };
        checked(hierarchy, path)
    }
}

/// Whether `bytes` are a version-1 (JSON) file: a `{` after optional whitespace, unless they
/// begin like a safetensors file (an 8-byte header length that fits, then the header's `{`),
/// whose length bytes could happen to read as whitespace and `{`.
fn is_json(bytes: &[u8]) -> bool {
    let safetensors = bytes.len() > 8 && bytes[8] == b'{' && {
        let mut len = [0u8; 8];
        len.copy_from_slice(&bytes[..8]);
        u64::from_le_bytes(len) <= (bytes.len() - 8) as u64
    };
    !safetensors && bytes.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{')
}

/// The checks every loaded hierarchy passes, whichever layout it came from.
fn checked(hierarchy: Hierarchy, path: &Path) -> Result<Hierarchy, HierarchyError> {
    for m in hierarchy
        .levels
        .iter()
        .map(|l| &l.laplacian)
        .chain(hierarchy.pooling.iter().flat_map(|p| [&p.pool, &p.depool]))
    {
        m.validate()
            .map_err(|e| HierarchyError::file(path, e.to_string()))?;
    }
    hierarchy
        .check_shapes()
        .map_err(|e| HierarchyError::file(path, e))?;
    Ok(hierarchy)
}

#[cfg(test)]
mod tests {
    use super::is_json;

    #[test]
    fn json_is_told_from_safetensors_by_content() {
        assert!(is_json(b"{\"format\":1}"));
        assert!(is_json(b" \n\t{}"));
        assert!(!is_json(b""));
        assert!(!is_json(b"[1]"));
        // A safetensors header of 0x7b20 bytes begins with a space and `{`.
        let mut st = vec![0x20, 0x7b, 0, 0, 0, 0, 0, 0, b'{'];
        st.resize(8 + 0x7b20, b' ');
        assert!(!is_json(&st));
    }
}
