//! The one error type of this crate. Every variant names the file or argument and what is wrong.

use std::path::PathBuf;

/// Everything that can go wrong building, saving or loading a [`crate::Hierarchy`].
#[derive(Debug, thiserror::Error)]
pub enum HierarchyError {
    #[error(transparent)]
    Simplify(#[from] qem_simplify::SimplifyError),
    #[error(transparent)]
    Csr(#[from] sparse_csr::CsrError),
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
    /// A configuration value out of range (`argument` names it, e.g. `"ratio"`).
    #[error("invalid argument {argument}: {message}")]
    InvalidArgument {
        argument: &'static str,
        message: String,
    },
    /// A hierarchy file that cannot be read, is foreign, newer than this build or damaged
    /// (checksum), lacks a tensor or has one of the wrong type or length, or whose operators
    /// disagree on their sizes.
    #[error("{}: not a valid hierarchy file: {message}", path.display())]
    File { path: PathBuf, message: String },
}

impl HierarchyError {
    pub(crate) fn file(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::File {
            path: path.into(),
            message: message.into(),
        }
    }
}
