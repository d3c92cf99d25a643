//! [`CsrMatrix`]: a compressed-sparse-row matrix with f64 values, checked on construction.
//! Every operator of a mesh hierarchy is stored as one (Laplacians, pooling, de-pooling);
//! consumers that need another precision convert once.

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
        m.validate()?;
        Ok(m)
    }

    /// Checks every invariant of [`CsrMatrix::new`]: `indptr` has `rows + 1` entries from 0 to
    /// `nnz`, never decreasing; each row's columns are strictly increasing and below `cols`;
    /// every value is finite. A deserialised matrix has not been through `new`: call this on
    /// it before use.
    pub fn validate(&self) -> Result<(), CsrError> {
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

    #[inline]
    pub fn rows(&self) -> usize {
        self.rows
    }

    #[inline]
    pub fn cols(&self) -> usize {
        self.cols
    }

    #[inline]
    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    #[inline]
    pub fn indptr(&self) -> &[usize] {
        &self.indptr
    }

    #[inline]
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    #[inline]
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Row `r` as (columns, values).
    #[inline]
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

    /// The matrix with renumbered rows and columns: row p of the result is row `rows[p]` of
    /// this one, and column `c` becomes `col_pos[c]` (the position of `c` in the new column
    /// order, i.e. the inverse of that order). `None` keeps a side's numbering. Each row's
    /// entries are sorted by their new column; values are moved, never recomputed.
    ///
    /// Errors: `rows` not `self.rows()` long or naming a row beyond; `col_pos` not
    /// `self.cols()` long, or sending a column beyond `cols` or two columns of one row to the
    /// same position (a permutation of each side never does).
    pub fn permuted(
        &self,
        rows: Option<&[u32]>,
        col_pos: Option<&[u32]>,
    ) -> Result<Self, CsrError> {
        if let Some(o) = rows {
            if o.len() != self.rows {
                return Err(CsrError(format!(
                    "row order has {} entries for {} rows",
                    o.len(),
                    self.rows
                )));
            }
            if let Some(&r) = o.iter().find(|&&r| r as usize >= self.rows) {
                return Err(CsrError(format!(
                    "row order names row {r}, beyond {}",
                    self.rows
                )));
            }
        }
        if let Some(pos) = col_pos
            && pos.len() != self.cols
        {
            return Err(CsrError(format!(
                "column positions have {} entries for {} columns",
                pos.len(),
                self.cols
            )));
        }
        let mut indptr = Vec::with_capacity(self.rows + 1);
        let mut indices = Vec::with_capacity(self.nnz());
        let mut values = Vec::with_capacity(self.nnz());
        indptr.push(0);
        let mut entries: Vec<(u32, usize)> = Vec::new();
        for p in 0..self.rows {
            let r = rows.map_or(p, |o| o[p] as usize);
            entries.clear();
            entries.extend((self.indptr[r]..self.indptr[r + 1]).map(|e| {
                let c = self.indices[e];
                (col_pos.map_or(c, |pos| pos[c as usize]), e)
            }));
            entries.sort_unstable();
            for &(c, e) in &entries {
                indices.push(c);
                values.push(self.values[e]);
            }
            indptr.push(indices.len());
        }
        Self::new(self.rows, self.cols, indptr, indices, values)
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

    #[test]
    fn validate_rejects_what_new_rejects() {
        // As a deserialised matrix would arrive: built without `new`.
        let raw = |indptr: Vec<usize>, indices: Vec<u32>, values: Vec<f64>| CsrMatrix {
            rows: 2,
            cols: 3,
            indptr,
            indices,
            values,
        };
        assert!(
            raw(vec![0, 1, 2], vec![2, 0], vec![1.0, -1.0])
                .validate()
                .is_ok()
        );
        for bad in [
            raw(vec![0, 1], vec![2], vec![1.0]), // indptr too short
            raw(vec![1, 1, 2], vec![2, 0], vec![1.0, -1.0]), // indptr not from 0
            raw(vec![0, 2, 1], vec![2, 0], vec![1.0, -1.0]), // indptr decreases
            raw(vec![0, 1, 2], vec![2, 0], vec![1.0]), // lengths disagree
            raw(vec![0, 2, 2], vec![2, 0], vec![1.0, -1.0]), // unsorted row
            raw(vec![0, 2, 2], vec![1, 1], vec![1.0, -1.0]), // repeated column
            raw(vec![0, 1, 2], vec![3, 0], vec![1.0, -1.0]), // column out of range
            raw(vec![0, 1, 2], vec![2, 0], vec![f64::NAN, -1.0]), // non-finite value
            raw(vec![0, 1, 2], vec![2, 0], vec![1.0, f64::INFINITY]), // non-finite value
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        let e = raw(vec![0, 2, 2], vec![1, 1], vec![1.0, -1.0])
            .validate()
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid sparse matrix: row 0 has unsorted or repeated columns"
        );
    }

    #[test]
    fn permuted_renumbers_rows_and_columns_and_moves_values() {
        let t = [
            (0, 1, 2.0),
            (0, 3, 5.0),
            (1, 0, -1.0),
            (2, 2, 4.0),
            (2, 3, 0.5),
        ];
        let a = CsrMatrix::from_triplets(3, 4, &t).unwrap();
        let rows = [2u32, 0, 1];
        let order = [3u32, 1, 0, 2]; // new column q holds old column order[q]
        let mut col_pos = [0u32; 4];
        for (q, &c) in order.iter().enumerate() {
            col_pos[c as usize] = q as u32;
        }
        let p = a.permuted(Some(&rows), Some(&col_pos)).unwrap();
        let (dense, pdense) = (a.to_dense(), p.to_dense());
        for i in 0..3 {
            for q in 0..4 {
                assert_eq!(pdense[i][q], dense[rows[i] as usize][order[q] as usize]);
            }
        }
        assert_eq!(p.row(0), (&[0u32, 3][..], &[0.5, 4.0][..]));
        assert_eq!(p.nnz(), a.nnz());
        assert_eq!(a.permuted(None, None).unwrap(), a);
        assert_eq!(a.permuted(Some(&[0, 1, 2]), None).unwrap(), a);
        // Bad orders are errors, not panics.
        assert!(a.permuted(Some(&[0, 1]), None).is_err());
        assert!(a.permuted(Some(&[0, 1, 3]), None).is_err());
        assert!(a.permuted(None, Some(&[0, 1, 2])).is_err());
        assert!(a.permuted(None, Some(&[0, 1, 2, 4])).is_err());
        assert!(a.permuted(None, Some(&[0, 0, 2, 0])).is_err()); // columns 1 and 3 of row 0 collide
    }
}
