//! The one error type of this crate. Every variant names the file (or argument) and what is wrong.

use std::path::PathBuf;

/// Everything that can go wrong reading, validating or writing meshes and mesh sets.
#[derive(Debug, thiserror::Error)]
pub enum MeshIoError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A syntax error; `line` is 1-based (0 where the format has no lines, e.g. binary data).
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{}: unsupported file type (expected .obj, .off, .ply, .glb, .gltf or .mvset)", path.display())]
    UnsupportedFormat { path: PathBuf },
    #[error("{}:{line}: face with {arity} vertices; only triangles and quads are accepted", path.display())]
    NonTriangleFace {
        path: PathBuf,
        line: usize,
        arity: usize,
    },
    #[error("{}:{line}: vertex index {index} is out of range (the mesh has {vertices} vertices)", path.display())]
    IndexOutOfRange {
        path: PathBuf,
        line: usize,
        index: i64,
        vertices: usize,
    },
    #[error("{}: vertex {vertex} has a non-finite coordinate ({value})", path.display())]
    NonFinite {
        path: PathBuf,
        vertex: usize,
        value: f32,
    },
    #[error("{}: the mesh has no vertices or no faces", path.display())]
    EmptyMesh { path: PathBuf },
    #[error("{}: {found} vertices, but {reference} has {expected}: all meshes of a set must share one connectivity", path.display(), reference = reference.display())]
    VertexCountMismatch {
        path: PathBuf,
        reference: PathBuf,
        expected: usize,
        found: usize,
    },
    #[error("{}: {detail}, unlike {reference}: all meshes of a set must share one connectivity", path.display(), reference = reference.display())]
    FaceMismatch {
        path: PathBuf,
        reference: PathBuf,
        detail: String,
    },
    #[error("{}: no mesh files found (looked for .obj, .off, .ply, .glb, .gltf)", path.display())]
    EmptySet { path: PathBuf },
    #[error("{}: a mesh set needs at least two meshes, found {count}", path.display())]
    TooFewMeshes { path: PathBuf, count: usize },
    #[error("{}: {message}", path.display())]
    Gltf { path: PathBuf, message: String },
    #[error("{}: not a valid mesh-set cache: {message}", path.display())]
    Cache { path: PathBuf, message: String },
    /// A safetensors file of the tool that is damaged, foreign or newer than this build.
    #[error("{}: {message}", path.display())]
    Tensors { path: PathBuf, message: String },
    #[error("{}:{line}: {message}", path.display())]
    Labels {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("invalid argument {argument}: {message}")]
    InvalidArgument {
        argument: &'static str,
        message: String,
    },
}

impl MeshIoError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn parse(path: impl Into<PathBuf>, line: usize, message: impl Into<String>) -> Self {
        Self::Parse {
            path: path.into(),
            line,
            message: message.into(),
        }
    }
}

pub type Result<T, E = MeshIoError> = std::result::Result<T, E>;

/// Something suspicious that did not stop reading (a quad that was split, a duplicate name, …).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    pub path: PathBuf,
    pub message: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}
