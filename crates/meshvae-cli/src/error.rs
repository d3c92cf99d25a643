//! The command's errors: each library's error, plus the command's own. `main` prints them.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
    #[error(transparent)]
    Features(#[from] deform_features::FeatureError),
    #[error(transparent)]
    Simplify(#[from] qem_simplify::SimplifyError),
    #[error(transparent)]
    Vae(#[from] meshvae::VaeError),
    #[error(transparent)]
    Render(#[from] mesh_render::RenderError),
    /// A bad combination of arguments that clap cannot catch.
    #[error("{argument}: {message}")]
    Argument {
        argument: &'static str,
        message: String,
    },
    #[error("{}: {message}", path.display())]
    Output { path: PathBuf, message: String },
    /// Training stopped by Ctrl-C or SIGTERM after writing its state; `next` says what to run
    /// to go on.
    #[error("{source}\n{next}")]
    Interrupted {
        source: meshvae::VaeError,
        next: String,
    },
}

impl CliError {
    /// The process's exit status for this error: 130 (as a shell reports Ctrl-C) for an
    /// interrupted training, 1 otherwise.
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::Interrupted { .. } => 130,
            _ => 1,
        }
    }

    pub fn argument(argument: &'static str, message: impl Into<String>) -> Self {
        Self::Argument {
            argument,
            message: message.into(),
        }
    }
}
