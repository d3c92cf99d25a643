//! # meshvae-py: the meshvae crates as the Python package `meshvae`
//!
//! **In:** numpy arrays (positions float32/float64 `[V, 3]` or `[N, V, 3]`, faces of any
//! integer type `[F, 3]`, features `[..., 9]`) and paths. **Out:** numpy arrays (float32
//! positions and features, int32 faces, int64 vertex maps), `scipy.sparse.csr_matrix` float32
//! operators, and the classes `MeshSet`, `Simplified`, `Hierarchy`, `Normalization`,
//! `FeatureFile`, `Model`,
//! and the levels behind `meshvae.sampling` (CoMA / SpiralNet++ transform matrices), and what
//! `meshvae.torch` reads from and writes to model folders (`torch_support`).
//!
//! A thin layer: every computation is a call into mesh-io, qem-simplify, mesh-hierarchy,
//! deform-features or meshvae (trained models), the same calls the `meshvae` command makes, so
//! results equal the command's.
//! Inputs are checked here with errors naming the argument ([`arrays`]); every error of the
//! crates becomes `meshvae.InputError` (a `ValueError`) or `meshvae.FileError` (an `OSError`)
//! carrying its message ([`errors`]); long calls release the GIL (`Python::detach`).
//!
//! Built by maturin (`pip install ./python` from the repository root); the Python side
//! (`meshvae/__init__.py`, the stubs, the tests) lives beside this crate.

mod arrays;
mod errors;
mod features;
mod hierarchy;
mod mesh;
mod model;
mod sampling;
mod simplify;
mod torch_support;

use pyo3::prelude::*;

#[pymodule]
fn _meshvae(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<mesh::MeshSet>()?;
    m.add_function(wrap_pyfunction!(mesh::load_set, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::load_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::save_obj, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::save_glb, m)?)?;
    m.add_class::<simplify::Simplified>()?;
    m.add_function(wrap_pyfunction!(simplify::simplify, m)?)?;
    m.add_class::<hierarchy::Hierarchy>()?;
    m.add_function(wrap_pyfunction!(sampling::sampling_levels, m)?)?;
    m.add_class::<features::Normalization>()?;
    m.add_class::<features::FeatureFile>()?;
    m.add_function(wrap_pyfunction!(features::acap_features, m)?)?;
    m.add_function(wrap_pyfunction!(features::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(features::load_features, m)?)?;
    m.add_class::<model::Model>()?;
    m.add_function(wrap_pyfunction!(torch_support::_torch_model_state, m)?)?;
    m.add_function(wrap_pyfunction!(torch_support::_torch_model_inputs, m)?)?;
    m.add_function(wrap_pyfunction!(torch_support::_torch_write_weights, m)?)?;
    m.add_function(wrap_pyfunction!(torch_support::_torch_engine_step, m)?)?;
    Ok(())
}
