//! # spectral-conv: graph convolution and pooling on meshes as candle ops
//!
//! **In:** fixed sparse operators as [`CsrMatrix`] (of the `sparse-csr` crate, re-exported here:
//! a rescaled Laplacian L̃, pooling, de-pooling or sampling matrices, as `mesh-hierarchy` builds
//! them from a mesh, though this crate does not depend on it), spiral index lists (`u32`, S per
//! vertex, as `mesh_hierarchy::spirals` makes them) and batches of per-vertex features
//! as candle tensors `[B, V, C]` (or `[V, C]`), f32 or f64.
//! **Out:** differentiable layers: [`SparseOp`] (y = A x), [`ChebConv`]
//! (y = Σ_k T_k(L̃) x W_k + b), [`SpatialConv`] (self + neighbour mean), [`SpiralConv`]
//! (SpiralNet++'s: a dense layer over each vertex's spiral of vertices), [`MeanPool`],
//! [`DePool`], [`Sampling`] and [`MaxPool`] (signed largest magnitude per cluster, or with
//! [`MaxMode::PlainMax`] graph max pooling over overlapping neighbourhoods).
//!
//! Training time is spent in these sparse products, and candle has no sparse tensors, so on the
//! CPU they are custom ops with hand-written rayon kernels ([`Backend::Kernel`]; ChebConv is one
//! fused op). Every layer also has a path built only from candle ops ([`Backend::Fallback`]) that
//! runs on any device; the kernel path switches to it by itself off the CPU, so a CUDA build only
//! needs this crate's `cuda` feature. Bad arguments are [`ConvError`]s.
//!
//! Layouts: every layer takes `[B, V, C]` (`forward`, `apply`) and also the vertex-major
//! `[V, B, C]` (`forward_vertex_major`, `apply_vertex_major`), in which one vertex's values for
//! the whole batch are contiguous. A network that keeps its activations `[V, B, C]` from the
//! first layer to the last never transposes (the `[B, V, C]` entry points transpose internally
//! on every call); channel stays the last dimension, so element-wise layers and batch norm over
//! channels are unchanged. Both give the same results.
//!
//! Speed notes: use mimalloc as the global allocator (every op allocates ~50 MB tensors), and
//! number the template's vertices with [`locality_order`] once, before building the hierarchy,
//! if its order has little locality (see `docs/benchmarks.md`). A network on the buffer-level
//! kernels ([`ChebKernel`], [`SparseKernel`]; made from a `SparseOp` or, without candle or a
//! device, from the matrix itself, [`ChebKernel::from_matrix`]) can instead renumber one level
//! where it pays:
//! [`ChebKernel::far_share`] measures the scatter, [`ChebKernel::locality_order`] gives an order,
//! and [`ChebKernel::permuted`] and [`SparseKernel::permuted`] the renumbered operators
//! (`docs/crates.md`, "Buffer-level kernels and vertex order").
//!
//! Scratch memory is explicit: the buffer-level kernels stage their work in a [`Workspace`] the
//! caller passes; each [`SparseOp`] (and every layer built on it) holds one, its own unless
//! [`SparseOp::with_workspace`] gives it a shared one. Large intermediates are reused between
//! calls from there; dropping the workspace (or [`Workspace::clear`]) frees them.
//!
//! ```
//! use candle_core::{DType, Device, Tensor};
//! use candle_nn::{VarBuilder, VarMap};
//! use spectral_conv::{ChebConfig, ChebConv, CsrMatrix, SparseOp};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // A square of two triangles 0-1-2, 0-2-3. With the normalised Laplacian
//! // L = I − D^-1/2 A D^-1/2 and λmax = 2, as the authors, L̃ = 2L/λmax − I = −D^-1/2 A D^-1/2
//! // (`mesh-hierarchy` builds it for any mesh:
//! // `rescaled_laplacian(&normalized_laplacian(&adjacency(v, faces)), LambdaMax::Two)`).
//! let edges = [(0u32, 1u32), (1, 2), (2, 0), (2, 3), (3, 0)];
//! let degree = [3.0f64, 2.0, 3.0, 2.0];
//! let entries: Vec<(u32, u32, f64)> = edges
//!     .iter()
//!     .flat_map(|&(i, j)| [(i, j), (j, i)])
//!     .map(|(i, j)| (i, j, -1.0 / (degree[i as usize] * degree[j as usize]).sqrt()))
//!     .collect();
//! let l = CsrMatrix::from_triplets(4, 4, &entries)?;
//! let device = Device::Cpu;
//! let laplacian = SparseOp::new(&l, &device)?;
//! let vars = VarMap::new();
//! let vb = VarBuilder::from_varmap(&vars, DType::F32, &device);
//! let conv = ChebConv::new(laplacian, ChebConfig::new(9, 9), vb.pp("conv1"))?; // K = 3
//! let x = Tensor::randn(0f32, 1.0, (2, 4, 9), &device)?; // [B, V, C]
//! let y = conv.forward(&x)?;
//! assert_eq!(y.dims(), &[2, 4, 9]);
//! let grads = y.sqr()?.sum_all()?.backward()?; // gradients reach the weights
//! assert!(grads.get(conv.weight()).is_some());
//! # Ok(()) }
//! ```

mod bias;
mod buffers;
mod cheb;
mod cheb_kernel;
mod cheb_op;
mod check;
mod custom_op;
mod error;
mod kernel;
mod layout;
mod max_kernel;
mod mix;
mod order;
mod pool;
mod simd;
mod spatial;
mod spiral;
mod spiral_kernel;
mod spmm;
#[cfg(test)]
mod test_util;
// The layers' vertex-major entry points against their `[B, V, C]` forms (every layer at once).
#[cfg(test)]
mod tests;
mod transpose;
mod workspace;

pub use buffers::{ChebKernel, ConvDims, Float, MaxKernel, SparseKernel};
pub use cheb::{ChebConfig, ChebConv};
pub use error::{ConvError, Result};
pub use max_kernel::MaxMode;
pub use order::{inverse_order, locality_order, permute_symmetric};
pub use pool::{DePool, MaxPool, MeanPool, Sampling};
pub use sparse_csr::CsrMatrix;
pub use spatial::{SpatialConfig, SpatialConv, neighbour_mean_matrix};
pub use spiral::SpiralConv;
pub use spmm::{Backend, SparseOp};
pub use workspace::Workspace;
