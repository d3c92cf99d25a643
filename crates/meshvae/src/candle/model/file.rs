//! Saving and loading a model's variables: one safetensors file with every trainable and state
//! tensor, and in the header's `__metadata__` the `mesh_io::stamped` convention (`format` =
//! `meshvae-weights`, `version`, `writer`, `checksum`, verified on loading), the model's
//! configuration (`config`, JSON), so that weights of another configuration are refused by name
//! rather than by a shape accident, and what the names alone do not say: `tied` (JSON: each
//! weight the file does not hold because it is another tensor reused) and `layout` (how the
//! tensors are named and shaped).

use super::MeshVae;
use crate::error::{Result, VaeError};
use crate::net::config::ModelConfig;
use candle_core::{DType, Tensor};
use mesh_io::stamped::{
    Dtype, Entry, Stamp, f32_bytes, f64_bytes, read_stamped, u32_bytes, write_stamped,
};
use serde_json::{Value, json};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// What a weights file's metadata says it is (version 1: before the checksum, `tied` and
/// `layout`).
pub const WEIGHTS_STAMP: Stamp = Stamp {
    format: "meshvae-weights",
    version: 2,
};

/// The `layout` metadata entry of every weights file.
pub const WEIGHTS_LAYOUT: &str = "encoder convolution i: enc.conv{i}.weight [C_in*K, C_out], \
    row c*K + k for input channel c and Chebyshev order k (spectral), or enc.conv{i}.w_self and \
    enc.conv{i}.w_nb [C_in, C_out] (spatial); its batch norm enc.bn{i}.gamma, beta (trained) and \
    running_mean, running_var (statistics) [C_out]; dense heads enc.mu.weight and \
    enc.sigma.weight [V_L*C, latent] on the coarsest level flattened vertex-major (vertex v, \
    channel c at v*C + c), enc.mu.bias and enc.sigma.bias [latent]; decoder dense bias \
    dec.fc.bias [V_L*C]; decoder layer i mirrors encoder convolution i: dec.conv{i}.*, \
    dec.bn{i}.*; conditional models add enc.mu.label_weight and enc.sigma.label_weight \
    [labels, latent] and dec.fc.label_weight [labels, V_L*C]";

impl MeshVae {
    /// Copies of every variable (trainable and state), by name. Copies: later training steps
    /// do not change them.
    pub fn tensors(&self) -> Result<BTreeMap<String, Tensor>> {
        self.named_vars()
            .map(|(n, v)| Ok((n.clone(), v.as_tensor().copy()?)))
            .collect()
    }

    /// Sets every variable from `tensors` (converted to the model's dtype). All names and shapes
    /// are checked before anything is changed; a missing, extra or misshapen tensor is a
    /// [`VaeError::Model`] naming `origin` and the tensor.
    pub fn set_tensors(&mut self, tensors: &HashMap<String, Tensor>, origin: &Path) -> Result<()> {
        let ours: BTreeMap<&String, _> = self.named_vars().collect();
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
        self.save_snapshot(&self.tensors()?, path, None)
    }

    /// Writes `tensors` (taken earlier by [`Self::tensors`], e.g. the best epoch's) as this
    /// model's weights file; `epoch`, the training epoch they are from, goes into the metadata
    /// (`epoch`), where a checkpoint finds the weights it continues from.
    pub fn save_snapshot(
        &self,
        tensors: &BTreeMap<String, Tensor>,
        path: &Path,
        epoch: Option<usize>,
    ) -> Result<()> {
        let config = serde_json::to_string(&self.config)
            .map_err(|e| VaeError::model(path, format!("config to JSON: {e}")))?;
        let mut metadata = BTreeMap::from([
            ("config".to_string(), config),
            ("tied".to_string(), tied_json(&self.config)),
            ("layout".to_string(), WEIGHTS_LAYOUT.to_string()),
        ]);
        if let Some(epoch) = epoch {
            metadata.insert(EPOCH_KEY.to_string(), epoch.to_string());
        }
        write_stamped(path, WEIGHTS_STAMP, metadata, entries(tensors))?;
        Ok(())
    }

