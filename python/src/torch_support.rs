//! What `meshvae.torch` needs from a model folder that the public API does not give: the loaded
//! weights by name, the hierarchy and normalisation the folder holds, the network's scaled
//! inputs of meshes, writing a weights file that `meshvae` reads, and one training step of the
//! CPU engine (to check torch's step against). Private functions (`_torch_*`), called by
//! `meshvae/torch/` only; every computation is the crate's.

use crate::arrays::{self, array};
use crate::errors::{input, to_py};
use crate::features::Normalization;
use crate::hierarchy::Hierarchy;
use crate::model::Model;
use candle_core::{DType, Device, Tensor};
use meshvae::{Adam, AdamConfig, EngineExecutor, InputScaling, LossWeights, VaeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

fn candle_err(e: candle_core::Error) -> PyErr {
    to_py(VaeError::from(e))
}

/// A tensor as a numpy array of its shape: float64 for an f64 tensor, float32 otherwise.
fn to_numpy<'py>(py: Python<'py>, t: &Tensor) -> PyResult<Bound<'py, PyAny>> {
    let flat = t.flatten_all().map_err(candle_err)?;
    if t.dtype() == DType::F64 {
        let values = flat.to_vec1::<f64>().map_err(candle_err)?;
        return Ok(array(py, values, t.dims())?.into_any());
    }
    let values = (flat.to_dtype(DType::F32))
        .and_then(|t| t.to_vec1::<f32>())
        .map_err(candle_err)?;
    Ok(array(py, values, t.dims())?.into_any())
}

/// A float array as a CPU tensor of its shape and `dtype` (F32 or F64).
fn to_tensor(obj: &Bound<'_, PyAny>, name: &str, dtype: DType) -> PyResult<Tensor> {
    if dtype == DType::F64 {
        let (values, shape) = arrays::floats64(obj, name)?;
        return Tensor::from_vec(values, shape.as_slice(), &Device::Cpu).map_err(candle_err);
    }
    let (values, shape) = arrays::floats(obj, name)?;
    Tensor::from_vec(values, shape.as_slice(), &Device::Cpu).map_err(candle_err)
}

/// Tensors by name as a dict of numpy arrays (see [`to_numpy`]).
fn tensors_dict<'py>(
    py: Python<'py>,
    tensors: &BTreeMap<String, Tensor>,
) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    for (name, t) in tensors {
        dict.set_item(name, to_numpy(py, t)?)?;
    }
    Ok(dict)
}

/// A dict of float arrays as tensors by name, checked against the model's variables: the same
/// names, every one present, the same shapes.
fn model_tensors(
    model: &Model,
    tensors: &Bound<'_, PyDict>,
    dtype: DType,
) -> PyResult<HashMap<String, Tensor>> {
    let reference = model.trained().model.tensors().map_err(to_py)?;
    let mut out = HashMap::new();
    let mut problems = Vec::new();
    for (key, value) in tensors.iter() {
        let name: String = key.extract()?;
        let t = to_tensor(&value, &name, dtype)?;
        match reference.get(&name) {
            None => problems.push(format!("unexpected tensor {name}")),
            Some(r) if r.dims() != t.dims() => problems.push(format!(
                "tensor {name} has shape {:?}, the model needs {:?}",
                t.dims(),
                r.dims()
            )),
            Some(_) => {}
        }
        out.insert(name, t);
    }
    problems.extend(
        (reference.keys())
            .filter(|n| !out.contains_key(*n))
            .map(|n| format!("missing tensor {n}")),
    );
    if !problems.is_empty() {
        return Err(input(format!(
            "tensors do not fit the model: {}",
            problems.join("; ")
        )));
    }
    Ok(out)
}

/// The model's variables (trained and batch-norm state, the weights it loaded) as float32
/// arrays by name, its hierarchy, and its normalisation (None for a position network).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn _torch_model_state<'py>(
    py: Python<'py>,
    model: &Model,
) -> PyResult<(Bound<'py, PyDict>, Hierarchy, Option<Normalization>)> {
    let trained = model.trained();
    let tensors = trained.model.tensors().map_err(to_py)?;
    let normalization = match &trained.normalization {
        InputScaling::Features(n) => Some(Normalization::from_inner(*n)),
        InputScaling::Positions(_) => None,
    };
    Ok((
        tensors_dict(py, &tensors)?,
        Hierarchy::from_inner(trained.hierarchy.clone()),
        normalization,
    ))
}

