//! The `.mvset` cache: a whole [`MeshSet`] in one safetensors file.
//!
//! Tensors: `positions` F32 [N, V, 3] and `faces` U32 [F, 3]. Metadata: the [`crate::stamped`]
//! convention (`format` = `meshvae-set`, `version` = `2`, `writer`, `checksum` of the tensor
//! bytes), `names` (JSON array) and, for labelled sets, `labels` (JSON array). Written
//! atomically; loading verifies the checksum (a damaged cache is refused, naming the file) and
//! checks shapes, indices and finiteness like any reader. Version-1 caches (no checksum) still
//! load.

use crate::error::{MeshIoError, Result};
use crate::mesh::{Face, MeshSet, Point};
use crate::stamped::{Dtype, Entry, Stamp, f32_bytes, read_stamped, u32_bytes, write_stamped};
use std::collections::BTreeMap;
use std::path::Path;

/// What a cache's metadata says it is.
pub const STAMP: Stamp = Stamp {
    format: "meshvae-set",
    version: 2,
};

/// Writes `set` to `path` (conventionally `*.mvset`), atomically.
pub fn write_cache(path: &Path, set: &MeshSet) -> Result<()> {
    let mut metadata = BTreeMap::from([("names".to_string(), json(set.names()))]);
    if let Some(labels) = set.labels() {
        metadata.insert("labels".into(), json(labels));
    }
    let positions = Entry::lazy(
        "positions",
        Dtype::F32,
        vec![set.len(), set.vertex_count(), 3],
        || {
            let flat: Vec<f32> = set.positions().iter().flatten().copied().collect();
            Ok(f32_bytes(&flat).into())
        },
    );
    let flat_faces: Vec<u32> = set.faces().iter().flatten().copied().collect();
    let faces = Entry::new(
        "faces",
        Dtype::U32,
        vec![set.faces().len(), 3],
        u32_bytes(&flat_faces),
    );
    write_stamped(path, STAMP, metadata, vec![positions, faces])
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
    let file = read_stamped(bytes, path, STAMP)?;
    let meta = &file.metadata;
    let strings = |key: &str| -> Result<Option<Vec<String>>> {
        meta.get(key)
            .map(|s| serde_json::from_str(s).map_err(|e| bad(format!("metadata `{key}`: {e}"))))
            .transpose()
    };
    let names = strings("names")?.ok_or_else(|| bad("metadata has no `names`".into()))?;
    let labels = strings("labels")?;

    let tensors = &file.tensors;
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

    #[test]
    fn a_cache_with_one_flipped_position_byte_is_refused_naming_the_file() {
        let set = small_set();
        let path =
            std::env::temp_dir().join(format!("mesh-io-cache-f-{}.mvset", std::process::id()));
        write_cache(&path, &set).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        // A high bit of one coordinate: still a finite number, so only the checksum tells.
        let (n, _) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
        bytes[8 + n + 5] ^= 0x04;
        let err = parse_cache(&bytes, &path).unwrap_err().to_string();
        assert!(
            err.contains("mesh-io-cache-f-") && err.contains("checksum"),
            "{err}"
        );
    }

    #[test]
    fn version_1_caches_without_a_checksum_still_load() {
        let set = small_set();
        let flat: Vec<f32> = set.positions().iter().flatten().copied().collect();
        let pos = f32_bytes(&flat);
        let faces = u32_bytes(&set.faces().iter().flatten().copied().collect::<Vec<_>>());
        let views = [
            (
                "positions",
                safetensors::tensor::TensorView::new(Dtype::F32, vec![3, 4, 3], &pos).unwrap(),
            ),
            (
                "faces",
                safetensors::tensor::TensorView::new(Dtype::U32, vec![2, 3], &faces).unwrap(),
            ),
        ];
        let meta = std::collections::HashMap::from([
            ("format".to_string(), "meshvae-set".to_string()),
            ("version".to_string(), "1".to_string()),
            ("names".to_string(), json(set.names())),
        ]);
        let bytes = safetensors::serialize(views, Some(meta)).unwrap();
        let back = parse_cache(&bytes, Path::new("old.mvset")).unwrap();
        assert_eq!(back.positions(), set.positions());
    }
}
