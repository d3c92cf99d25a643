//! The hierarchy (mesh-hierarchy): levels, rescaled Laplacians and pooling operators as
//! `scipy.sparse.csr_matrix`, the Rust pooling itself, and the project's hierarchy file.

use crate::arrays::{self, array, faces_out, points_out};
use crate::errors::{Kind, input, raise, to_py};
use mesh_hierarchy::{CsrMatrix, DepoolMode, HierarchyConfig, HierarchyError, Pooler, PoolingOp};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Levels 0..=L of a template mesh and the L pooling steps between them (step ``i``: level
/// ``i`` → ``i + 1``), as ``meshvae train`` builds them.
///
/// Per level: the rescaled Laplacian L̃ = 2L/λmax − I of its connectivity (λmax = 2), its
/// faces and positions. Per step: the pooling matrix P (m×n, coarse = P · fine) and the
/// de-pooling matrix D (n×m, fine = D · coarse). Matrices come as ``scipy.sparse.csr_matrix``
/// float32 (scipy is imported on first use).
#[pyclass(module = "meshvae", frozen)]
pub struct Hierarchy {
    inner: mesh_hierarchy::Hierarchy,
}

impl Hierarchy {
    /// A hierarchy the crates built or loaded (for `torch_support.rs`).
    pub(crate) fn from_inner(inner: mesh_hierarchy::Hierarchy) -> Self {
        Self { inner }
    }

    fn step(&self, step: usize) -> PyResult<&PoolingOp> {
        self.inner.pooling.get(step).ok_or_else(|| {
            input(format!(
                "step: {step} is not a pooling step (the hierarchy has {})",
                self.inner.pooling.len()
            ))
        })
    }

    fn level(&self, level: usize) -> PyResult<&mesh_hierarchy::Level> {
        self.inner.levels.get(level).ok_or_else(|| {
            input(format!(
                "level: {level} is not a level (the hierarchy has levels 0..={})",
                self.inner.pooling.len()
            ))
        })
    }

    /// Applies `f` (pool or de-pool, `n` values in, per vertex-major sample) to every sample of
    /// `x`, `[n, C]` or `[B, n, C]`, giving `[out, C]` or `[B, out, C]` float32.
    fn apply<'py>(
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        n: usize,
        out: usize,
        f: impl Fn(&[f64], usize) -> Result<Vec<f64>, HierarchyError> + Send + Sync,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let (values, shape) = arrays::floats(x, "x")?;
        let layout = format!("[{n}, C] or [B, {n}, C]");
        let (batch, channels) = match shape[..] {
            [v, c] if v == n => (1, c),
            [b, v, c] if v == n => (b, c),
            _ => return Err(input(format!("x: expected shape {layout}, got {shape:?}"))),
        };
        let result = py
            .detach(|| -> Result<Vec<f32>, HierarchyError> {
                let mut y = Vec::with_capacity(batch * out * channels);
                for sample in values.chunks_exact(n * channels.max(1)).take(batch) {
                    let sample: Vec<f64> = sample.iter().map(|&v| f64::from(v)).collect();
                    y.extend(f(&sample, channels)?.into_iter().map(|v| v as f32));
                }
                Ok(y)
            })
            .map_err(to_py)?;
        let mut out_shape = shape;
        let k = out_shape.len() - 2;
        out_shape[k] = out;
        array(py, result, &out_shape)
    }
}

