//! The one error type of this crate. Every variant says which input or argument is wrong.

/// Everything that can go wrong simplifying a mesh.
#[derive(Debug, thiserror::Error)]
pub enum SimplifyError {
    #[error(transparent)]
    MeshIo(#[from] mesh_io::MeshIoError),
    /// A configuration value out of range (`argument` names it, e.g. `"lambda"`).
    #[error("invalid argument {argument}: {message}")]
    InvalidArgument {
        argument: &'static str,
        message: String,
    },
    /// The input is not a 2-manifold triangle mesh (with or without boundary).
    #[error("the input mesh is not a 2-manifold: {0}")]
    NonManifold(crate::manifold::ManifoldDefect),
    /// All the vertices coincide: there is no scale to measure the edge-length term against.
    #[error("the input mesh has a zero bounding box (all {vertices} vertices coincide)")]
    ZeroExtent { vertices: usize },
    /// No valid contraction is left before the target count is reached (every remaining edge
    /// would break the manifold, flip or degenerate a face).
    #[error(
        "cannot reach {target} vertices: every remaining contraction is invalid at {reached} \
         vertices"
    )]
    TargetUnreachable { target: usize, reached: usize },
    /// The faces have zero total area: there is no surface to remesh.
    #[error("the input mesh has zero area (all {faces} faces are degenerate)")]
    ZeroArea { faces: usize },
    /// A remeshing put more coarse vertices on a connected component of the template than it
    /// has fine vertices, so not every cluster can hold a fine vertex of its own.
    #[error(
        "component {component} of the template has {fine} vertices, fewer than the {coarse} \
         coarse vertices remeshed onto it"
    )]
    ComponentTooSmall {
        component: usize,
        fine: usize,
        coarse: usize,
    },
}

/// This crate's result type.
pub type Result<T, E = SimplifyError> = std::result::Result<T, E>;
