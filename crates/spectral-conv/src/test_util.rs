//! Test helpers: deterministic random data, small graphs, a dense reference product and a
//! central-finite-difference gradient check in f64.

use candle_core::{DType, Device, Tensor, Var};
use mesh_hierarchy::CsrMatrix;

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
