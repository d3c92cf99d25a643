//! A sparse symmetric positive-definite matrix factorised once (faer's supernodal/simplicial
//! Cholesky with AMD ordering), then solved many times.
//!
//! Parallelism is fixed to `Par::Seq` on purpose: on a 2-core machine faer's default (rayon)
//! makes a 3-column solve 5–10× slower (measured with faer 0.24). Callers
//! parallelise across shapes instead.

use crate::error::FeatureError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, MatMut, Par, Side};

const PAR: Par = Par::Seq;

/// An n×n SPD matrix's Cholesky factor.
#[derive(Debug)]
pub(crate) struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
}

impl Cholesky {
    /// Factorises the symmetric matrix given by `triplets` (duplicates are summed; both
    /// triangles or only the lower one may be given: only the lower triangle is read).
    /// `regularize` replaces pivots below `epsilon` by `delta` (for matrices with exact
    /// null directions that the right-hand sides never excite).
    pub fn new(
        n: usize,
        triplets: &[Triplet<usize, usize, f64>],
        system: &'static str,
        regularize: Option<(f64, f64)>,
    ) -> Result<Self, FeatureError> {
        let fail = |message: String| FeatureError::Factorization { system, message };
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, triplets)
            .map_err(|e| fail(format!("{e:?}")))?;
        let symbolic = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| fail(format!("{e:?}")))?;
        let mut values = vec![0.0; symbolic.len_val()];
        let mut mem = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(PAR, Default::default()),
        )
        .map_err(|e| fail(format!("{e:?}")))?;
        let regularization = match regularize {
            Some((epsilon, delta)) => LltRegularization {
                dynamic_regularization_delta: delta,
                dynamic_regularization_epsilon: epsilon,
            },
            None => LltRegularization::default(),
        };
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut values,
                a.as_ref(),
                Side::Lower,
                regularization,
                PAR,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| fail(format!("{e:?}")))?;
        Ok(Self { symbolic, values })
    }

    /// Solves `A x = b` for every column of `rhs`, in place.
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>) {
        let mut mem = MemBuffer::new(
            self.symbolic
                .solve_in_place_scratch::<f64>(rhs.ncols(), PAR),
        );
        LltRef::<usize, f64>::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            PAR,
            MemStack::new(&mut mem),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    #[test]
    fn solves_a_small_spd_system_like_a_dense_reference() {
        // A 1-D Laplacian plus identity, 3 right-hand sides.
        let n = 30;
        let mut t = Vec::new();
        let mut dense = vec![vec![0.0; n]; n];
        for i in 0..n {
            t.push(Triplet::new(i, i, 3.0));
            dense[i][i] = 3.0;
            if i + 1 < n {
                t.push(Triplet::new(i + 1, i, -1.0));
                t.push(Triplet::new(i, i + 1, -1.0));
                dense[i + 1][i] = -1.0;
                dense[i][i + 1] = -1.0;
            }
        }
        let chol = Cholesky::new(n, &t, "test", None).unwrap();
        let x_true = Mat::<f64>::from_fn(n, 3, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
        let mut b = Mat::<f64>::from_fn(n, 3, |i, j| {
            (0..n).map(|k| dense[i][k] * x_true[(k, j)]).sum()
        });
        chol.solve_in_place(b.as_mut());
        for i in 0..n {
            for j in 0..3 {
                assert!((b[(i, j)] - x_true[(i, j)]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn indefinite_matrix_is_an_error() {
        let t = [Triplet::new(0, 0, 1.0), Triplet::new(1, 1, -1.0)];
        assert!(matches!(
            Cholesky::new(2, &t, "test", None),
            Err(FeatureError::Factorization { .. })
        ));
    }
}
