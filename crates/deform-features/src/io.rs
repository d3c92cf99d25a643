//! Features files: safetensors with the feature array, optionally the rest mesh, and the
//! normalisation and frame names as metadata. Written atomically.
//!
//! Tensors: `features` F32 [N, V, 9] (normalised when metadata `normalized` = `true`);
//! optional `rest_positions` F32 [V, 3] and `faces` U32 [F, 3] (enough to reconstruct).
//! Metadata (all strings): the `mesh_io::stamped` convention (`format` = `meshvae-features`,
//! `version` = `2`, `writer`, `checksum` of the tensor bytes, verified on reading),
//! `channels` (comma-separated channel names, see [`crate::CHANNEL_NAMES`]), `normalized`,
//! `normalization` (JSON of [`Normalization`]), `names` (JSON array of frame names), plus any
//! extra entries given. Files of version 1 (`format` = `meshvae-features/1`) still load.

use crate::error::FeatureError;
use crate::features::{CHANNEL_NAMES, CHANNELS, FeatureSet};
use crate::normalize::Normalization;
use mesh_io::MeshIoError;
use mesh_io::stamped::{Dtype, Entry, Stamp, f32_bytes, read_stamped, u32_bytes, write_stamped};
use mesh_io::{Face, Point};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// What a features file's metadata says it is.
pub const STAMP: Stamp = Stamp {
    format: "meshvae-features",
    version: 2,
};

/// Metadata entries of the convention, not returned among [`FeatureFile::extra`].
const CONVENTION: [&str; 4] = ["format", "version", "writer", "checksum"];

/// Everything a features file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureFile {
    pub features: FeatureSet,
    /// Whether `features` are normalised (then `normalization` maps them back).
    pub normalized: bool,
    pub normalization: Option<Normalization>,
    /// One name per frame.
    pub names: Vec<String>,
    /// The rest mesh the features are relative to, if stored.
    pub rest_positions: Option<Vec<Point>>,
    pub faces: Option<Vec<Face>>,
    /// Other metadata entries (e.g. the feature options as JSON).
    pub extra: HashMap<String, String>,
}

/// Writes `file` to `path` (temporary file + rename).
pub fn save_features(path: &Path, file: &FeatureFile) -> Result<(), FeatureError> {
    let fs = &file.features;
    if file.names.len() != fs.frames() {
        return Err(FeatureError::shape(
            "frame names",
            fs.frames(),
            file.names.len(),
        ));
    }
    if file.normalized && file.normalization.is_none() {
        return Err(FeatureError::input(
            "features file",
            "normalised features need their normalisation",
        ));
    }
    let mut metadata: BTreeMap<String, String> = file
        .extra
        .iter()
        .filter(|(k, _)| !CONVENTION.contains(&k.as_str()))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    metadata.insert("channels".into(), CHANNEL_NAMES.join(","));
    metadata.insert("normalized".into(), file.normalized.to_string());
    if let Some(n) = &file.normalization {
        metadata.insert("normalization".into(), n.to_json());
    }
    let names = serde_json::to_string(&file.names)
        .map_err(|e| FeatureError::input("frame names", e.to_string()))?;
    metadata.insert("names".into(), names);

    let mut entries = vec![Entry::new(
        "features",
        Dtype::F32,
        vec![fs.frames(), fs.vertices(), CHANNELS],
        f32_bytes(fs.as_slice()),
    )];
    if let Some(p) = &file.rest_positions {
        if p.len() != fs.vertices() {
            return Err(FeatureError::shape(
                "rest positions",
                fs.vertices(),
                p.len(),
            ));
        }
        let flat: Vec<f32> = p.iter().flatten().copied().collect();
        entries.push(Entry::new(
            "rest_positions",
            Dtype::F32,
            vec![p.len(), 3],
            f32_bytes(&flat),
        ));
    }
    if let Some(f) = &file.faces {
        let flat: Vec<u32> = f.iter().flatten().copied().collect();
        entries.push(Entry::new(
            "faces",
            Dtype::U32,
            vec![f.len(), 3],
            u32_bytes(&flat),
        ));
    }
    write_stamped(path, STAMP, metadata, entries).map_err(format_error)
}

/// A damaged, foreign or newer file is a [`FeatureError::Format`] naming it.
fn format_error(e: MeshIoError) -> FeatureError {
    match e {
        MeshIoError::Tensors { path, message } => FeatureError::Format { path, message },
        other => FeatureError::MeshIo(other),
    }
}

