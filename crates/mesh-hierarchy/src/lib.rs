//! # mesh-hierarchy: levels, Laplacians, pooling and de-pooling operators
//!
//! **In:** a template mesh and a [`HierarchyConfig`] (pooler, number of pooling steps, ratio per
//! step, λmax choice, de-pooling mode). **Out:** a [`Hierarchy`]: levels 0..=L, each with its
//! connectivity, positions and rescaled Laplacian L̃ = 2L/λmax − I, and between consecutive
//! levels a [`PoolingOp`] (pool m×n, de-pool n×m, all as [`CsrMatrix`], the type of the
//! `sparse-csr` crate, re-exported here). Saved to and loaded
//! from one file without recomputation ([`Hierarchy::save`], [`Hierarchy::load`]): safetensors
//! of the workspace's stamped convention, bit-exact; the older JSON files still load.
//!
//! ## Poolers ([`Pooler`], the paper's ablation)
//! - `ours` (alias `mean`): the simplifier with the edge-length term (λ = 0.001); mean pooling
//!   P[c, v] = 1/|C_c|; de-pooling copies (D[v, c] = 1, so P·D = I) or, with
//!   [`DepoolMode::Transpose`], is Pᵀ as in the authors' code.
//! - `qem`: classical QEM (λ = 0), same mean pooling.
//! - `max`: the paper's simplifier, signed largest magnitude per cluster
//!   ([`PoolingOp::pool`]); `pool` holds the mean matrix for consumers that need a matrix.
//! - `sampling` (CoMA): keep the survivors of classical QEM; up-sample by barycentric
//!   coordinates in the nearest coarse triangle (see [`sampling`]).
//! - `none`: identity operators; every level is the template.
//! - `graph` (Shen et al. 2018): our simplifier's coarse level; each coarse vertex takes the
//!   channel-wise max over its survivor's closed one-ring ∪ its cluster (overlapping
//!   neighbourhoods, see [`graph`]); de-pooling averages over the neighbourhoods containing a
//!   fine vertex.
//! - `remesh`: a uniform remeshing as the coarse level, mean pooling over its clusters.
//!
//! [`Pooler`]'s documentation gives the exact definitions of the last two. [`spiral`] gives
//! SpiralNet++'s spiral sequences on any level.
//!
//! ```
//! use mesh_hierarchy::{Hierarchy, HierarchyConfig, Pooler};
//! # fn main() -> Result<(), mesh_hierarchy::HierarchyError> {
//! let sphere = qem_simplify::shapes::icosphere(2);
//! let config = HierarchyConfig { pooler: Pooler::Mean, levels: 2, ..Default::default() };
//! let h = Hierarchy::build(&sphere, &config)?;
//! assert_eq!(h.vertex_counts(), vec![162, 81, 41]);
//! let coarse = h.pooling[0].pool(&vec![1.0; 162], 1)?;
//! assert!(coarse.iter().all(|x| (x - 1.0).abs() < 1e-12));
//! # Ok(()) }
//! ```

mod error;
mod file;
pub mod graph;
mod hierarchy;
pub mod laplacian;
pub mod pooling;
pub mod sampling;
pub mod spiral;

pub use error::HierarchyError;
pub use file::{FORMAT, VERSION};
pub use hierarchy::{Hierarchy, HierarchyConfig, Level};
pub use laplacian::{
    LambdaMax, adjacency, normalized_laplacian, rescaled_laplacian, try_adjacency,
};
pub use pooling::{DepoolMode, PoolMode, Pooler, PoolingOp, UnknownDepoolMode, UnknownPooler};
pub use sparse_csr::{CsrError, CsrMatrix};
pub use spiral::{Spirals, spirals};
