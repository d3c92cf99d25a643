//! # qem-simplify: quadric edge collapse with the paper's edge-length term
//!
//! Not built yet (issue "qem-simplify and mesh-hierarchy"). In: a template `mesh_io::TriMesh`.
//! Out: a coarse mesh and the map from fine vertices to coarse vertices.

mod error;
pub use error::SimplifyError;
