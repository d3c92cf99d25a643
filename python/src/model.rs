//! A model trained by `meshvae train` (crate meshvae): `Model.load`, `encode`, `decode`.

use crate::arrays::{self, array};
use crate::errors::{Kind, input, raise, to_py};
use candle_core::{DType, Tensor};
use meshvae::{Mode, TrainedModel, VaeError};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Meshes (or latent vectors) per network call in `encode`, bounding memory on large N (as the
/// library's `reconstruct`, whose chunk this is; `decode_latents` chunks on its own).
const CHUNK: usize = 16;

/// The result of a network call: rows × width values.
type Rows = Vec<f32>;

/// A trained mesh VAE: its network (best weights), hierarchy, normalisation and template.
///
/// ``Model.load(folder)`` reads a folder written by ``meshvae train``. ``encode(positions)``
/// gives the posterior (μ, σ) of meshes with the model's connectivity; ``decode(z)`` gives
/// positions from latent vectors, both in inference mode (batch norm on its running
/// statistics), so ``decode(encode(x)[0])`` is what ``meshvae reconstruct`` writes.
/// A conditional model (trained with ``--labels``/``--conditional``) takes one label per mesh
/// or vector (``labels=``).
#[pyclass(module = "meshvae", frozen)]
pub struct Model {
    inner: TrainedModel,
}

impl Model {
    /// The loaded model folder (for `torch_support.rs`).
    pub(crate) fn trained(&self) -> &TrainedModel {
        &self.inner
    }

    /// The one-hot label rows `[B, L]` for a conditional model (`None` for an unconditional
    /// one), checking that labels are given exactly when the model needs them, one per row.
    fn conditions(&self, labels: Option<&[String]>, rows: usize) -> PyResult<Option<Tensor>> {
        let known = self.inner.model.labels();
        match labels {
            None if known.is_empty() => Ok(None),
            None => Err(input(format!(
                "labels: the model is conditional; give one label per mesh, one of {}",
                known.join(", ")
            ))),
            Some(_) if known.is_empty() => Err(input(
                "labels: the model is not conditional (trained without labels)",
            )),
            Some(l) if l.len() != rows => {
                Err(input(format!("labels: {} labels for {rows} rows", l.len())))
            }
            Some(l) => self.inner.model.one_hot(l).map(Some).map_err(to_py),
        }
    }

    fn encode_chunks(
        &self,
        set: &mesh_io::MeshSet,
        conditions: Option<&Tensor>,
    ) -> meshvae::Result<(Rows, Rows)> {
        let trained = &self.inner;
        let extractor = trained.extractor()?;
        let (mut mu, mut sigma) = (Vec::new(), Vec::new());
        let ids: Vec<usize> = (0..set.len()).collect();
        for chunk in ids.chunks(CHUNK) {
            let x = trained
                .encode_input(&extractor, set, chunk, &meshvae::default_device())?
                .to_dtype(trained.model.dtype())?;
            let c = conditions
                .map(|c| c.narrow(0, chunk[0], chunk.len()))
                .transpose()?;
            let encoded = trained.model.encode(&x, c.as_ref(), Mode::Eval)?;
            let flat = |t: &Tensor| -> meshvae::Result<Rows> {
                Ok(t.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?)
            };
            mu.extend(flat(&encoded.mu)?);
            sigma.extend(flat(&encoded.sigma)?);
        }
        Ok((mu, sigma))
    }
}

/// Positions `[N][V]` (f64, as the library returns them) as float32 values, frame-major.
fn flat_positions(meshes: Vec<Vec<[f64; 3]>>) -> Vec<f32> {
    meshes
        .iter()
        .flat_map(|m| m.as_flattened().iter().map(|&x| x as f32))
        .collect()
}

#[pymethods]
impl Model {
    /// Reads a model folder written by ``meshvae train`` (config.json, weights.safetensors,
    /// hierarchy.safetensors, normalization.json, split.json, template.obj) with its best weights.
    /// A missing folder raises :class:`FileError`; a foreign or inconsistent one
    /// :class:`InputError`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        if !path.exists() {
            return Err(raise(
                Kind::File,
                format!("{}: no such model folder", path.display()),
            ));
        }
        let inner = py
            .detach(|| TrainedModel::load(&path, &meshvae::default_device()))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// The posterior q(z|x) = N(μ, diag σ²) of meshes, inference mode.
    ///
    /// ``positions``: float [N, V, 3] (or [V, 3] for one mesh) with the model's connectivity
    /// (its template's vertex order and faces); ``labels``: for a conditional model, one label
    /// per mesh. Returns ``(mu, sigma)``, float32 [N, latent] each (or [latent]).
    #[pyo3(signature = (positions, labels=None))]
    #[allow(clippy::type_complexity)]
    fn encode<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        labels: Option<Vec<String>>,
    ) -> PyResult<(Bound<'py, PyArrayDyn<f32>>, Bound<'py, PyArrayDyn<f32>>)> {
        let v = self.inner.spec.vertices;
        let (values, shape) = arrays::floats(positions, "positions")?;
        let (n, single) = match shape[..] {
            [n, rows, 3] if rows == v && n > 0 => (n, false),
            [rows, 3] if rows == v => (1, true),
            _ => {
                return Err(input(format!(
                    "positions: expected shape [N, {v}, 3] or [{v}, 3] (the model's meshes \
                     have {v} vertices), got {shape:?}"
                )));
            }
        };
        let points = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
        let names = (0..n).map(|i| i.to_string()).collect();
        let set = mesh_io::MeshSet::from_flat(self.inner.template.faces.clone(), v, points, names)
            .map_err(to_py)?;
        self.inner
            .spec
            .check_set(&set, &self.inner.template, &self.inner.folder.dir)
            .map_err(to_py)?;
        let conditions = self.conditions(labels.as_deref(), n)?;
        let (mu, sigma) = py
            .detach(|| self.encode_chunks(&set, conditions.as_ref()))
            .map_err(to_py)?;
        let latent = self.inner.model.latent();
        let out_shape = if single {
            vec![latent]
        } else {
            vec![n, latent]
        };
        Ok((array(py, mu, &out_shape)?, array(py, sigma, &out_shape)?))
    }

    /// Positions decoded from latent vectors, inference mode: the decoder's features,
    /// de-normalised, then the ACAP Poisson solve (positioned at the template's centroid).
    ///
    /// ``z``: float [N, latent] (or [latent]); ``labels``: for a conditional model, one label
    /// per vector. Returns float32 [N, V, 3] (or [V, 3]).
    #[pyo3(signature = (z, labels=None))]
    fn decode<'py>(
        &self,
        py: Python<'py>,
        z: &Bound<'py, PyAny>,
        labels: Option<Vec<String>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let latent = self.inner.model.latent();
        let (values, shape) = arrays::floats(z, "z")?;
        let (n, single) = match shape[..] {
            [n, l] if l == latent && n > 0 => (n, false),
            [l] if l == latent => (1, true),
            _ => {
                return Err(input(format!(
                    "z: expected shape [N, {latent}] or [{latent}] (the model's latent size is \
                     {latent}), got {shape:?}"
                )));
            }
        };
        if let Some(i) = values.iter().position(|x| !x.is_finite()) {
            return Err(input(format!("z: row {} is not finite", i / latent)));
        }
        let latents: Vec<Vec<f32>> = values.chunks_exact(latent).map(<[f32]>::to_vec).collect();
        let conditions = self
            .conditions(labels.as_deref(), n)?
            .map(|c| c.to_dtype(DType::F32)?.to_vec2::<f32>())
            .transpose()
            .map_err(|e| to_py(VaeError::from(e)))?;
        let meshes = py
            .detach(|| self.inner.decode_latents(&latents, conditions.as_deref()))
            .map_err(to_py)?;
        let v = self.inner.spec.vertices;
        let out_shape = if single { vec![v, 3] } else { vec![n, v, 3] };
        array(py, flat_positions(meshes), &out_shape)
    }

    /// The model folder's config.json as a dict: ``model`` (structure, latent size, …),
    /// ``train``, ``features``, ``hierarchy``, and the training set's ``vertices``, ``faces``,
    /// ``names``, ``source`` (and ``labels`` of a conditional model).
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let text =
            serde_json::to_string(&self.inner.spec).map_err(|e| input(format!("config: {e}")))?;
        py.import("json")?
            .call_method1("loads", (text,))?
            .cast_into::<PyDict>()
            .map_err(Into::into)
    }

    /// Size of the latent vector z.
    #[getter]
    fn latent(&self) -> usize {
        self.inner.model.latent()
    }

    /// Vertices of the model's meshes.
    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.spec.vertices
    }

    /// int32 [F, 3]: the template's (every input mesh's) triangles.
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<i32>>> {
        arrays::faces_out(py, &self.inner.template.faces)
    }

    /// float32 [V, 3]: the template (rest mesh) the features are relative to.
    #[getter]
    fn template<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        arrays::points_out(py, self.inner.template.positions.clone())
    }

    /// The class labels of a conditional model, in one-hot order (empty: unconditional).
    #[getter]
    fn labels(&self) -> Vec<String> {
        self.inner.model.labels().to_vec()
    }

    /// The folder the model was loaded from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.folder.dir.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({:?}, latent={}, vertices={}, structure={})",
            self.inner.folder.dir.display().to_string(),
            self.inner.model.latent(),
            self.inner.spec.vertices,
            self.inner.spec.model.structure
        )
    }
}
