//! The levels behind `meshvae.sampling` (the psbody-free `generate_transform_matrices` of CoMA,
//! SpiralNet++ and Neural3DMM): repeated simplification to given vertex counts, and per step
//! the survivors, the coarse faces and the down-/up-sampling matrices. The Python module
//! `meshvae/sampling.py` turns them into the references' lists of `scipy.sparse` matrices.
//!
//! Two kinds of step, both over public APIs of qem-simplify and mesh-hierarchy:
//!
//! - `sampling` (CoMA's convention): classical QEM (λ = 0, as mesh-hierarchy's `sampling`
//!   pooler) to exactly the count; the coarse vertices stay at their survivors' fine positions
//!   (CoMA's `new_mesh_v = D · v`, not the simplifier's quadric optima); down-sampling selects
//!   the survivors ([`sampling::selection`]), up-sampling is barycentric in the closest of all
//!   coarse triangles, as CoMA's AABB-tree query ([`sampling::upsampling_global`]).
//!   The next step simplifies this coarse mesh (survivor positions, simplifier's faces).
//! - `mean`/`ours`, `qem` (our edge-contraction pooling, as `Hierarchy` builds it): the
//!   simplifier with its λ, coarse vertices at the simplifier's positions, mean pooling over
//!   the clusters and copy (or transpose) de-pooling ([`PoolingOp::from_clusters`]).
//!
//! A count equal to the current vertex count (a factor of 1) is an identity step.

use crate::arrays::{self, array, faces_out, points_out};
use crate::errors::{input, to_py};
use mesh_hierarchy::{CsrMatrix, DepoolMode, Pooler, PoolingOp, sampling};
use mesh_io::TriMesh;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use qem_simplify::{SimplifyConfig, Target};

/// One step: level i (n vertices) → level i + 1 (m vertices).
struct Step {
    /// Coarse vertex → the fine vertex that survived as it (ascending); identity for a factor 1.
    survivors: Vec<u32>,
    /// Fine vertex → its coarse cluster vertex.
    cluster_of: Vec<u32>,
    /// The coarse mesh (survivor positions for `sampling`, the simplifier's otherwise).
    coarse: TriMesh,
    /// m×n: coarse = down · fine.
    down: CsrMatrix,
    /// n×m: fine = up · coarse.
    up: CsrMatrix,
}

#[derive(Clone, Copy)]
enum Kind {
    Sampling,
    Contraction(Pooler, DepoolMode),
}

fn step(fine: &TriMesh, count: usize, kind: Kind) -> Result<Step, String> {
    let n = fine.vertex_count();
    if count == n {
        let identity: Vec<u32> = (0..n as u32).collect();
        return Ok(Step {
            survivors: identity.clone(),
            cluster_of: identity,
            coarse: fine.clone(),
            down: CsrMatrix::identity(n),
            up: CsrMatrix::identity(n),
        });
    }
    let lambda = match kind {
        Kind::Sampling => Pooler::Sampling.lambda(),
        Kind::Contraction(pooler, _) => pooler.lambda(),
    }
    .ok_or("the pooler does not simplify")?;
    let config = SimplifyConfig {
        target: Target::Vertices(count),
        lambda,
    };
    let simplified = qem_simplify::simplify(fine, &config).map_err(|e| e.to_string())?;
    let csr = |e: mesh_hierarchy::CsrError| e.to_string();
    match kind {
        Kind::Sampling => {
            let positions = simplified
                .survivors
                .iter()
                .map(|&s| fine.positions[s as usize])
                .collect();
            let coarse = TriMesh {
                positions,
                faces: simplified.coarse.faces,
            };
            let down = sampling::selection(&simplified.survivors, n).map_err(csr)?;
            let up = sampling::upsampling_global(
                &fine.positions,
                &simplified.cluster_of,
                &coarse.positions,
                &coarse.faces,
            )
            .map_err(csr)?;
            Ok(Step {
                survivors: simplified.survivors,
                cluster_of: simplified.cluster_of,
                coarse,
                down,
                up,
            })
        }
        Kind::Contraction(pooler, depool) => {
            let m = simplified.coarse.vertex_count();
            let op =
                PoolingOp::from_clusters(pooler, &simplified.cluster_of, m, depool).map_err(csr)?;
            Ok(Step {
                survivors: simplified.survivors,
                cluster_of: simplified.cluster_of,
                coarse: simplified.coarse,
                down: op.pool,
                up: op.depool,
            })
        }
    }
}

