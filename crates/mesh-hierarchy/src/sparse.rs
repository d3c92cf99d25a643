//! `CsrMatrix`: the compressed-sparse-row matrix every operator of a hierarchy is stored as
//! (Laplacians, pooling, de-pooling). Values are f64; consumers convert once.

use serde::{Deserialize, Serialize};

/// A sparse matrix in CSR form: row `r`'s entries are `indices[indptr[r]..indptr[r + 1]]` (column
/// indices, strictly increasing within a row) with `values` alongside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CsrMatrix {
    rows: usize,
    cols: usize,
    indptr: Vec<usize>,
    indices: Vec<u32>,
    values: Vec<f64>,
}

/// Why a set of arrays is not a valid CSR matrix.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid sparse matrix: {0}")]
pub struct CsrError(pub String);

impl CsrMatrix {
    /// Builds from CSR arrays, checking every invariant (sorted unique columns, in range).
    pub fn new(
        rows: usize,
        cols: usize,
        indptr: Vec<usize>,
        indices: Vec<u32>,
        values: Vec<f64>,
    ) -> Result<Self, CsrError> {
        let m = Self {
            rows,
            cols,
            indptr,
            indices,
            values,
        };
        m.check()?;
        Ok(m)
    }

    /// Checks every invariant of [`CsrMatrix::new`]; a deserialised matrix has not been
    /// through it.
    pub(crate) fn check(&self) -> Result<(), CsrError> {
        let (rows, cols) = (self.rows, self.cols);
        let (indptr, indices, values) = (&self.indptr, &self.indices, &self.values);
        if Some(indptr.len()) != rows.checked_add(1) || indptr[0] != 0 {
            return Err(CsrError(format!(
                "indptr has {} entries for {rows} rows",
                indptr.len()
            )));
        }
        if indices.len() != values.len() || indptr[rows] != indices.len() {
            return Err(CsrError(
                "indptr, indices and values disagree on the length".into(),
            ));
        }
        for r in 0..rows {
            let (a, b) = (indptr[r], indptr[r + 1]);
            if a > b || b > indices.len() {
                return Err(CsrError(format!("indptr decreases or overruns at row {r}")));
            }
            let row = &indices[a..b];
            if row.windows(2).any(|w| w[0] >= w[1]) {
                return Err(CsrError(format!(
                    "row {r} has unsorted or repeated columns"
                )));
            }
            if row.last().is_some_and(|&c| c as usize >= cols) {
                return Err(CsrError(format!("row {r} has a column beyond {cols}")));
            }
        }
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(CsrError(format!("non-finite value {v}")));
        }
        Ok(())
    }

    /// Builds from (row, column, value) triplets; duplicates are summed, explicit zeros kept.
    pub fn from_triplets(
        rows: usize,
        cols: usize,
        triplets: &[(u32, u32, f64)],
    ) -> Result<Self, CsrError> {
        if let Some(t) = triplets
            .iter()
            .find(|t| t.0 as usize >= rows || t.1 as usize >= cols)
        {
            return Err(CsrError(format!(
                "entry ({}, {}) outside {rows}x{cols}",
                t.0, t.1
            )));
        }
        let mut sorted = triplets.to_vec();
        sorted.sort_by_key(|t| (t.0, t.1));
        let mut indptr = vec![0usize; rows + 1];
        let mut indices: Vec<u32> = Vec::with_capacity(sorted.len());
        let mut values: Vec<f64> = Vec::with_capacity(sorted.len());
        let mut last: Option<(u32, u32)> = None;
        for &(r, c, v) in &sorted {
            if last == Some((r, c)) {
                *values.last_mut().expect("a previous entry exists") += v;
                continue;
            }
            last = Some((r, c));
            indptr[r as usize + 1] += 1;
            indices.push(c);
            values.push(v);
        }
        for r in 0..rows {
            indptr[r + 1] += indptr[r];
        }
        Self::new(rows, cols, indptr, indices, values)
    }

    /// The n×n identity.
    pub fn identity(n: usize) -> Self {
        Self {
            rows: n,
            cols: n,
            indptr: (0..=n).collect(),
            indices: (0..n as u32).collect(),
            values: vec![1.0; n],
        }
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    pub fn cols(&self) -> usize {
        self.cols
    }

    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    pub fn indptr(&self) -> &[usize] {
        &self.indptr
    }

    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Row `r` as (columns, values).
    pub fn row(&self, r: usize) -> (&[u32], &[f64]) {
        let span = self.indptr[r]..self.indptr[r + 1];
        (&self.indices[span.clone()], &self.values[span])
    }

    /// The transpose, again in CSR form (so a kernel can apply Aᵀ row by row).
    pub fn transpose(&self) -> Self {
        let mut counts = vec![0usize; self.cols + 1];
        for &c in &self.indices {
            counts[c as usize + 1] += 1;
        }
        for c in 0..self.cols {
            counts[c + 1] += counts[c];
        }
        let indptr = counts.clone();
        let mut next = counts;
        let mut indices = vec![0u32; self.nnz()];
        let mut values = vec![0f64; self.nnz()];
        for r in 0..self.rows {
            let (cols, vals) = self.row(r);
            for (&c, &v) in cols.iter().zip(vals) {
                let k = next[c as usize];
                indices[k] = r as u32;
                values[k] = v;
                next[c as usize] += 1;
            }
        }
        Self {
            rows: self.cols,
            cols: self.rows,
            indptr,
            indices,
            values,
        }
    }

    /// y = A x for one column vector.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        (0..self.rows)
            .map(|r| {
                let (cols, vals) = self.row(r);
                cols.iter()
                    .zip(vals)
                    .map(|(&c, &v)| v * x[c as usize])
                    .sum()
            })
            .collect()
    }

    /// The dense matrix, row-major; for tests and small meshes.
    pub fn to_dense(&self) -> Vec<Vec<f64>> {
        let mut dense = vec![vec![0.0; self.cols]; self.rows];
        for (r, row) in dense.iter_mut().enumerate() {
            let (cols, vals) = self.row(r);
            for (&c, &v) in cols.iter().zip(vals) {
                row[c as usize] = v;
            }
        }
        dense
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triplets_transpose_and_product_match_dense() {
        let t = [
            (0, 1, 2.0),
            (2, 0, -1.0),
            (0, 1, 0.5),
            (1, 2, 3.0),
            (2, 2, 4.0),
        ];
        let a = CsrMatrix::from_triplets(3, 3, &t).unwrap();
        let dense = a.to_dense();
        assert_eq!(
            dense,
            vec![
                vec![0.0, 2.5, 0.0],
                vec![0.0, 0.0, 3.0],
                vec![-1.0, 0.0, 4.0]
            ]
        );
        let at = a.transpose().to_dense();
        for r in 0..3 {
            for c in 0..3 {
                assert_eq!(at[r][c], dense[c][r]);
            }
        }
        assert_eq!(a.mul_vec(&[1.0, 2.0, 3.0]), vec![5.0, 9.0, 11.0]);
        assert!(CsrMatrix::from_triplets(2, 2, &[(2, 0, 1.0)]).is_err());
        assert!(CsrMatrix::new(1, 2, vec![0, 2], vec![1, 0], vec![1.0, 1.0]).is_err());
    }
}
