//! # qem-simplify: quadric edge collapse with the paper's edge-length term
//!
//! **In:** a template [`mesh_io::TriMesh`] (a 2-manifold, with or without boundary).
//! **Out:** a [`Simplified`]: the coarse mesh, and the map fine vertex → coarse vertex that
//! mesh pooling averages over (every fine vertex in exactly one cluster, every cluster connected
//! on the fine mesh), plus reports on how even ([`UniformityReport`]) and how faithful
//! ([`geometric_error_rel`]) the result is.
//! [`remesh`] is the ablation's alternative: isotropic remeshing to the same count, with clusters
//! by geodesic nearest coarse vertex (see [`RemeshConfig`]).
//!
//! ## The method
//! Garland–Heckbert edge contraction, cheapest first, with the cost of Eq. 1 of Yuan et al. 2020:
//! contracting (v_i, v_j) into v̄ costs v̄ᵀ(Q_i + Q_j)v̄ + λ · (the longest of the new edges from v̄
//! to the other neighbours of v_i and v_j). The length term avoids long edges, so the coarse
//! vertices stand for evenly sized regions, which is what pooling needs.
//!
//! - **Scale.** Quadrics and lengths are measured on the mesh translated and scaled to a unit
//!   bounding-box diagonal, so one λ fits every mesh: [`DEFAULT_LAMBDA`] = 0.001 (the paper's).
//!   λ = 0 is the classical method. The output is in the input's own units.
//! - **Quadrics.** Each vertex starts with the sum of the (unweighted, as in the 1997 paper)
//!   planes of its faces; each boundary edge adds a plane through it, perpendicular to its face,
//!   with weight 100, which keeps the boundary in place.
//! - **Placement.** v̄ solves the 3×3 system of Q_i + Q_j; when that is singular, or its solution
//!   lies more than one edge length from the edge's midpoint (a nearly flat quadric), v̄ is
//!   whichever of the midpoint and the two ends has the least quadric error.
//! - **Validity.** A contraction happens only if it passes the link condition (boundaries closed
//!   by a virtual vertex: the output is a 2-manifold of the same topology and Euler
//!   characteristic), flips no face against its current normal nor against the fine face it
//!   descends from, and makes no face a sliver (shape quality below 0.01, unless it was already
//!   worse). An invalid candidate waits until a contraction nearby re-costs it.
//! - **Order.** Ties are broken by edge id, so the same input gives the same output on any run
//!   and on any number of threads (the set-up — edge table, initial costs — runs on rayon's
//!   pool; the contraction loop is sequential).
//! - **Target.** Exactly the requested vertex count (default: half, rounded up, as the paper
//!   contracts half per level), or [`SimplifyError::TargetUnreachable`].
//! - **Result.** Coarse vertex k is the k-th surviving fine vertex in ascending index (the
//!   authors' convention), placed at its final v̄; each fine vertex belongs to the cluster of its
//!   last surviving ancestor. Pooling needs only that map; the coarse positions matter for the
//!   coarse mesh's own connectivity and Laplacian and for the geometric error.
//!
//! ```
//! use qem_simplify::{simplify, SimplifyConfig, UniformityReport};
//! # fn main() -> Result<(), qem_simplify::SimplifyError> {
//! let sphere = qem_simplify::shapes::icosphere(3);
//! let result = simplify(&sphere, &SimplifyConfig::default())?;
//! assert_eq!(result.coarse.vertex_count(), sphere.vertex_count().div_ceil(2));
//! let report = UniformityReport::of(&sphere, &result);
//! println!("edge-length CV {:.3}, largest cluster {}", report.edge_cv, report.cluster_max);
//! # Ok(()) }
//! ```

mod collapse;
mod connectivity;
mod error;
mod geometry;
mod heap;
mod lists;
pub mod manifold;
mod nearest;
mod prefetch;
pub mod quadric;
mod remesh;
mod report;
pub mod shapes;
mod simplify;

pub use error::{Result, SimplifyError};
pub use remesh::{RemeshConfig, Remeshed, Smoothing, flipped_faces_on_surface, remesh};
pub use report::{
    Method, SimplifyReport, UniformityReport, edge_length_cv, flipped_faces, geometric_error_rel,
};
pub use simplify::{DEFAULT_LAMBDA, Simplified, SimplifyConfig, Target, simplify};
