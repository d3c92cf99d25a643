//! The one error type of this crate.

/// Everything that can go wrong computing or inverting deformation features.
#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
}
