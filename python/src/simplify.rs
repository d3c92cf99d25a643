//! The simplifier (qem-simplify): `simplify` → `Simplified`, with the fine → coarse vertex map
//! and the report `meshvae simplify` prints.

use crate::arrays::{self, array, faces_out, points_out};
use crate::errors::{input, to_py};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use qem_simplify::{RemeshConfig, SimplifyConfig, SimplifyReport, Target};
use std::time::Instant;

/// A simplified (or remeshed) mesh and how the fine vertices map onto it.
#[pyclass(module = "meshvae", frozen)]
pub struct Simplified {
    vertices: Py<PyArrayDyn<f32>>,
    faces: Py<PyArrayDyn<i32>>,
    cluster: Py<PyArrayDyn<i64>>,
    survivors: Option<Py<PyArrayDyn<i64>>>,
    report: Py<PyAny>,
}

#[pymethods]
impl Simplified {
    /// float32 [M, 3]: the coarse vertices.
    #[getter]
    fn vertices(&self, py: Python<'_>) -> Py<PyArrayDyn<f32>> {
        self.vertices.clone_ref(py)
    }

    /// int32 [F', 3]: the coarse triangles.
    #[getter]
    fn faces(&self, py: Python<'_>) -> Py<PyArrayDyn<i32>> {
        self.faces.clone_ref(py)
    }

    /// int64 [V]: the coarse vertex (in 0..M) whose cluster each fine vertex belongs to; every
    /// cluster is connected on the fine mesh. Mean pooling averages over these clusters.
    #[getter]
    fn cluster(&self, py: Python<'_>) -> Py<PyArrayDyn<i64>> {
        self.cluster.clone_ref(py)
    }

    /// int64 [M]: the fine vertex that survived as each coarse vertex (ascending), for the QEM
    /// methods; None for a remeshing, whose vertices are new points.
    #[getter]
    fn survivors(&self, py: Python<'_>) -> Option<Py<PyArrayDyn<i64>>> {
        self.survivors.as_ref().map(|s| s.clone_ref(py))
    }

    /// The quality report ``meshvae simplify --json`` prints, as a dict: method, vertices_in,
    /// vertices_out, faces_in, faces_out, lambda (None for remesh), edge_cv_in, edge_cv,
    /// cluster_cv, cluster_max, cluster_area_cv, manifold, flipped_faces, degenerate_faces,
    /// euler_in, euler_out, seconds, geometric_error_rel.
    #[getter]
    fn report(&self, py: Python<'_>) -> Py<PyAny> {
        self.report.clone_ref(py)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let counts = |a: &Py<PyArrayDyn<f32>>| a.bind(py).len().unwrap_or(0);
        format!(
            "Simplified({} fine → {} coarse vertices)",
            self.cluster.bind(py).len().unwrap_or(0),
            counts(&self.vertices)
        )
    }
}

fn indices_out(py: Python<'_>, v: &[u32]) -> PyResult<Py<PyArrayDyn<i64>>> {
    let data = v.iter().map(|&c| i64::from(c)).collect();
    Ok(array(py, data, &[v.len()])?.unbind())
}

/// Simplifies a template mesh to ``ratio`` of its vertices (rounded up), keeping a 2-manifold
/// of the same topology, and returns the coarse mesh with the map fine vertex → coarse vertex.
///
/// ``method``:
///
/// - ``"modified-qem"`` (default): quadric edge collapse with the paper's edge-length term of
///   weight ``lam`` (default 0.001, lengths in units of the bounding-box diagonal), the
///   simplifier of ``meshvae simplify`` and of the ``ours``/``mean`` pooling;
/// - ``"qem"``: classical quadric simplification (λ = 0; ``lam`` must be None or 0);
/// - ``"remesh"``: isotropic remeshing to the same count, each fine vertex in the cluster of its
///   geodesically nearest coarse vertex (``lam`` must be None).
///
/// Deterministic. ``vertices``: float [V, 3]; ``faces``: int [F, 3]. Raises ``InputError``
/// for a non-manifold mesh, an unreachable count or a bad argument.
#[pyfunction]
#[pyo3(signature = (vertices, faces, ratio=0.5, lam=None, method="modified-qem"))]
pub fn simplify(
    py: Python<'_>,
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    ratio: f64,
    lam: Option<f64>,
    method: &str,
) -> PyResult<Simplified> {
    let positions = arrays::points(vertices, "vertices")?;
    let faces = arrays::faces(faces, "faces", positions.len(), "vertices")?;
    let fine = mesh_io::TriMesh::new(positions, faces).map_err(to_py)?;
    let target = Target::Ratio(ratio);
    let lambda = match (method, lam) {
        ("modified-qem", lam) => Some(lam.unwrap_or(qem_simplify::DEFAULT_LAMBDA)),
        ("qem", None | Some(0.0)) => Some(0.0),
        ("qem", Some(l)) => {
            return Err(input(format!(
                "lam: {l} given with method=\"qem\", which is classical QEM (λ = 0); use \
                 method=\"modified-qem\" for an edge-length term"
            )));
        }
        ("remesh", None) => None,
        ("remesh", Some(_)) => {
            return Err(input(
                "lam: applies to the QEM methods only (a remeshing has no edge-length weight)",
            ));
        }
        (other, _) => {
            return Err(input(format!(
                "method: unknown method {other:?} (expected \"modified-qem\", \"qem\" or \
                 \"remesh\")"
            )));
        }
    };
    // The same calls as `meshvae simplify`: the simplification alone is timed.
    let (coarse, cluster_of, survivors, report) = py
        .detach(|| -> Result<_, qem_simplify::SimplifyError> {
            let start = Instant::now();
            Ok(match lambda {
                Some(lambda) => {
                    let s = qem_simplify::simplify(&fine, &SimplifyConfig { target, lambda })?;
                    let seconds = start.elapsed().as_secs_f64();
                    let report = SimplifyReport::of(&fine, &s, lambda, seconds);
                    (s.coarse, s.cluster_of, Some(s.survivors), report)
                }
                None => {
                    let config = RemeshConfig {
                        target,
                        ..RemeshConfig::default()
                    };
                    let r = qem_simplify::remesh(&fine, &config)?;
                    let seconds = start.elapsed().as_secs_f64();
                    let report = SimplifyReport::of_remeshed(&fine, &r, seconds);
                    (r.coarse, r.cluster_of, None, report)
                }
            })
        })
        .map_err(to_py)?;
    let report_json = serde_json::to_string(&report).map_err(|e| input(e.to_string()))?;
    let report = py
        .import("json")?
        .call_method1("loads", (report_json,))?
        .unbind();
    Ok(Simplified {
        faces: faces_out(py, &coarse.faces)?.unbind(),
        vertices: points_out(py, coarse.positions)?.unbind(),
        cluster: indices_out(py, &cluster_of)?,
        survivors: survivors.map(|s| indices_out(py, &s)).transpose()?,
        report,
    })
}
