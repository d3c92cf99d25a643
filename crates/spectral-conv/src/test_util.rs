//! Test helpers: deterministic random data, small graphs and the operators a mesh hierarchy
//! would give for them (adjacency, Laplacians, graph pooling's neighbourhoods; this crate does
//! not depend on `mesh-hierarchy`), a dense reference product and a central-finite-difference
//! gradient check in f64.

use candle_core::{DType, Device, Tensor, Var};
use sparse_csr::CsrMatrix;

/// A deterministic stream of numbers in [-1, 1) (splitmix64).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(1))
    }

    pub fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

pub fn random_vec(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| rng.next()).collect()
}

/// A random non-symmetric sparse matrix (so that forgetting a transpose shows).
pub fn random_matrix(rows: usize, cols: usize, density: f64, seed: u64) -> CsrMatrix {
    let mut rng = Rng::new(seed);
    let mut triplets = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            if (rng.next() + 1.0) / 2.0 < density {
                triplets.push((r as u32, c as u32, rng.next()));
            }
        }
    }
    CsrMatrix::from_triplets(rows, cols, &triplets).expect("valid triplets")
}

/// The faces of an n×m grid of vertices, two triangles per cell: a small mesh-like graph.
pub fn grid_faces(n: usize, m: usize) -> Vec<[u32; 3]> {
    let id = |i: usize, j: usize| (i * m + j) as u32;
    let mut faces = Vec::new();
    for i in 0..n - 1 {
        for j in 0..m - 1 {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    faces
}

/// The undirected, unweighted vertex adjacency of `n` vertices joined by the edges of `faces`:
/// A[i][j] = 1 when i and j share an edge, no self-loops.
pub fn adjacency(n: usize, faces: &[[u32; 3]]) -> CsrMatrix {
    let mut edges = std::collections::BTreeSet::new();
    for f in faces {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            if a != b {
                edges.insert((a, b));
                edges.insert((b, a));
            }
        }
    }
    let triplets: Vec<(u32, u32, f64)> = edges.into_iter().map(|(a, b)| (a, b, 1.0)).collect();
    CsrMatrix::from_triplets(n, n, &triplets).expect("face indices below n")
}

/// The normalised Laplacian L = I − D^-1/2 A D^-1/2 of an adjacency A (D: its row sums).
pub fn normalized_laplacian(a: &CsrMatrix) -> CsrMatrix {
    let n = a.rows();
    let inv_sqrt_degree: Vec<f64> = (0..n)
        .map(|r| {
            let d: f64 = a.row(r).1.iter().sum();
            if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 }
        })
        .collect();
    let mut triplets = Vec::new();
    for r in 0..n {
        triplets.push((r as u32, r as u32, 1.0));
        let (cols, vals) = a.row(r);
        for (&c, &v) in cols.iter().zip(vals) {
            triplets.push((
                r as u32,
                c,
                -v * inv_sqrt_degree[r] * inv_sqrt_degree[c as usize],
            ));
        }
    }
    CsrMatrix::from_triplets(n, n, &triplets).expect("indices of a valid matrix")
}

/// The rescaled Laplacian L̃ = 2L/λmax − I with λmax = 2 (the authors' choice), i.e. L − I.
pub fn rescaled_laplacian(l: &CsrMatrix) -> CsrMatrix {
    let lambda_max = 2.0;
    let n = l.rows();
    let mut triplets = Vec::new();
    for r in 0..n {
        triplets.push((r as u32, r as u32, -1.0));
        let (cols, vals) = l.row(r);
        for (&c, &v) in cols.iter().zip(vals) {
            triplets.push((r as u32, c, 2.0 * v / lambda_max));
        }
    }
    CsrMatrix::from_triplets(n, n, &triplets).expect("indices of a valid matrix")
}

/// L̃ of the mesh with `n` vertices and these faces: the Chebyshev operator of one level.
pub fn mesh_laplacian(n: usize, faces: &[[u32; 3]]) -> CsrMatrix {
    rescaled_laplacian(&normalized_laplacian(&adjacency(n, faces)))
}

/// Graph pooling's neighbourhoods (Shen et al. 2018): the m×n membership matrix with
/// M[c, u] = 1 for u in N(c) = the closed one-ring of the survivor `survivors[c]` ∪ the
/// cluster of c (`cluster_of[u] == c`); n = `cluster_of.len()`, m = `survivors.len()`.
pub fn neighbourhoods(faces: &[[u32; 3]], survivors: &[u32], cluster_of: &[u32]) -> CsrMatrix {
    let adj = adjacency(cluster_of.len(), faces);
    let mut members: Vec<std::collections::BTreeSet<u32>> = survivors
        .iter()
        .map(|&s| {
            std::iter::once(s)
                .chain(adj.row(s as usize).0.iter().copied())
                .collect()
        })
        .collect();
    for (u, &c) in cluster_of.iter().enumerate() {
        members[c as usize].insert(u as u32);
    }
    let triplets: Vec<(u32, u32, f64)> = members
        .iter()
        .enumerate()
        .flat_map(|(c, n_c)| n_c.iter().map(move |&u| (c as u32, u, 1.0)))
        .collect();
    CsrMatrix::from_triplets(survivors.len(), cluster_of.len(), &triplets)
        .expect("survivors and clusters in range")
}

