//! ACAP deformation features and their inverse (deform-features): `acap_features`,
//! `Normalization`, `reconstruct`, `load_features`.

use crate::arrays::{self, array};
use crate::errors::{input, to_py, warn_all};
use crate::mesh::MeshSet;
use deform_features::{
    CHANNELS, FeatureExtractor, FeatureOptions, FeatureSet, Reconstructor, RestMesh,
};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::path::PathBuf;

/// A frame of a set, by index or by name.
#[derive(FromPyObject)]
pub enum Frame {
    Index(usize),
    Name(String),
}

/// A float array whose last axis holds the 9 features, as a `FeatureSet` of one "frame" per
/// leading row (normalisation treats every vertex alike), with its shape.
fn feature_rows(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(FeatureSet, Vec<usize>)> {
    let (values, shape) = arrays::floats(obj, name)?;
    if shape.last() != Some(&CHANNELS) {
        return Err(input(format!(
            "{name}: expected an array of shape [..., {CHANNELS}], got shape {shape:?}"
        )));
    }
    let rows = values.len() / CHANNELS;
    Ok((FeatureSet::new(1, rows, values).map_err(to_py)?, shape))
}

fn features_out<'py>(
    py: Python<'py>,
    f: FeatureSet,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    array(py, f.into_vec(), shape)
}

/// Per frame and vertex, the 9 ACAP deformation features relative to the rest frame:
/// ``[ωx, ωy, ωz, S11, S12, S13, S22, S23, S33]``, the rotation vector of R and the symmetric
/// stretch S of the vertex's deformation gradient T = R S. float32 [N, V, 9], raw (not
/// normalised: see :class:`Normalization`), exactly what ``meshvae features --raw`` stores.
///
/// ``rest``: the rest frame, an index or a name (default 0). ``integrable`` (default True):
/// correct the per-vertex fits so that :func:`reconstruct` inverts them exactly; False is the
/// plain fit (``--plain``). ``principal``: principal rotation vectors (|ω| ≤ π) instead of
/// ACAP-consistent ones (``--principal``). ``normal_weight``: weight of the vertex-normal pair
/// in the fit. Warnings about the rest mesh are issued as ``UserWarning``.
#[pyfunction]
#[pyo3(
    signature = (mesh_set, rest=Frame::Index(0), *, integrable=true, principal=false, normal_weight=1.0),
    text_signature = "(mesh_set, rest=0, *, integrable=True, principal=False, normal_weight=1.0)"
)]
pub fn acap_features<'py>(
    py: Python<'py>,
    mesh_set: &MeshSet,
    rest: Frame,
    integrable: bool,
    principal: bool,
    normal_weight: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let set = &mesh_set.inner;
    let rest = match rest {
        Frame::Index(i) if i < set.len() => i,
        Frame::Name(name) => set.find(&name).ok_or_else(|| {
            input(format!(
                "rest: no frame {name:?} (the set has {} frames)",
                set.len()
            ))
        })?,
        Frame::Index(i) => {
            return Err(input(format!(
                "rest: frame {i} is beyond the set's {} frames",
                set.len()
            )));
        }
    };
    let options = FeatureOptions {
        normal_weight,
        consistent_rotations: !principal,
        integrable,
    };
    // The same calls as `meshvae features`.
    let out = py
        .detach(|| {
            let rest = RestMesh::new(set.frame(rest), set.faces())?;
            FeatureExtractor::new(rest, options)?.extract(set)
        })
        .map_err(to_py)?;
    warn_all(py, &out.warnings)?;
    let shape = [set.len(), set.vertex_count(), CHANNELS];
    features_out(py, out.features, &shape)
}

/// Positions from raw (de-normalised) features: one factorised sparse solve per frame.
///
/// ``features``: float [N, V, 9] (or [V, 9] for one frame); ``template_vertices`` float
/// [V, 3] and ``template_faces`` int [F, 3]: the rest mesh the features are relative to.
/// Returns float32 [N, V, 3] (or [V, 3]). Features cannot see translation: each connected
/// component of the result has the rest mesh's centroid.
#[pyfunction]
pub fn reconstruct<'py>(
    py: Python<'py>,
    features: &Bound<'py, PyAny>,
    template_vertices: &Bound<'py, PyAny>,
    template_faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let positions = arrays::points(template_vertices, "template_vertices")?;
    let v = positions.len();
    let faces = arrays::faces(template_faces, "template_faces", v, "template_vertices")?;
    let (values, shape) = arrays::floats(features, "features")?;
    let frames = match shape[..] {
        [n, rows, c] if rows == v && c == CHANNELS => n,
        [rows, c] if rows == v && c == CHANNELS => 1,
        _ => {
            return Err(input(format!(
                "features: expected shape [N, {v}, {CHANNELS}] or [{v}, {CHANNELS}] (the \
                 template has {v} vertices), got {shape:?}"
            )));
        }
    };
    let set = FeatureSet::new(frames, v, values).map_err(to_py)?;
    let meshes = py
        .detach(|| {
            let rest = RestMesh::new(&positions, &faces)?;
            Reconstructor::new(&rest)?.reconstruct_all(&set)
        })
        .map_err(to_py)?;
    let data: Vec<f32> = meshes
        .iter()
        .flat_map(|m| m.as_flattened().iter().map(|&x| x as f32))
        .collect();
    let mut out_shape = shape;
    let k = out_shape.len() - 1;
    out_shape[k] = 3;
    array(py, data, &out_shape)
}

