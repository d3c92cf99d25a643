//! The candle reference model: [`model::MeshVae`] (encoder, decoder, its variables and weight
//! files, the conditional inputs), built from plain candle ops, spectral-conv's graph operators
//! and batch norm (with the train/eval [`batch_norm::Mode`]). It is the reference the CPU engine
//! (`cpu/`) is tested against and the path for other devices (and `--no-engine`), and the other
//! auto-encoders ([`baseline::BaselineNet`]), which only it runs.

pub(crate) mod baseline;
pub(crate) mod batch_norm;
mod elementwise;
mod elu;
pub(crate) mod model;