/// y[b] = A x[b] with dense arithmetic; x is `[batch, A.cols, c]`.
pub fn dense_apply(m: &CsrMatrix, x: &[f64], batch: usize, c: usize) -> Vec<f64> {
    let dense = m.to_dense();
    let mut y = vec![0.0; batch * m.rows() * c];
    for b in 0..batch {
        for (i, row) in dense.iter().enumerate() {
            for (j, &a) in row.iter().enumerate() {
                for ch in 0..c {
                    y[(b * m.rows() + i) * c + ch] += a * x[(b * m.cols() + j) * c + ch];
                }
            }
        }
    }
    y
}

pub fn tensor(data: Vec<f64>, shape: &[usize]) -> Tensor {
    Tensor::from_vec(data, shape, &Device::Cpu).expect("shape matches data")
}

pub fn to_vec(t: &Tensor) -> Vec<f64> {
    t.to_dtype(DType::F64)
        .and_then(|t| t.flatten_all())
        .and_then(|t| t.to_vec1::<f64>())
        .expect("a float tensor")
}

pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> f64 {
    assert_eq!(a.dims(), b.dims());
    to_vec(a)
        .iter()
        .zip(to_vec(b))
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max)
}

/// Checks the autodiff gradient of `loss()` with respect to each of `vars` (f64) against central
/// finite differences at every entry (or every `stride`-th for larger variables). Returns the
/// largest relative error found; panics on a candle error.
pub fn grad_check(vars: &[&Var], loss: impl Fn() -> candle_core::Result<Tensor>) -> f64 {
    let eps = 1e-6;
    let grads = loss().and_then(|l| l.backward()).expect("backward");
    let mut worst: f64 = 0.0;
    for var in vars {
        let analytic = to_vec(grads.get(var).expect("a gradient for every var"));
        let base = to_vec(var.as_tensor());
        let stride = (base.len() / 60).max(1);
        for idx in (0..base.len()).step_by(stride) {
            let eval = |delta: f64| {
                let mut v = base.clone();
                v[idx] += delta;
                var.set(&tensor(v, var.dims())).expect("same shape");
                loss()
                    .and_then(|l| l.to_scalar::<f64>())
                    .expect("scalar loss")
            };
            let numeric = (eval(eps) - eval(-eps)) / (2.0 * eps);
            let err = (numeric - analytic[idx]).abs() / (1.0 + numeric.abs());
            worst = worst.max(err);
        }
        var.set(&tensor(base, var.dims())).expect("same shape");
    }
    worst
}

/// sum(r ⊙ y) with a fixed random r: a loss whose gradient reaches every output entry differently.
pub fn weighted_sum(y: &Tensor, seed: u64) -> candle_core::Result<Tensor> {
    let r = Tensor::from_vec(random_vec(y.elem_count(), seed), y.dims(), y.device())?
        .to_dtype(y.dtype())?;
    (y * r)?.sum_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn helper_operators_match_their_definitions() {
        // Two triangles 0-1-2, 0-2-3 and an isolated vertex 4.
        let a = adjacency(5, &[[0, 1, 2], [0, 2, 3]]).to_dense();
        assert_eq!(a[0], vec![0.0, 1.0, 1.0, 1.0, 0.0]);
        assert_eq!(a[1], vec![1.0, 0.0, 1.0, 0.0, 0.0]);
        assert_eq!(a[4], vec![0.0; 5]);
        let deg: Vec<f64> = a.iter().map(|r| r.iter().sum()).collect();
        let l = normalized_laplacian(&adjacency(5, &[[0, 1, 2], [0, 2, 3]])).to_dense();
        let lt = mesh_laplacian(5, &[[0, 1, 2], [0, 2, 3]]).to_dense();
        for i in 0..5 {
            for j in 0..5 {
                let eye = if i == j { 1.0 } else { 0.0 };
                let off = if a[i][j] == 0.0 {
                    0.0
                } else {
                    a[i][j] / (deg[i] * deg[j]).sqrt()
                };
                assert!((l[i][j] - (eye - off)).abs() < 1e-15);
                assert!((lt[i][j] + off).abs() < 1e-15);
            }
        }
        // A strip 0-1-2-3 over 4-5-6-7; coarse 0 = survivor 2 with cluster {2, 3, 7}, coarse 1 =
        // survivor 4 with {0, 1, 4}, coarse 2 = survivor 5 with {5, 6}.
        let faces = [
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
        ];
        let m = neighbourhoods(&faces, &[2, 4, 5], &[1, 1, 0, 0, 1, 2, 2, 0]);
        assert_eq!(m.row(0).0, [1, 2, 3, 6, 7]);
        assert_eq!(m.row(1).0, [0, 1, 4, 5]);
        assert_eq!(m.row(2).0, [0, 1, 4, 5, 6]);
        assert!(m.values().iter().all(|&v| v == 1.0));
    }
}
