//! One-file storage of a [`Hierarchy`]: JSON with a format tag and version, written atomically,
//! checked on load so nothing is recomputed and nothing inconsistent is returned.

use crate::error::HierarchyError;
use crate::hierarchy::Hierarchy;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The value of the file's `format` field.
pub const FORMAT: &str = "meshvae-hierarchy";
/// The file layout version this crate writes and reads.
pub const VERSION: u32 = 1;

#[derive(Serialize)]
struct FileOut<'a> {
    format: &'a str,
    version: u32,
    hierarchy: &'a Hierarchy,
}

#[derive(Deserialize)]
struct FileIn {
    format: String,
    version: u32,
    hierarchy: Hierarchy,
}

impl Hierarchy {
    /// Writes the hierarchy to `path` (JSON; a temporary file renamed into place).
    pub fn save(&self, path: &Path) -> Result<(), HierarchyError> {
        let out = FileOut {
            format: FORMAT,
            version: VERSION,
            hierarchy: self,
        };
        mesh_io::atomic::write_atomic(path, |w| {
            serde_json::to_writer(&mut *w, &out).map_err(std::io::Error::other)
        })?;
        Ok(())
    }

    /// Reads a hierarchy written by [`Hierarchy::save`], checking the format tag, the version,
    /// every sparse matrix's invariants and every operator's shape against its levels.
    pub fn load(path: &Path) -> Result<Self, HierarchyError> {
        let bytes = std::fs::read(path).map_err(|e| HierarchyError::file(path, e.to_string()))?;
        let file: FileIn = serde_json::from_slice(&bytes)
            .map_err(|e| HierarchyError::file(path, e.to_string()))?;
        if file.format != FORMAT {
            return Err(HierarchyError::file(
                path,
                format!("format is {:?}, expected {FORMAT:?}", file.format),
            ));
        }
        if file.version != VERSION {
            return Err(HierarchyError::file(
                path,
                format!("version {} (this build reads {VERSION})", file.version),
            ));
        }
        let hierarchy = file.hierarchy;
        // CsrMatrix derives Deserialize, so re-check its invariants before anything indexes it.
        for m in hierarchy
            .levels
            .iter()
            .map(|l| &l.laplacian)
            .chain(hierarchy.pooling.iter().flat_map(|p| [&p.pool, &p.depool]))
        {
            crate::sparse::CsrMatrix::new(
                m.rows(),
                m.cols(),
                m.indptr().to_vec(),
                m.indices().to_vec(),
                m.values().to_vec(),
            )
            .map_err(|e| HierarchyError::file(path, e.to_string()))?;
        }
        hierarchy
            .check_shapes()
            .map_err(|e| HierarchyError::file(path, e))?;
        Ok(hierarchy)
    }
}
