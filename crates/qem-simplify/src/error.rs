//! The one error type of this crate.

/// Everything that can go wrong simplifying a mesh.
#[derive(Debug, thiserror::Error)]
pub enum SimplifyError {
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
}