    /// Reads weights written by [`Self::save`] for the same configuration and vertex counts.
    /// Nothing is changed on error.
    pub fn load(&mut self, path: &Path) -> Result<()> {
        self.load_epoch(path).map(|_| ())
    }

    /// As [`Self::load`], and returns the training epoch the file says the weights are from
    /// (`None` for weights saved outside training, or before files said so).
    pub fn load_epoch(&mut self, path: &Path) -> Result<Option<usize>> {
        let data = std::fs::read(path).map_err(|e| VaeError::io(path, e))?;
        let file = read_stamped(&data, path, WEIGHTS_STAMP).map_err(stamped_error)?;
        let epoch = match file.metadata.get(EPOCH_KEY) {
            None => None,
            Some(text) => Some(text.parse::<usize>().map_err(|_| {
                VaeError::model(path, format!("unreadable epoch {text:?} in the metadata"))
            })?),
        };
        let saved = read_config(&file.metadata).map_err(|what| VaeError::model(path, what))?;
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
        self.set_tensors(&tensors, path)?;
        Ok(epoch)
    }
}

/// The metadata entry of a weights file written by training: the epoch of the weights.
pub const EPOCH_KEY: &str = "epoch";

/// The tensors as lazily converted entries, so that a big model is never twice in memory as
/// bytes.
pub(crate) fn entries(tensors: &BTreeMap<String, Tensor>) -> Vec<Entry<'_>> {
    tensors.iter().map(|(name, t)| entry(name, t)).collect()
}

/// One tensor as an entry converted when written: f64, i64 and u32 keep their type, every other
/// float is written as f32.
pub(crate) fn entry<'a>(name: &str, t: &'a Tensor) -> Entry<'a> {
    let dtype = match t.dtype() {
        DType::F64 => Dtype::F64,
        DType::I64 => Dtype::I64,
        DType::U32 => Dtype::U32,
        _ => Dtype::F32,
    };
    Entry::lazy(name, dtype, t.dims().to_vec(), move || {
        let flat = t.flatten_all().map_err(|e| e.to_string())?;
        let bytes: Vec<u8> = match dtype {
            Dtype::F64 => f64_bytes(&flat.to_vec1::<f64>().map_err(|e| e.to_string())?),
            Dtype::I64 => flat
                .to_vec1::<i64>()
                .map_err(|e| e.to_string())?
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            Dtype::U32 => u32_bytes(&flat.to_vec1::<u32>().map_err(|e| e.to_string())?),
            _ => {
                let flat = flat.to_dtype(DType::F32).map_err(|e| e.to_string())?;
                f32_bytes(&flat.to_vec1::<f32>().map_err(|e| e.to_string())?)
            }
        };
        Ok(bytes.into())
    })
}

/// A damaged, foreign or newer file is a [`VaeError::Model`] naming it.
pub(crate) fn stamped_error(e: mesh_io::MeshIoError) -> VaeError {
    match e {
        mesh_io::MeshIoError::Tensors { path, message } => VaeError::model(path, message),
        other => other.into(),
    }
}

/// The `tied` metadata entry: weights the file does not hold, and which tensor stands for each.
pub(crate) fn tied_json(config: &ModelConfig) -> String {
    let mut tied = serde_json::Map::new();
    tied.insert(
        "dec.fc.weight".into(),
        json!("enc.mu.weight, transposed: the decoder's dense layer is z * enc.mu.weight^T + dec.fc.bias"),
    );
    if config.tie_decoder_convs {
        tied.insert(
            "dec.conv{i}.weight".into(),
            json!("the adjoint of enc.conv{i}.weight (decoder convolutions tied to the encoder's)"),
        );
    }
    Value::Object(tied).to_string()
}

/// The configuration stored in a weight file's metadata.
fn read_config(meta: &BTreeMap<String, String>) -> std::result::Result<ModelConfig, String> {
    let config = meta
        .get("config")
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
