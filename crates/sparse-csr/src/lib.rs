//! # sparse-csr: a validated compressed-sparse-row matrix
//!
//! **In:** a matrix's CSR arrays (row pointers, column indices, values) or its (row, column,
//! value) triplets. **Out:** a [`CsrMatrix`] whose invariants hold (row pointers that fit,
//! columns sorted, unique and in range, finite f64 values), or a [`CsrError`] saying which one
//! fails; then row access as slices, the transpose, products with a vector, a dense copy and
//! renumbered rows and columns ([`CsrMatrix::permuted`]).
//!
//! It is the one sparse type of the workspace: `mesh-hierarchy` stores its Laplacians and
//! pooling operators in it (and re-exports it), and `spectral-conv` takes it as input, without
//! either depending on the other. A matrix that was deserialised (serde) has not been through
//! [`CsrMatrix::new`]; check it with [`CsrMatrix::validate`].
//!
//! ```
//! use sparse_csr::CsrMatrix;
//!
//! # fn main() -> Result<(), sparse_csr::CsrError> {
//! // [[0, 2.5], [-1, 4]]; duplicates are summed.
//! let a = CsrMatrix::from_triplets(2, 2, &[(0, 1, 2.0), (1, 1, 4.0), (0, 1, 0.5), (1, 0, -1.0)])?;
//! assert_eq!(a.nnz(), 3);
//! assert_eq!(a.row(1), (&[0u32, 1][..], &[-1.0, 4.0][..]));
//! assert_eq!(a.mul_vec(&[1.0, 2.0]), vec![5.0, 7.0]);
//! assert_eq!(a.transpose().to_dense(), vec![vec![0.0, -1.0], vec![2.5, 4.0]]);
//! // Columns must be sorted and in range.
//! assert!(CsrMatrix::new(1, 2, vec![0, 2], vec![1, 0], vec![1.0, 1.0]).is_err());
//! # Ok(()) }
//! ```

mod csr;

pub use csr::{CsrError, CsrMatrix};
