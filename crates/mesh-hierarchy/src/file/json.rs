//! Version 1: the whole hierarchy as JSON. serde_json's `float_roundtrip` (a workspace feature)
//! makes it exact, but floats as decimal text make it several times larger than version 2.

use super::FORMAT;
use crate::error::HierarchyError;
use crate::hierarchy::Hierarchy;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The only JSON layout version.
const JSON_VERSION: u32 = 1;

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

pub(super) fn write(hierarchy: &Hierarchy, path: &Path) -> Result<(), HierarchyError> {
    let out = FileOut {
        format: FORMAT,
        version: JSON_VERSION,
        hierarchy,
    };
    mesh_io::atomic::write_atomic(path, |w| {
        serde_json::to_writer(&mut *w, &out).map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// The hierarchy of a version-1 file, not yet checked.
pub(super) fn read(bytes: &[u8], path: &Path) -> Result<Hierarchy, HierarchyError> {
    let file: FileIn =
        serde_json::from_slice(bytes).map_err(|e| HierarchyError::file(path, e.to_string()))?;
    if file.format != FORMAT {
        return Err(HierarchyError::file(
            path,
            format!("format is {:?}, expected {FORMAT:?}", file.format),
        ));
    }
    if file.version != JSON_VERSION {
        return Err(HierarchyError::file(
            path,
            format!(
                "JSON of version {}, but only version 1 is JSON (later versions are safetensors)",
                file.version
            ),
        ));
    }
    Ok(file.hierarchy)
}
