//! # mesh-hierarchy: levels, Laplacians, pooling and de-pooling operators
//!
//! Not built yet (issue "qem-simplify and mesh-hierarchy"). In: a template mesh and a per-level
//! ratio. Out: a serialisable hierarchy of graphs, rescaled Laplacians and pooling operators.