/// The network's input of meshes with the model's connectivity (positions float [N, V, 3]):
/// ACAP features relative to the model's template with its feature options, normalised as the
/// model's normalization.json says (what `meshvae` feeds the encoder), float32 [N, V, 9].
#[pyfunction]
pub fn _torch_model_inputs<'py>(
    py: Python<'py>,
    model: &Model,
    positions: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let trained = model.trained();
    let v = trained.spec.vertices;
    let (values, shape) = arrays::floats(positions, "positions")?;
    let n = match shape[..] {
        [n, rows, 3] if rows == v && n > 0 => n,
        _ => {
            return Err(input(format!(
                "positions: expected shape [N, {v}, 3] (the model's meshes have {v} vertices), \
                 got {shape:?}"
            )));
        }
    };
    let points = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let names = (0..n).map(|i| i.to_string()).collect();
    let set = mesh_io::MeshSet::from_flat(trained.template.faces.clone(), v, points, names)
        .map_err(to_py)?;
    trained
        .spec
        .check_set(&set, &trained.template, &trained.folder.dir)
        .map_err(to_py)?;
    let x = py
        .detach(|| {
            let extractor = trained.extractor()?;
            let ids: Vec<usize> = (0..n).collect();
            trained.encode_input(&extractor, &set, &ids, &Device::Cpu)
        })
        .map_err(to_py)?;
    to_numpy(py, &x)
}

/// Writes `tensors` (float arrays by name: every variable of the model, no other) as a weights
/// file `meshvae` reads for this model's configuration (names, shapes, f32, metadata: format
/// stamp, checksum, config, tied, layout; `epoch` if given), atomically.
#[pyfunction]
#[pyo3(signature = (model, path, tensors, epoch=None))]
pub fn _torch_write_weights(
    py: Python<'_>,
    model: &Model,
    path: PathBuf,
    tensors: &Bound<'_, PyDict>,
    epoch: Option<usize>,
) -> PyResult<()> {
    let trained = model.trained();
    let tensors: BTreeMap<String, Tensor> = model_tensors(model, tensors, DType::F32)?
        .into_iter()
        .collect();
    py.detach(|| trained.model.save_snapshot(&tensors, &path, epoch))
        .map_err(to_py)
}

/// One training step of the CPU engine (what `meshvae train` runs on the CPU) on a copy of
/// the model set to `tensors`: train-mode forward and backward on features `x` [B, V, 9] with
/// noise `eps` [B, latent] (and one-hot `labels` [B, L] for a conditional model), then Adam
/// from zero moments (`lr`, `betas`, `adam_eps`, no rate scaling, no clipping) with the L2
/// term's gradient. Returns `(total, rec, kl, l2)` (weighted by `loss_weights` = (rec, kl,
/// l2); the L2 term of the weights before the step), every variable after the step, and the
/// gradient of rec + kl (the L2 term's, w_l2 · θ, is Adam's to add) of every trained variable.
/// `double` runs the engine in f64 (inputs read, results returned as float64), which takes
/// rounding out of a comparison with another implementation.
#[pyfunction]
#[pyo3(signature = (model, tensors, x, eps, labels, lr, betas, adam_eps, loss_weights, double=false))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn _torch_engine_step<'py>(
    py: Python<'py>,
    model: &Model,
    tensors: &Bound<'py, PyDict>,
    x: &Bound<'py, PyAny>,
    eps: &Bound<'py, PyAny>,
    labels: Option<&Bound<'py, PyAny>>,
    lr: f64,
    betas: (f64, f64),
    adam_eps: f64,
    loss_weights: (f64, f64, f64),
    double: bool,
) -> PyResult<((f64, f64, f64, f64), Bound<'py, PyDict>, Bound<'py, PyDict>)> {
    let trained = model.trained();
    let dtype = if double { DType::F64 } else { DType::F32 };
    let tensors = model_tensors(model, tensors, dtype)?;
    let x = to_tensor(x, "x", dtype)?;
    let eps = to_tensor(eps, "eps", dtype)?;
    let labels = labels.map(|l| to_tensor(l, "labels", dtype)).transpose()?;
    let batch = x.dims().first().copied().unwrap_or(0);
    let (terms, after, grads) = py
        .detach(|| -> meshvae::Result<_> {
            let spec = &trained.spec;
            let mut net = meshvae::MeshVae::with_dtype(
                &spec.model,
                &trained.hierarchy,
                &Device::Cpu,
                dtype,
                spec.train.seed,
            )?;
            net.set_tensors(&tensors, &trained.folder.dir)?;
            let mut engine = EngineExecutor::new(&net, batch.max(1))?;
            let config = AdamConfig {
                lr,
                beta1: betas.0,
                beta2: betas.1,
                eps: adam_eps,
            };
            let mut adam = Adam::with_config(net.trainable_vars(), config)?;
            let weights = LossWeights {
                rec: loss_weights.0,
                kl: loss_weights.1,
                l2: loss_weights.2,
            };
            // What `Executor::step` does, with the gradients taken in between.
            let loss = engine.forward_backward(&net, &x, labels.as_ref(), &eps, &weights)?;
            let grads: BTreeMap<String, Tensor> = engine.gradients(&net)?.into_iter().collect();
            let l2 = engine.apply_adam(&mut adam, weights.l2)?;
            let terms = (loss.rec + loss.kl + l2, loss.rec, loss.kl, l2);
            Ok((terms, net.tensors()?, grads))
        })
        .map_err(to_py)?;
    Ok((terms, tensors_dict(py, &after)?, tensors_dict(py, &grads)?))
}
