//! Graph operators of one level: vertex adjacency, the normalised Laplacian
//! L = I − D^-1/2 A D^-1/2, and its rescaled form L̃ = 2L/λmax − I that Chebyshev filters use.

use crate::error::HierarchyError;
use mesh_io::Face;
use sparse_csr::CsrMatrix;

/// The undirected, unweighted vertex adjacency of a triangle mesh (no self-loops): `A[i][j] = 1`
/// when i and j share an edge. As the authors' code: the binarised cotangent-weight pattern.
///
/// # Panics
/// If a face index is `>= vertex_count`; faces of a validated `MeshSet` never are. For faces
/// that may be out of range, [`try_adjacency`] returns an error instead.
pub fn adjacency(vertex_count: usize, faces: &[Face]) -> CsrMatrix {
    match try_adjacency(vertex_count, faces) {
        Ok(a) => a,
        Err(e) => panic!("adjacency: {e}"),
    }
}

/// [`adjacency`], with out-of-range face indices reported as an error naming the face.
pub fn try_adjacency(vertex_count: usize, faces: &[Face]) -> Result<CsrMatrix, HierarchyError> {
    if let Some((i, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v as usize >= vertex_count))
    {
        return Err(HierarchyError::InvalidArgument {
            argument: "faces",
            message: format!("face {i} = {f:?} has an index >= the vertex count {vertex_count}"),
        });
    }
    let mut triplets: Vec<(u32, u32, f64)> = Vec::with_capacity(faces.len() * 6);
    for f in faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            if a != b {
                triplets.push((a, b, 1.0));
                triplets.push((b, a, 1.0));
            }
        }
    }
    triplets.sort_by_key(|t| (t.0, t.1));
    triplets.dedup_by_key(|t| (t.0, t.1));
    Ok(CsrMatrix::from_triplets(
        vertex_count,
        vertex_count,
        &triplets,
    )?)
}

/// How λmax, the largest eigenvalue of L, is chosen for the rescaling.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum LambdaMax {
    /// λmax = 2, the bound for a normalised Laplacian, as the authors' code does by default
    /// (then L̃ = −D^-1/2 A D^-1/2).
    Two,
    /// λmax estimated by power iteration (this many iterations).
    PowerIteration(usize),
}

/// The normalised Laplacian L = I − D^-1/2 A D^-1/2 (isolated vertices get L_ii = 1).
pub fn normalized_laplacian(adjacency: &CsrMatrix) -> CsrMatrix {
    let n = adjacency.rows();
    let inv_sqrt_degree: Vec<f64> = (0..n)
        .map(|r| {
            let d: f64 = adjacency.row(r).1.iter().sum();
            if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 }
        })
        .collect();
    let mut triplets = Vec::with_capacity(adjacency.nnz() + n);
    for r in 0..n {
        triplets.push((r as u32, r as u32, 1.0));
        let (cols, vals) = adjacency.row(r);
        for (&c, &v) in cols.iter().zip(vals) {
            triplets.push((
                r as u32,
                c,
                -v * inv_sqrt_degree[r] * inv_sqrt_degree[c as usize],
            ));
        }
    }
    CsrMatrix::from_triplets(n, n, &triplets).expect("indices come from a valid matrix")
}

/// L̃ = 2L/λmax − I, whose spectrum lies in [−1, 1] (for λmax the true largest eigenvalue).
pub fn rescaled_laplacian(laplacian: &CsrMatrix, lambda_max: LambdaMax) -> CsrMatrix {
    let lmax = match lambda_max {
        LambdaMax::Two => 2.0,
        LambdaMax::PowerIteration(iterations) => largest_eigenvalue(laplacian, iterations),
    };
    let n = laplacian.rows();
    let mut triplets = Vec::with_capacity(laplacian.nnz() + n);
    for r in 0..n {
        triplets.push((r as u32, r as u32, -1.0));
        let (cols, vals) = laplacian.row(r);
        for (&c, &v) in cols.iter().zip(vals) {
            triplets.push((r as u32, c, 2.0 * v / lmax));
        }
    }
    CsrMatrix::from_triplets(n, n, &triplets).expect("indices come from a valid matrix")
}

/// The largest eigenvalue of a symmetric positive semi-definite matrix by power iteration from
/// a fixed, deterministic start vector. Never below 1e-12, so it can divide.
pub fn largest_eigenvalue(matrix: &CsrMatrix, iterations: usize) -> f64 {
    let n = matrix.rows();
    let mut x: Vec<f64> = (0..n)
        .map(|i| 1.0 + ((i * 7919) % 97) as f64 / 97.0)
        .collect();
    let mut lambda = 0.0;
    for _ in 0..iterations.max(1) {
        let y = matrix.mul_vec(&x);
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        let xnorm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 || xnorm == 0.0 {
            break;
        }
        lambda = norm / xnorm;
        x = y.iter().map(|v| v / norm).collect();
    }
    lambda.max(1e-12)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing an edge: 0-1-2 and 0-2-3.
    fn quad() -> (usize, Vec<Face>) {
        (4, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn out_of_range_faces_are_an_error_naming_the_face() {
        let err = try_adjacency(3, &[[0, 1, 2], [0, 2, 3]])
            .unwrap_err()
            .to_string();
        assert!(err.contains("face 1") && err.contains("3"), "{err}");
        assert_eq!(
            try_adjacency(4, &[[0, 1, 2], [0, 2, 3]]).unwrap(),
            adjacency(4, &quad().1)
        );
    }

    #[test]
    fn laplacian_matches_dense_formula() {
        let (n, faces) = quad();
        let a = adjacency(n, &faces);
        let dense_a = a.to_dense();
        assert_eq!(dense_a[0], vec![0.0, 1.0, 1.0, 1.0]);
        assert_eq!(dense_a[1], vec![1.0, 0.0, 1.0, 0.0]);
        let deg: Vec<f64> = dense_a.iter().map(|r| r.iter().sum()).collect();
        let l = normalized_laplacian(&a).to_dense();
        let lt = rescaled_laplacian(&normalized_laplacian(&a), LambdaMax::Two).to_dense();
        for i in 0..n {
            for j in 0..n {
                let eye = if i == j { 1.0 } else { 0.0 };
                let want = eye - dense_a[i][j] / (deg[i] * deg[j]).sqrt();
                assert!((l[i][j] - want).abs() < 1e-15);
                assert!((lt[i][j] - (want - eye)).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn power_iteration_finds_the_top_eigenvalue() {
        // A path graph's normalised Laplacian has largest eigenvalue exactly 2 (bipartite).
        let path = CsrMatrix::from_triplets(
            4,
            4,
            &[
                (0, 1, 1.0),
                (1, 0, 1.0),
                (1, 2, 1.0),
                (2, 1, 1.0),
                (2, 3, 1.0),
                (3, 2, 1.0),
            ],
        )
        .unwrap();
        let l = normalized_laplacian(&path);
        assert!((largest_eigenvalue(&l, 500) - 2.0).abs() < 1e-6);
        let lt = rescaled_laplacian(&l, LambdaMax::PowerIteration(500)).to_dense();
        let lt2 = rescaled_laplacian(&l, LambdaMax::Two).to_dense();
        for (a, b) in lt.iter().flatten().zip(lt2.iter().flatten()) {
            assert!((a - b).abs() < 1e-5);
        }
    }
}
