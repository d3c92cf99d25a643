//! Numerics that know nothing of meshes or of the network: the seeded random stream every draw
//! of a run comes from ([`rng::Rng`]), principal components and the symmetric eigensolver
//! ([`pca`](pca::pca)), t-SNE ([`tsne`](tsne::tsne)) for the embeddings, host arrays in either
//! float type ([`host`]), the float types the CPU kernels run on ([`real::Real`]) and their wide-vector loops ([`wide::wide`]), and the machine features the results depend on
//! ([`platform::Platform`]).

pub(crate) mod host;
pub(crate) mod pca;
pub(crate) mod platform;
pub(crate) mod real;
pub(crate) mod rng;
pub(crate) mod tsne;
pub(crate) mod wide;
