//! The one error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong computing or inverting deformation features.
#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
    /// The rest mesh cannot carry features (no faces, index out of range, non-finite, …).
    #[error("invalid rest mesh: {message}")]
    InvalidMesh { message: String },
    /// A frame, feature array or normalisation does not fit the rest mesh or the other inputs.
    #[error("{what}: expected {expected}, found {found}")]
    ShapeMismatch {
        what: String,
        expected: String,
        found: String,
    },
    /// An input value that cannot be used (NaN in features, a bad option value, …).
    #[error("{what}: {message}")]
    InvalidInput { what: String, message: String },
    #[error("invalid option {option}: {message}")]
    InvalidOption {
        option: &'static str,
        message: String,
    },
    /// The sparse Cholesky factorisation failed (e.g. the matrix is not positive definite).
    #[error("factorising the {system}: {message}")]
    Factorization {
        system: &'static str,
        message: String,
    },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A features file that is not what [`crate::io::save_features`] writes.
    #[error("{}: not a valid features file: {message}", path.display())]
    Format { path: PathBuf, message: String },
}

impl FeatureError {
    pub(crate) fn invalid_mesh(message: impl Into<String>) -> Self {
        Self::InvalidMesh {
            message: message.into(),
        }
    }

    pub(crate) fn shape(
        what: impl Into<String>,
        expected: impl std::fmt::Display,
        found: impl std::fmt::Display,
    ) -> Self {
        Self::ShapeMismatch {
            what: what.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }

    pub(crate) fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::InvalidInput {
            what: what.into(),
            message: message.into(),
        }
    }
}
