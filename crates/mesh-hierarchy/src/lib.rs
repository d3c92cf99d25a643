//! # mesh-hierarchy: levels, Laplacians, pooling and de-pooling operators
//!
//! In: a template mesh and a per-level ratio. Out: a serialisable hierarchy of graphs, rescaled
//! Laplacians and pooling operators, all as [`CsrMatrix`].
//!
//! Built so far: the sparse matrix type and the graph Laplacians of one level. Levels and
//! pooling operators come with the hierarchy work.

pub mod laplacian;
pub mod sparse;

pub use laplacian::{LambdaMax, adjacency, normalized_laplacian, rescaled_laplacian};
pub use sparse::{CsrError, CsrMatrix};
