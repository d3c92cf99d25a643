//! The `.mvset` cache: a whole [`MeshSet`] in one safetensors file.
//!
//! Tensors: `positions` F32 [N, V, 3] and `faces` U32 [F, 3]. Metadata: `format` =
//! `meshvae-set`, `version` = `1`, `names` (JSON array) and, for labelled sets, `labels` (JSON
//! array). Written atomically; loading checks shapes, indices and finiteness like any reader.

use crate::atomic::write_bytes_atomic;
use crate::error::{MeshIoError, Result};
use crate::mesh::{Face, MeshSet, Point};
use safetensors::SafeTensors;
use safetensors::tensor::{Dtype, TensorView};
use std::collections::HashMap;
use std::path::Path;

const FORMAT: &str = "meshvae-set";
const VERSION: &str = "1";

/// Writes `set` to `path` (conventionally `*.mvset`), atomically.
pub fn write_cache(path: &Path, set: &MeshSet) -> Result<()> {
    let bad = |message: String| MeshIoError::Cache {
        path: path.into(),
        message,
    };
    let positions: Vec<u8> = set
        .positions()
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let faces: Vec<u8> = set
        .faces()
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let pos_view = TensorView::new(
        Dtype::F32,
        vec![set.len(), set.vertex_count(), 3],
        &positions,
    )
    .map_err(|e| bad(e.to_string()))?;
    let face_view = TensorView::new(Dtype::U32, vec![set.faces().len(), 3], &faces)
        .map_err(|e| bad(e.to_string()))?;
    let mut metadata = HashMap::from([
        ("format".to_string(), FORMAT.to_string()),
        ("version".to_string(), VERSION.to_string()),
        ("names".to_string(), json(set.names())),
    ]);
    if let Some(labels) = set.labels() {
        metadata.insert("labels".into(), json(labels));
    }
    let bytes = safetensors::serialize(
        [("positions", pos_view), ("faces", face_view)],
        Some(metadata),
    )
    .map_err(|e| bad(e.to_string()))?;
    write_bytes_atomic(path, &bytes)
}

fn json(strings: &[String]) -> String {
    serde_json::to_string(strings).unwrap_or_else(|_| "[]".into())
}

/// Reads a cache written by [`write_cache`].
pub fn read_cache(path: &Path) -> Result<MeshSet> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::io(path, e))?;
    parse_cache(&bytes, path)
}

/// Parses cache bytes; `path` only names the source in errors.
pub fn parse_cache(bytes: &[u8], path: &Path) -> Result<MeshSet> {
    let bad = |message: String| MeshIoError::Cache {
        path: path.into(),
        message,
    };
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| bad(e.to_string()))?;
    let meta = header
        .metadata()
        .as_ref()
        .ok_or_else(|| bad("no metadata".into()))?;
    if meta.get("format").map(String::as_str) != Some(FORMAT) {
        return Err(bad(format!("metadata `format` is not {FORMAT:?}")));
    }
    if meta.get("version").map(String::as_str) != Some(VERSION) {
        return Err(bad(format!(
            "unsupported version {:?}",
            meta.get("version")
        )));
    }
    let strings = |key: &str| -> Result<Option<Vec<String>>> {
        meta.get(key)
            .map(|s| serde_json::from_str(s).map_err(|e| bad(format!("metadata `{key}`: {e}"))))
            .transpose()
    };
    let names = strings("names")?.ok_or_else(|| bad("metadata has no `names`".into()))?;
    let labels = strings("labels")?;

    let tensors = SafeTensors::deserialize(bytes).map_err(|e| bad(e.to_string()))?;
    let pos = tensors
        .tensor("positions")
        .map_err(|e| bad(e.to_string()))?;
    let faces = tensors.tensor("faces").map_err(|e| bad(e.to_string()))?;
    let (&[n, v, 3], Dtype::F32) = (pos.shape(), pos.dtype()) else {
        return Err(bad(format!(
            "positions are {:?} {:?}, expected F32 [N, V, 3]",
            pos.dtype(),
            pos.shape()
        )));
    };
    let (&[_, 3], Dtype::U32) = (faces.shape(), faces.dtype()) else {
        return Err(bad(format!(
            "faces are {:?} {:?}, expected U32 [F, 3]",
            faces.dtype(),
            faces.shape()
        )));
    };
    if n != names.len() {
        return Err(bad(format!("{} names for {n} frames", names.len())));
    }
    let positions: Vec<Point> = pos
        .data()
        .chunks_exact(12)
        .map(|c| {
            std::array::from_fn(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()))
        })
        .collect();
    let faces: Vec<Face> = faces
        .data()
        .chunks_exact(12)
        .map(|c| {
            std::array::from_fn(|k| u32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()))
        })
        .collect();
    let set = MeshSet::from_flat(faces, v, positions, names).map_err(|e| bad(e.to_string()))?;
    match labels {
        Some(l) => set.with_labels(l).map_err(|e| bad(e.to_string())),
        None => Ok(set),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_set() -> MeshSet {
        let faces = vec![[0, 1, 2], [0, 2, 3]];
        let positions: Vec<Point> = (0..12)
            .map(|i| [i as f32 * 0.1, (i * i) as f32 / 7.0, -1.5])
            .collect();
        MeshSet::from_flat(
            faces,
            4,
            positions,
            vec!["a".into(), "b".into(), "c".into()],
        )
        .unwrap()
        .with_labels(vec!["x".into(), "y".into(), "x".into()])
        .unwrap()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let set = small_set();
        let path = std::env::temp_dir().join(format!("mesh-io-cache-{}.mvset", std::process::id()));
        write_cache(&path, &set).unwrap();
        let back = read_cache(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(back.faces(), set.faces());
        assert_eq!(back.names(), set.names());
        assert_eq!(back.labels(), set.labels());
        let bits = |s: &MeshSet| {
            s.positions()
                .iter()
                .flatten()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&back), bits(&set));
    }

    #[test]
    fn corrupt_caches_are_errors() {
        let set = small_set();
        let path =
            std::env::temp_dir().join(format!("mesh-io-cache-c-{}.mvset", std::process::id()));
        write_cache(&path, &set).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        for cut in [0, 7, 8, 50, bytes.len() - 1] {
            assert!(
                parse_cache(&bytes[..cut], &path).is_err(),
                "truncated at {cut}"
            );
        }
        assert!(parse_cache(b"not a cache at all", &path).is_err());
    }
}