/// Reads a file written by [`save_features`].
pub fn load_features(path: &Path) -> Result<FeatureFile, FeatureError> {
    let bytes = std::fs::read(path).map_err(|source| FeatureError::Io {
        path: path.into(),
        source,
    })?;
    let bad = |message: String| FeatureError::Format {
        path: path.into(),
        message,
    };
    let file = read_stamped(&bytes, path, STAMP).map_err(format_error)?;
    let tensors = &file.tensors;
    let mut extra: HashMap<String, String> = file
        .metadata
        .into_iter()
        .filter(|(k, _)| !CONVENTION.contains(&k.as_str()))
        .collect();
    extra.remove("channels");
    let normalized = match extra.remove("normalized").as_deref() {
        Some("true") => true,
        Some("false") | None => false,
        Some(other) => return Err(bad(format!("metadata normalized = {other:?}"))),
    };
    let normalization = match extra.remove("normalization") {
        Some(text) => Some(Normalization::from_json(&text).map_err(|e| bad(e.to_string()))?),
        None if normalized => return Err(bad("normalised features without normalization".into())),
        None => None,
    };

    let features = tensors.tensor("features").map_err(|e| bad(e.to_string()))?;
    let shape = features.shape().to_vec();
    if features.dtype() != Dtype::F32 || shape.len() != 3 || shape[2] != CHANNELS {
        return Err(bad(format!(
            "tensor features is {:?} {shape:?}, expected F32 [N, V, {CHANNELS}]",
            features.dtype()
        )));
    }
    let data = read_f32(features.data());
    let features = FeatureSet::new(shape[0], shape[1], data).map_err(|e| bad(e.to_string()))?;

    let names: Vec<String> = match extra.remove("names") {
        Some(text) => serde_json::from_str(&text).map_err(|e| bad(format!("names: {e}")))?,
        None => (0..features.frames()).map(|i| i.to_string()).collect(),
    };
    if names.len() != features.frames() {
        return Err(bad(format!(
            "{} names for {} frames",
            names.len(),
            features.frames()
        )));
    }
    let rest_positions = match tensors.tensor("rest_positions") {
        Ok(t) if t.dtype() == Dtype::F32 && t.shape() == [features.vertices(), 3] => {
            let flat = read_f32(t.data());
            Some(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        }
        Ok(t) => {
            return Err(bad(format!(
                "tensor rest_positions is {:?} {:?}",
                t.dtype(),
                t.shape()
            )));
        }
        Err(_) => None,
    };
    let faces = match tensors.tensor("faces") {
        Ok(t) if t.dtype() == Dtype::U32 && t.shape().len() == 2 && t.shape()[1] == 3 => {
            let flat: Vec<u32> = t
                .data()
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            Some(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        }
        Ok(t) => {
            return Err(bad(format!(
                "tensor faces is {:?} {:?}",
                t.dtype(),
                t.shape()
            )));
        }
        Err(_) => None,
    };
    Ok(FeatureFile {
        features,
        normalized,
        normalization,
        names,
        rest_positions,
        faces,
        extra,
    })
}

fn read_f32(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> mesh_io::scratch::ScratchFile {
        mesh_io::scratch::ScratchFile::new("deform-features-io", name).unwrap()
    }

    fn sample() -> FeatureFile {
        let data: Vec<f32> = (0..2 * 3 * 9).map(|x| x as f32 * 0.01 - 0.2).collect();
        FeatureFile {
            features: FeatureSet::new(2, 3, data).unwrap(),
            normalized: true,
            normalization: Some(Normalization {
                rotation_min: -1.0,
                rotation_max: 2.0,
                scale_min: -0.5,
                scale_max: 1.5,
                clamp: None,
            }),
            names: vec!["a".into(), "b".into()],
            rest_positions: Some(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]),
            faces: Some(vec![[0, 1, 2]]),
            extra: HashMap::from([("options".to_string(), "{}".to_string())]),
        }
    }

    #[test]
    fn save_then_load_is_identity() {
        let path = temp("round.safetensors");
        let file = sample();
        save_features(&path, &file).unwrap();
        assert_eq!(load_features(&path).unwrap(), file);
        let minimal = FeatureFile {
            normalized: false,
            normalization: None,
            rest_positions: None,
            faces: None,
            extra: HashMap::new(),
            ..file
        };
        save_features(&path, &minimal).unwrap();
        assert_eq!(load_features(&path).unwrap(), minimal);
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn a_damaged_file_is_refused_naming_it() {
        let path = temp("damaged.safetensors");
        save_features(&path, &sample()).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 30;
        bytes[last] ^= 1;
        std::fs::write(&path, bytes).unwrap();
        let err = load_features(&path).unwrap_err();
        assert!(matches!(err, FeatureError::Format { .. }));
        let text = err.to_string();
        assert!(
            text.contains("damaged.safetensors") && text.contains("checksum"),
            "{text}"
        );
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn bad_files_are_format_errors() {
        let path = temp("bad.safetensors");
        std::fs::write(&path, b"not a safetensors file").unwrap();
        assert!(matches!(
            load_features(&path),
            Err(FeatureError::Format { .. })
        ));
        // A valid safetensors file without our metadata.
        let bytes = safetensors::serialize(
            [(
                "x",
                safetensors::tensor::TensorView::new(Dtype::F32, vec![1], &[0, 0, 0, 0]).unwrap(),
            )],
            None,
        )
        .unwrap();
        std::fs::write(&path, bytes).unwrap();
        assert!(matches!(
            load_features(&path),
            Err(FeatureError::Format { .. })
        ));
        assert!(matches!(
            load_features(&temp("missing")),
            Err(FeatureError::Io { .. })
        ));
        // Inconsistent input is refused before anything is written.
        let mut file = sample();
        file.names.pop();
        assert!(save_features(&path, &file).is_err());
        std::fs::remove_file(&path).unwrap();
    }
}