/// A `CsrMatrix` as `scipy.sparse.csr_matrix` of `dtype` ("float32", the default, or
/// "float64", the values as computed).
fn csr<'py>(py: Python<'py>, m: &CsrMatrix, dtype: Option<&str>) -> PyResult<Bound<'py, PyAny>> {
    let sparse = py.import("scipy.sparse").map_err(|e| {
        pyo3::exceptions::PyImportError::new_err(format!(
            "meshvae needs scipy for sparse matrices (pip install scipy): {e}"
        ))
    })?;
    let data = match dtype.unwrap_or("float32") {
        "float32" => array(
            py,
            m.values().iter().map(|&v| v as f32).collect(),
            &[m.nnz()],
        )?
        .into_any(),
        "float64" => array(py, m.values().to_vec(), &[m.nnz()])?.into_any(),
        other => {
            return Err(input(format!(
                "dtype: {other:?} is not \"float32\" or \"float64\""
            )));
        }
    };
    let indices = array(
        py,
        m.indices().iter().map(|&i| i64::from(i)).collect(),
        &[m.nnz()],
    )?;
    let indptr = array(
        py,
        m.indptr().iter().map(|&i| i as i64).collect(),
        &[m.rows() + 1],
    )?;
    sparse.call_method1(
        "csr_matrix",
        ((data, indices, indptr), (m.rows(), m.cols())),
    )
}

#[pymethods]
impl Hierarchy {
    /// Builds the hierarchy of a template mesh (what ``meshvae train`` does before training).
    ///
    /// ``levels``: pooling steps (1 for the paper's 'CCPC', 2 for 'CCPCCPC'); ``pool``: ``"mean"``
    /// (or ``"ours"``: modified QEM, mean pooling, the paper's), ``"qem"``, ``"max"``,
    /// ``"sampling"``, ``"none"``, ``"graph"`` or ``"remesh"`` (the paper's ablation; see
    /// mesh-hierarchy's ``Pooler``); ``ratio``: fraction of vertices kept per step;
    /// ``depool``: ``"copy"`` (D[v, c] = 1, so P·D = I) or ``"transpose"`` (D = Pᵀ, as the
    /// authors' code), for the mean poolers.
    #[staticmethod]
    #[pyo3(signature = (vertices, faces, levels=1, pool="mean", ratio=0.5, depool="copy"))]
    fn build(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        levels: usize,
        pool: &str,
        ratio: f64,
        depool: &str,
    ) -> PyResult<Self> {
        let positions = arrays::points(vertices, "vertices")?;
        let faces = arrays::faces(faces, "faces", positions.len(), "vertices")?;
        let template = mesh_io::TriMesh::new(positions, faces).map_err(to_py)?;
        let config = HierarchyConfig {
            pooler: pool
                .parse::<Pooler>()
                .map_err(|e| input(format!("pool: {e}")))?,
            levels,
            ratio,
            depool: depool
                .parse::<DepoolMode>()
                .map_err(|e| input(format!("depool: {e}")))?,
            ..HierarchyConfig::default()
        };
        let inner = py
            .detach(|| mesh_hierarchy::Hierarchy::build(&template, &config))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Reads a hierarchy file written by :meth:`save` (or by ``meshvae train``: a model folder's
    /// ``hierarchy.safetensors``, or the ``hierarchy.json`` of older folders), checking it;
    /// nothing is recomputed. A missing, unreadable or invalid
    /// file raises ``FileError``.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        match py.detach(|| mesh_hierarchy::Hierarchy::load(&path)) {
            Ok(inner) => Ok(Self { inner }),
            // The crate reports every problem with the file as `File`, I/O included.
            Err(e @ HierarchyError::File { .. }) => Err(raise(Kind::File, e.to_string())),
            Err(e) => Err(to_py(e)),
        }
    }

