//! The candle reference model: [`model::MeshVae`] (encoder, decoder, its variables and weight
//! files, the conditional inputs) and the layers and fused CPU ops it is built from: batch norm
//! (with the train/eval [`batch_norm::Mode`]), the dense layers that keep their gradients out of
//! candle's store, the element-wise ops and the squared error. Training's candle path and every
//! application run this model; the CPU engine (`cpu/`) is checked against it.

pub(crate) mod batch_norm;
pub(crate) mod dense;
pub(crate) mod model;
pub(crate) mod ops;
pub(crate) mod sse;