/// A `CsrMatrix` as the numpy triple (indptr int64, indices int64, data float64) that
/// `scipy.sparse.csr_matrix((data, indices, indptr), shape)` takes, with its shape.
fn csr_parts<'py>(py: Python<'py>, m: &CsrMatrix) -> PyResult<Bound<'py, PyTuple>> {
    let indptr = array(
        py,
        m.indptr().iter().map(|&i| i as i64).collect(),
        &[m.rows() + 1],
    )?;
    let indices = array(
        py,
        m.indices().iter().map(|&i| i64::from(i)).collect(),
        &[m.nnz()],
    )?;
    let data = array(py, m.values().to_vec(), &[m.nnz()])?;
    (data, indices, indptr, (m.rows(), m.cols())).into_pyobject(py)
}

fn indices_out<'py>(py: Python<'py>, v: &[u32]) -> PyResult<Bound<'py, PyAny>> {
    Ok(array(py, v.iter().map(|&i| i64::from(i)).collect(), &[v.len()])?.into_any())
}

/// The steps of ``meshvae.sampling`` (private: use that module). ``counts[i]``: the vertex
/// count of level ``i + 1`` (each at most the previous one's, at least 1). ``pool``:
/// ``"sampling"`` (CoMA: classical QEM survivors at their own positions, selection down,
/// barycentric up), or ``"mean"``/``"ours"``/``"qem"`` (edge-contraction mean pooling,
/// ``depool`` ``"copy"`` or ``"transpose"``). Per step a tuple (survivors int64 [m], cluster
/// int64 [n], coarse vertices float32 [m, 3], coarse faces int32 [F, 3], down, up), each matrix
/// as (data float64, indices int64, indptr int64, shape) of a CSR matrix.
#[pyfunction]
#[pyo3(name = "_sampling_levels", signature = (vertices, faces, counts, pool="sampling", depool="copy"))]
pub fn sampling_levels<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    counts: Vec<usize>,
    pool: &str,
    depool: &str,
) -> PyResult<Vec<Bound<'py, PyTuple>>> {
    let positions = arrays::points(vertices, "vertices")?;
    let faces = arrays::faces(faces, "faces", positions.len(), "vertices")?;
    let template = TriMesh::new(positions, faces).map_err(to_py)?;
    let depool = depool
        .parse::<DepoolMode>()
        .map_err(|e| input(format!("depool: {e}")))?;
    let kind = match pool
        .parse::<Pooler>()
        .map_err(|e| input(format!("pool: {e}")))?
    {
        Pooler::Sampling => Kind::Sampling,
        p @ (Pooler::Mean | Pooler::Qem) => Kind::Contraction(p, depool),
        other => {
            return Err(input(format!(
                "pool: {other} has no linear down-/up-sampling matrices here (expected \
                 sampling, mean, ours or qem)"
            )));
        }
    };
    let mut previous = template.vertex_count();
    for (i, &count) in counts.iter().enumerate() {
        if count == 0 || count > previous {
            return Err(input(format!(
                "counts: level {} asks for {count} vertices, not in 1..={previous}",
                i + 1
            )));
        }
        previous = count;
    }
    let steps = py
        .detach(|| -> Result<Vec<Step>, String> {
            let mut steps: Vec<Step> = Vec::with_capacity(counts.len());
            for (i, &count) in counts.iter().enumerate() {
                let fine = steps.last().map_or(&template, |s| &s.coarse);
                let next = step(fine, count, kind)
                    .map_err(|e| format!("level {} ({count} vertices): {e}", i + 1))?;
                steps.push(next);
            }
            Ok(steps)
        })
        .map_err(input)?;
    steps
        .into_iter()
        .map(|s| {
            let items: Vec<Bound<'py, PyAny>> = vec![
                indices_out(py, &s.survivors)?,
                indices_out(py, &s.cluster_of)?,
                points_out(py, s.coarse.positions)?.into_any(),
                faces_out(py, &s.coarse.faces)?.into_any(),
                csr_parts(py, &s.down)?.into_any(),
                csr_parts(py, &s.up)?.into_any(),
            ];
            PyTuple::new(py, items)
        })
        .collect()
}
