//! The one error type of this crate. Every variant names the argument (or file) and what is wrong.

use std::path::PathBuf;

/// Everything that can go wrong rendering, plotting, composing or writing pictures.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// An input that must not be empty is (no vertices, no faces, no tiles, no points, …).
    #[error("{argument}: empty (nothing to draw)")]
    Empty { argument: &'static str },
    /// A face refers to a vertex that does not exist.
    #[error("faces: face {face} refers to vertex {index}, but there are {vertices} vertices")]
    FaceIndex {
        face: usize,
        index: u32,
        vertices: usize,
    },
    /// A coordinate (or value) is NaN or infinite.
    #[error("{argument}: item {index} has a non-finite value ({value})")]
    NonFinite {
        argument: &'static str,
        index: usize,
        value: f32,
    },
    /// A per-vertex array whose length does not match the vertex count.
    #[error("{argument}: {found} entries for {expected} vertices")]
    Length {
        argument: &'static str,
        expected: usize,
        found: usize,
    },
    /// An image size that is zero, too large, or inconsistent with its pixel buffer.
    #[error("{argument}: bad size {width}x{height}: {message}")]
    Size {
        argument: &'static str,
        width: u64,
        height: u64,
        message: String,
    },
    /// Any other argument out of its domain (columns = 0, a negative maximum, …).
    #[error("{argument}: {message}")]
    InvalidArgument {
        argument: &'static str,
        message: String,
    },
    /// Drawing text or a plot failed (e.g. the embedded font could not be loaded).
    #[error("drawing {what}: {message}")]
    Draw { what: &'static str, message: String },
    /// PNG encoding or decoding failed; `path` is `<memory>` for in-memory data.
    #[error("{}: PNG: {message}", path.display())]
    Png { path: PathBuf, message: String },
    /// Writing or reading a file failed (the error names the file).
    #[error(transparent)]
    Io(#[from] mesh_io::MeshIoError),
}

impl RenderError {
    pub(crate) fn invalid(argument: &'static str, message: impl Into<String>) -> Self {
        Self::InvalidArgument {
            argument,
            message: message.into(),
        }
    }
}
