//! The one error type of this crate: every variant says which file, argument or stage failed
//! and what is wrong.

use std::path::PathBuf;

/// Everything that can go wrong building, training, saving, loading or evaluating a model.
#[derive(Debug, thiserror::Error)]
pub enum VaeError {
    /// A configuration value or argument is unusable.
    #[error("invalid {arg}: {what}")]
    Argument { arg: String, what: String },
    /// A tensor or data shape does not fit the model.
    #[error("{op}: {what}")]
    Shape { op: &'static str, what: String },
    /// A model folder or file is missing, foreign, or inconsistent.
    #[error("{}: {what}", path.display())]
    Model { path: PathBuf, what: String },
    /// Training diverged.
    #[error("training stopped: {0}")]
    Diverged(String),
    /// Training stopped on request ([`crate::StopFlag`], e.g. Ctrl-C) after writing its best
    /// epoch's state; resuming the folder continues the run.
    #[error("{}: training interrupted after epoch {epoch}; {}", dir.display(), match checkpoint {
        Some(c) => format!("its checkpoint holds epoch {c}, where a resumed run continues"),
        None => "no checkpoint yet, so a resumed run starts afresh".to_string(),
    })]
    Interrupted {
        dir: PathBuf,
        /// The last epoch finished.
        epoch: usize,
        /// The epoch of the checkpoint in the folder (the best so far), if there is one.
        checkpoint: Option<usize>,
    },
    /// Reading or writing a file.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
    #[error(transparent)]
    Features(#[from] deform_features::FeatureError),
    #[error(transparent)]
    Hierarchy(#[from] mesh_hierarchy::HierarchyError),
    #[error(transparent)]
    Conv(#[from] spectral_conv::ConvError),
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
}

/// This crate's result type.
pub type Result<T> = std::result::Result<T, VaeError>;

impl VaeError {
    pub fn argument(arg: impl Into<String>, what: impl Into<String>) -> Self {
        Self::Argument {
            arg: arg.into(),
            what: what.into(),
        }
    }

    pub fn shape(op: &'static str, what: impl Into<String>) -> Self {
        Self::Shape {
            op,
            what: what.into(),
        }
    }

    pub fn model(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Self::Model {
            path: path.into(),
            what: what.into(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
