//! # deform-features: per-vertex ACAP deformation features and their inverse
//!
//! Not built yet (issue "deform-features"). In: a `mesh_io::MeshSet` and its rest mesh. Out:
//! per-vertex 9-number features (log-rotation 3 + stretch 6), their normalisation, and meshes
//! reconstructed from features.

mod error;
pub use error::FeatureError;
