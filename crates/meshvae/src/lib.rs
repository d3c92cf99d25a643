//! # meshvae: the mesh variational autoencoder
//!
//! **In:** a `mesh_io::MeshSet` (meshes sharing one connectivity). **Out:** a trained model
//! folder (config, weights, hierarchy, normalisation, split, template), reconstructions of
//! unseen shapes and their RMS errors.
//!
//! The pipeline: ACAP features (`deform-features`) → normalisation fitted on the training split
//! → a [`MeshVae`] whose graph operators come from a `mesh_hierarchy::Hierarchy` (Chebyshev or
//! spatial convolutions from `spectral-conv`, pooling by edge contraction) → training with
//! Adam, checkpoints and resumption → evaluation.

mod adam;
mod batch_norm;
mod checkpoint;
mod config;
mod data;
mod error;
mod eval;
mod folder;
mod loss;
mod model;
mod ops;
mod params;
mod reconstruct;
mod rng;
mod split;
mod structure;
mod train;

pub use adam::{Adam, AdamConfig};
pub use batch_norm::BatchNorm;
pub use checkpoint::{Checkpoint, Progress};
pub use config::{ConvKind, ConvSpec, FEATURE_CHANNELS, ModelConfig, PoolKind};
pub use data::{MeshData, denormalize};
pub use error::{Result, VaeError};
pub use eval::{ErrorReport, error_report, mean_shape};
pub use folder::{ModelFolder, ModelSpec, SplitFile, TrainConfig, TrainedModel};
pub use loss::{Loss, LossWeights};
pub use model::{Encoded, MeshVae, Mode};
pub use params::{ParamCount, param_count};
pub use reconstruct::EvalReport;
pub use rng::Rng;
pub use split::{Split, resolve_mesh};
pub use structure::{Layer, Structure};
pub use train::{
    EpochRecord, TrainOptions, TrainRequest, TrainSummary, hierarchy_config, read_log, train,
    validation_loss,
};
