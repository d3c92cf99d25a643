//! Saving and loading a model's variables: one safetensors file with every trainable and state
//! tensor, and the model's configuration (JSON) in the header's `__metadata__`, so that weights
//! of another configuration are refused by name rather than by a shape accident.
//!
//! The file is written by hand (the format is an 8-byte little-endian header length, a JSON
//! header, then the raw little-endian data) so that it goes through
//! `mesh_io::atomic::write_atomic`; it is read back with candle's safetensors loader.

use super::MeshVae;
use crate::config::ModelConfig;
use crate::error::{Result, VaeError};
use candle_core::{DType, Tensor};
use serde_json::{Map, Value, json};
use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::Path;

/// `__metadata__.format` of our weight files.
pub const WEIGHTS_FORMAT: &str = "meshvae-weights";

impl MeshVae {
    /// Copies of every variable (trainable and state), by name. Copies: later training steps
    /// do not change them.
    pub fn tensors(&self) -> Result<BTreeMap<String, Tensor>> {
        self.trainable
            .iter()
            .chain(&self.state)
            .map(|(n, v)| Ok((n.clone(), v.as_tensor().copy()?)))
            .collect()
    }

    /// Sets every variable from `tensors` (converted to the model's dtype). All names and shapes
    /// are checked before anything is changed; a missing, extra or misshapen tensor is a
    /// [`VaeError::Model`] naming `origin` and the tensor.
    pub fn set_tensors(&mut self, tensors: &HashMap<String, Tensor>, origin: &Path) -> Result<()> {
        let ours: BTreeMap<&String, _> = self.trainable.iter().chain(&self.state).collect();
        let mut problems = Vec::new();
        for (name, v) in &ours {
            match tensors.get(*name) {
                None => problems.push(format!("missing tensor {name}")),
                Some(t) if t.dims() != v.dims() => problems.push(format!(
                    "tensor {name} has shape {:?}, the model needs {:?}",
                    t.dims(),
                    v.dims()
                )),
                Some(t) if !t.dtype().is_float() => {
                    problems.push(format!("tensor {name} is {:?}, not a float", t.dtype()))
                }
                Some(_) => {}
            }
        }
        let mut extra: Vec<&String> = tensors.keys().filter(|n| !ours.contains_key(n)).collect();
        extra.sort();
        problems.extend(extra.iter().map(|n| format!("unexpected tensor {n}")));
        if !problems.is_empty() {
            let shown = problems.len().min(5);
            let more = if problems.len() > shown {
                format!(" (and {} more)", problems.len() - shown)
            } else {
                String::new()
            };
            return Err(VaeError::model(
                origin,
                format!(
                    "weights do not fit the model: {}{more}",
                    problems[..shown].join("; ")
                ),
            ));
        }
        for (name, v) in ours {
            let t = &tensors[name];
            v.set(&t.to_dtype(self.dtype)?.to_device(&self.device)?)?;
        }
        Ok(())
    }

    /// Writes every variable and the configuration to `path` (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        self.save_snapshot(&self.tensors()?, path)
    }

    /// Writes `tensors` (taken earlier by [`Self::tensors`], e.g. the best epoch's) as this
    /// model's weights file.
    pub fn save_snapshot(&self, tensors: &BTreeMap<String, Tensor>, path: &Path) -> Result<()> {
        let config = serde_json::to_string(&self.config)
            .map_err(|e| VaeError::model(path, format!("config to JSON: {e}")))?;
        let bytes = serialize(tensors, &config)?;
        mesh_io::atomic::write_atomic(path, |w| w.write_all(&bytes))?;
        Ok(())
    }

    /// Reads weights written by [`Self::save`] for the same configuration and vertex counts.
    /// Nothing is changed on error.
    pub fn load(&mut self, path: &Path) -> Result<()> {
        let data = std::fs::read(path).map_err(|e| VaeError::io(path, e))?;
        let saved = read_config(&data).map_err(|what| VaeError::model(path, what))?;
        if saved != self.config {
            return Err(VaeError::model(
                path,
                format!(
                    "weights of another configuration ({}); the model is {}",
                    config_diff(&saved, &self.config),
                    serde_json::to_string(&self.config).unwrap_or_default()
                ),
            ));
        }
        let tensors = candle_core::safetensors::load_buffer(&data, &self.device)
            .map_err(|e| VaeError::model(path, format!("not a readable safetensors file: {e}")))?;
        self.set_tensors(&tensors, path)
    }
}

/// The safetensors bytes of `tensors` (f32/f64), with `config` in the metadata.
fn serialize(tensors: &BTreeMap<String, Tensor>, config: &str) -> Result<Vec<u8>> {
    let mut header = Map::new();
    header.insert(
        "__metadata__".into(),
        json!({ "format": WEIGHTS_FORMAT, "config": config }),
    );
    let mut data = Vec::new();
    for (name, t) in tensors {
        let start = data.len();
        let flat = t.flatten_all()?;
        let dtype = match t.dtype() {
            DType::F64 => {
                for x in flat.to_vec1::<f64>()? {
                    data.extend_from_slice(&x.to_le_bytes());
                }
                "F64"
            }
            _ => {
                for x in flat.to_dtype(DType::F32)?.to_vec1::<f32>()? {
                    data.extend_from_slice(&x.to_le_bytes());
                }
                "F32"
            }
        };
        header.insert(
            name.clone(),
            json!({ "dtype": dtype, "shape": t.dims(), "data_offsets": [start, data.len()] }),
        );
    }
    let mut head = serde_json::to_vec(&Value::Object(header))
        .map_err(|e| VaeError::shape("MeshVae::save", e.to_string()))?;
    // The data starts 8-aligned (the format's recommendation): pad the header with spaces.
    while head.len() % 8 != 0 {
        head.push(b' ');
    }
    let mut out = Vec::with_capacity(8 + head.len() + data.len());
    out.extend_from_slice(&(head.len() as u64).to_le_bytes());
    out.extend_from_slice(&head);
    out.extend_from_slice(&data);
    Ok(out)
}

/// The configuration stored in a weight file's metadata.
fn read_config(data: &[u8]) -> std::result::Result<ModelConfig, String> {
    let len = data
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as usize)
        .ok_or("too short for a safetensors file")?;
    let head = data
        .get(8..8usize.saturating_add(len))
        .ok_or("truncated safetensors header")?;
    let header: Value =
        serde_json::from_slice(head).map_err(|e| format!("unreadable safetensors header: {e}"))?;
    let meta = &header["__metadata__"];
    if meta["format"] != WEIGHTS_FORMAT {
        return Err(format!(
            "not a meshvae weight file (no \"format\": \"{WEIGHTS_FORMAT}\" in its metadata)"
        ));
    }
    let config = meta["config"]
        .as_str()
        .ok_or("no model config in the metadata")?;
    serde_json::from_str(config).map_err(|e| format!("unreadable model config: {e}"))
}

/// "field: saved → ours" for every field that differs.
fn config_diff(saved: &ModelConfig, ours: &ModelConfig) -> String {
    let (Ok(Value::Object(a)), Ok(Value::Object(b))) =
        (serde_json::to_value(saved), serde_json::to_value(ours))
    else {
        return "unknown difference".into();
    };
    let diffs: Vec<String> = a
        .iter()
        .filter(|(k, v)| b.get(*k) != Some(v))
        .map(|(k, v)| format!("{k}: {v} there, {} here", b.get(k).unwrap_or(&Value::Null)))
        .collect();
    diffs.join(", ")
}