/// The linear map of features into [−0.95, 0.95] a tanh network is trained on: one range for
/// the rotation entries (channels 0–2), one for the stretch entries (3–8).
///
/// ``Normalization.fit(features)`` fits the ranges (min/max over every frame and vertex, the
/// authors' choice; ``quantile=q`` fits between the q and 1 − q quantiles and clamps to ±1, as
/// ``meshvae train`` does by default with q = 0.001); ``apply`` maps raw features in,
/// ``invert`` maps back. Also made from its fields, or from the JSON of a features file or a
/// model folder's ``normalization.json``.
#[pyclass(module = "meshvae", frozen)]
pub struct Normalization {
    inner: deform_features::Normalization,
}

impl Normalization {
    /// A normalisation the crates fitted or loaded (for `torch_support.rs`).
    pub(crate) fn from_inner(inner: deform_features::Normalization) -> Self {
        Self { inner }
    }
}

#[pymethods]
impl Normalization {
    #[new]
    #[pyo3(signature = (rotation_min, rotation_max, scale_min, scale_max, clamp=None))]
    fn new(
        rotation_min: f64,
        rotation_max: f64,
        scale_min: f64,
        scale_max: f64,
        clamp: Option<f64>,
    ) -> PyResult<Self> {
        let inner = deform_features::Normalization {
            rotation_min,
            rotation_max,
            scale_min,
            scale_max,
            clamp,
        };
        inner.validate().map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Fits the ranges on ``features`` (float [..., 9], raw).
    #[staticmethod]
    #[pyo3(signature = (features, quantile=0.0))]
    fn fit(py: Python<'_>, features: &Bound<'_, PyAny>, quantile: f64) -> PyResult<Self> {
        let (set, _) = feature_rows(features, "features")?;
        let inner = py
            .detach(|| deform_features::Normalization::fit_quantile([&set], quantile))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Raw features (float [..., 9]) → normalised, float32 of the same shape.
    fn apply<'py>(
        &self,
        py: Python<'py>,
        features: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let (set, shape) = feature_rows(features, "features")?;
        let out = py.detach(|| self.inner.apply(&set));
        features_out(py, out, &shape)
    }

    /// Normalised features (float [..., 9]) → raw, float32 of the same shape.
    fn invert<'py>(
        &self,
        py: Python<'py>,
        normalized: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let (set, shape) = feature_rows(normalized, "normalized")?;
        let out = py.detach(|| self.inner.invert(&set));
        features_out(py, out, &shape)
    }

    /// The JSON form stored in features files and model folders.
    fn to_json(&self) -> String {
        self.inner.to_json()
    }

    /// Parses (and checks) the JSON written by :meth:`to_json`.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let inner = deform_features::Normalization::from_json(text).map_err(to_py)?;
        Ok(Self { inner })
    }

    #[getter]
    fn rotation_min(&self) -> f64 {
        self.inner.rotation_min
    }

    #[getter]
    fn rotation_max(&self) -> f64 {
        self.inner.rotation_max
    }

    #[getter]
    fn scale_min(&self) -> f64 {
        self.inner.scale_min
    }

    #[getter]
    fn scale_max(&self) -> f64 {
        self.inner.scale_max
    }

    /// Normalised values are clamped to ±this (None: not clamped).
    #[getter]
    fn clamp(&self) -> Option<f64> {
        self.inner.clamp
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<Normalization>()
            .is_ok_and(|o| o.get().inner == self.inner)
    }

    fn __repr__(&self) -> String {
        let n = &self.inner;
        format!(
            "Normalization(rotation_min={}, rotation_max={}, scale_min={}, scale_max={}, \
             clamp={})",
            n.rotation_min,
            n.rotation_max,
            n.scale_min,
            n.scale_max,
            n.clamp.map_or("None".into(), |c| c.to_string())
        )
    }
}

/// What a features file (``meshvae features --out``) holds.
#[pyclass(module = "meshvae", frozen)]
pub struct FeatureFile {
    features: Py<PyArrayDyn<f32>>,
    normalized: bool,
    normalization: Option<Py<Normalization>>,
    names: Vec<String>,
}

#[pymethods]
impl FeatureFile {
    /// float32 [N, V, 9]: normalised when :attr:`normalized` is True, raw otherwise.
    #[getter]
    fn features(&self, py: Python<'_>) -> Py<PyArrayDyn<f32>> {
        self.features.clone_ref(py)
    }

    /// Whether :attr:`features` are normalised (then :attr:`normalization` maps them back).
    #[getter]
    fn normalized(&self) -> bool {
        self.normalized
    }

    /// The normalisation fitted on these features, or None.
    #[getter]
    fn normalization(&self, py: Python<'_>) -> Option<Py<Normalization>> {
        self.normalization.as_ref().map(|n| n.clone_ref(py))
    }

    /// One name per frame.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.names.clone()
    }
}

/// Reads a features file written by ``meshvae features``.
#[pyfunction]
pub fn load_features(py: Python<'_>, path: PathBuf) -> PyResult<FeatureFile> {
    let file = py
        .detach(|| deform_features::load_features(&path))
        .map_err(to_py)?;
    let fs = &file.features;
    let shape = [fs.frames(), fs.vertices(), CHANNELS];
    let normalization = file
        .normalization
        .map(|inner| Py::new(py, Normalization { inner }))
        .transpose()?;
    Ok(FeatureFile {
        features: features_out(py, file.features, &shape)?.unbind(),
        normalized: file.normalized,
        normalization,
        names: file.names,
    })
}
