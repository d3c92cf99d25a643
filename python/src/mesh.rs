//! Mesh files and mesh sets (mesh-io): `load_set`, `MeshSet`, `load_mesh`, `save_obj`,
//! `save_glb`.

use crate::arrays::{self, array, faces_out, points_out, read_only};
use crate::errors::{input, to_py, warn_all};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::path::PathBuf;

/// N meshes ("frames") of one connectivity: an animation or a set of poses.
///
/// Made by :func:`load_set`, or from arrays: ``MeshSet(positions, faces, names=None,
/// labels=None)`` with ``positions`` float [N, V, 3] and ``faces`` int [F, 3] (names default to
/// ``"0"``, ``"1"``, …). The arrays it returns are read-only views of what it holds.
#[pyclass(module = "meshvae", frozen)]
pub struct MeshSet {
    pub(crate) inner: mesh_io::MeshSet,
    positions: Py<PyArrayDyn<f32>>,
    faces: Py<PyArrayDyn<i32>>,
}

impl MeshSet {
    pub(crate) fn wrap(py: Python<'_>, inner: mesh_io::MeshSet) -> PyResult<Self> {
        let shape = [inner.len(), inner.vertex_count(), 3];
        let positions = array(py, inner.positions().as_flattened().to_vec(), &shape)?;
        let faces = faces_out(py, inner.faces())?;
        read_only(&positions)?;
        read_only(&faces)?;
        Ok(Self {
            inner,
            positions: positions.unbind(),
            faces: faces.unbind(),
        })
    }
}

#[pymethods]
impl MeshSet {
    #[new]
    #[pyo3(signature = (positions, faces, names=None, labels=None))]
    fn new(
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        names: Option<Vec<String>>,
        labels: Option<Vec<String>>,
    ) -> PyResult<Self> {
        let (points, n, v) = arrays::frames(positions, "positions")?;
        let faces = arrays::faces(faces, "faces", v, "positions")?;
        let names = names.unwrap_or_else(|| (0..n).map(|i| i.to_string()).collect());
        let mut set = mesh_io::MeshSet::from_flat(faces, v, points, names).map_err(to_py)?;
        if let Some(labels) = labels {
            set = set.with_labels(labels).map_err(to_py)?;
        }
        Self::wrap(py, set)
    }

    /// float32 [N, V, 3]: frame ``i``'s vertex ``j`` is ``positions[i, j]`` (file order).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f32>> {
        self.positions.bind(py).clone()
    }

    /// int32 [F, 3]: the shared triangles, 0-based.
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<i32>> {
        self.faces.bind(py).clone()
    }

    /// One name per frame (file names without extension, in natural order).
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names().to_vec()
    }

    /// One label per frame (from ``labels.csv``), or None.
    #[getter]
    fn labels(&self) -> Option<Vec<String>> {
        self.inner.labels().map(<[String]>::to_vec)
    }

    /// Vertices per frame (V).
    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.vertex_count()
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "MeshSet({} frames × {} vertices, {} faces{})",
            self.inner.len(),
            self.inner.vertex_count(),
            self.inner.faces().len(),
            if self.inner.labels().is_some() {
                ", labelled"
            } else {
                ""
            }
        )
    }
}

/// Reads a mesh set: a folder of OBJ/OFF/PLY/glTF files (natural order, with an optional
/// ``labels.csv``), a multi-frame GLB (morph targets as frames) or a ``.mvset`` cache. Every
/// file must have the same vertex count and faces. Problems that do not stop loading are issued
/// as ``UserWarning``.
///
/// Raises ``FileError`` (an ``OSError``) when the path cannot be read, ``InputError`` (a
/// ``ValueError``) when its contents are not a valid set.
#[pyfunction]
pub fn load_set(py: Python<'_>, path: PathBuf) -> PyResult<MeshSet> {
    let loaded = py.detach(|| mesh_io::load_set(&path)).map_err(to_py)?;
    warn_all(py, &loaded.warnings)?;
    MeshSet::wrap(py, loaded.value)
}

/// Reads one mesh file (OBJ, OFF, PLY, glTF/GLB) in file order, unused vertices included.
///
/// Returns ``(vertices, faces)``: float32 [V, 3] and int32 [F, 3].
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn load_mesh(
    py: Python<'_>,
    path: PathBuf,
) -> PyResult<(Bound<'_, PyArrayDyn<f32>>, Bound<'_, PyArrayDyn<i32>>)> {
    let loaded = py.detach(|| mesh_io::read_mesh(&path)).map_err(to_py)?;
    warn_all(py, &loaded.warnings)?;
    let mesh = loaded.value;
    let faces = faces_out(py, &mesh.faces)?;
    Ok((points_out(py, mesh.positions)?, faces))
}

/// Writes one mesh as OBJ (``v`` and ``f`` lines; coordinates read back bit-exactly),
/// atomically. ``vertices``: float [V, 3]; ``faces``: int [F, 3].
#[pyfunction]
pub fn save_obj(
    py: Python<'_>,
    path: PathBuf,
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let positions = arrays::points(vertices, "vertices")?;
    let faces = arrays::faces(faces, "faces", positions.len(), "vertices")?;
    let mesh = mesh_io::TriMesh::new(positions, faces).map_err(to_py)?;
    py.detach(|| mesh_io::obj::write_obj(&path, &mesh))
        .map_err(to_py)
}

/// Writes frames of one connectivity as one GLB, atomically: frame 0 is the base mesh, every
/// later frame a morph target, and an animation steps through them, so the sequence plays in
/// any glTF viewer (and :func:`load_set` reads it back). ``frames``: float [N, V, 3];
/// ``faces``: int [F, 3]; ``names``: one per frame (default ``"0"``, ``"1"``, …).
#[pyfunction]
#[pyo3(signature = (path, frames, faces, names=None))]
pub fn save_glb(
    py: Python<'_>,
    path: PathBuf,
    frames: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    names: Option<Vec<String>>,
) -> PyResult<()> {
    let (points, n, v) = arrays::frames(frames, "frames")?;
    let faces = arrays::faces(faces, "faces", v, "frames")?;
    let names = names.unwrap_or_else(|| (0..n).map(|i| i.to_string()).collect());
    if names.len() != n {
        return Err(input(format!(
            "names: {} names for {n} frames",
            names.len()
        )));
    }
    let set = mesh_io::MeshSet::from_flat(faces, v, points, names).map_err(to_py)?;
    py.detach(|| mesh_io::glb::write_glb_set(&path, &set))
        .map_err(to_py)
}