    /// Writes the hierarchy to ``path`` in the project's format (safetensors with a format tag,
    /// version and checksum, the file ``meshvae train`` keeps in a model folder), atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.inner.save(&path)).map_err(to_py)
    }

    /// Number of pooling steps L (levels are 0..=L).
    #[getter]
    fn levels(&self) -> usize {
        self.inner.pooling.len()
    }

    /// The pooler's name (``"mean"`` also for ``"ours"``, its older name).
    #[getter]
    fn pool_kind(&self) -> String {
        self.inner.config.pooler.to_string()
    }

    /// Vertex counts of levels 0..=L.
    #[getter]
    fn vertex_counts(&self) -> Vec<usize> {
        self.inner.vertex_counts()
    }

    /// The rescaled Laplacian L̃ of ``level`` (0 = the template), V×V CSR of ``dtype``
    /// (``"float32"``, or ``"float64"``: the values as computed).
    #[pyo3(signature = (level, dtype=None))]
    fn laplacian<'py>(
        &self,
        py: Python<'py>,
        level: usize,
        dtype: Option<&str>,
    ) -> PyResult<Bound<'py, PyAny>> {
        csr(py, &self.level(level)?.laplacian, dtype)
    }

    /// The pooling matrix P of ``step`` (level ``step`` → ``step + 1``), m×n CSR of ``dtype``
    /// (as :meth:`laplacian`): coarse = P @ fine. For the mean poolers row c is 1/|cluster c|
    /// on the cluster's fine vertices; for ``max`` and ``graph`` it is the mean over the set
    /// the max is taken on (use :meth:`pool` for the max itself).
    #[pyo3(signature = (step, dtype=None))]
    fn pooling<'py>(
        &self,
        py: Python<'py>,
        step: usize,
        dtype: Option<&str>,
    ) -> PyResult<Bound<'py, PyAny>> {
        csr(py, &self.step(step)?.pool, dtype)
    }

    /// The de-pooling matrix D of ``step``, n×m CSR of ``dtype`` (as :meth:`laplacian`):
    /// fine = D @ coarse.
    #[pyo3(signature = (step, dtype=None))]
    fn depooling<'py>(
        &self,
        py: Python<'py>,
        step: usize,
        dtype: Option<&str>,
    ) -> PyResult<Bound<'py, PyAny>> {
        csr(py, &self.step(step)?.depool, dtype)
    }

    /// int64 [n]: the coarse vertex of each fine vertex at ``step`` (the simplifier's clusters);
    /// None for the ``sampling`` and ``none`` poolers, which have no clusters.
    fn cluster<'py>(
        &self,
        py: Python<'py>,
        step: usize,
    ) -> PyResult<Option<Bound<'py, PyArrayDyn<i64>>>> {
        let op = self.step(step)?;
        let Some(clusters) = &op.clusters else {
            return Ok(None);
        };
        let mut of = vec![-1i64; op.fine_count()];
        for (c, members) in clusters.iter().enumerate() {
            for &v in members {
                if let Some(slot) = of.get_mut(v as usize) {
                    *slot = c as i64;
                }
            }
        }
        Ok(Some(array(py, of, &[op.fine_count()])?))
    }

    /// float32 [V, 3]: the positions of ``level`` (the template's, then the simplifier's).
    fn positions<'py>(
        &self,
        py: Python<'py>,
        level: usize,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        points_out(py, self.level(level)?.positions.clone())
    }

    /// int32 [F, 3]: the triangles of ``level``.
    fn faces<'py>(&self, py: Python<'py>, level: usize) -> PyResult<Bound<'py, PyArrayDyn<i32>>> {
        faces_out(py, &self.level(level)?.faces)
    }

    /// Pools ``x`` (float [n, C] or [B, n, C]) from level ``step`` to ``step + 1`` as the
    /// network does: P @ x for the mean poolers and sampling, the signed largest magnitude per
    /// cluster for ``max``, the largest value per neighbourhood for ``graph``. float32 out.
    fn pool<'py>(
        &self,
        py: Python<'py>,
        step: usize,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let op = self.step(step)?;
        Self::apply(py, x, op.fine_count(), op.coarse_count(), |v, c| {
            op.pool(v, c)
        })
    }

    /// De-pools ``x`` (float [m, C] or [B, m, C]) from level ``step + 1`` back to ``step``:
    /// D @ x. float32 out.
    fn depool<'py>(
        &self,
        py: Python<'py>,
        step: usize,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let op = self.step(step)?;
        Self::apply(py, x, op.coarse_count(), op.fine_count(), |v, c| {
            op.depool(v, c)
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Hierarchy(pool={}, vertex_counts={:?})",
            self.inner.config.pooler,
            self.inner.vertex_counts()
        )
    }
}
