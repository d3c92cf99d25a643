//! # meshvae: the mesh variational autoencoder
//!
//! **In:** a `mesh_io::MeshSet` (meshes sharing one connectivity). **Out:** a trained model
//! folder (config, weights, hierarchy, normalisation, split, template), reconstructions of
//! unseen shapes and their RMS errors.
//!
//! The pipeline: a random split by shape (copies of one pose on one side, [`Split`]) → ACAP
//! features (`deform-features`) → normalisation fitted on the training split → a [`MeshVae`]
//! whose graph operators come from a `mesh_hierarchy::Hierarchy` (Chebyshev or spatial
//! convolutions from `spectral-conv`, pooling by edge contraction) → training with Adam,
//! a learning-rate schedule, early stopping on the validation loss ([`Schedule`]; a run says
//! why it stopped, [`StopReason`]), checkpoints and resumption → evaluation. On the CPU, training runs a hand-written forward +
//! backward over reused buffers ([`Engine`], checked against candle's autograd) when it
//! supports the model, and candle's autograd otherwise. A conditional model
//! (`ModelConfig::labels`) also takes each mesh's label (see `model/cond.rs`); generation,
//! interpolation and embedding work on the trained folder ([`TrainedModel`]).
//!
//! The defaults are the paper's network as the authors' code runs it (`CCPC`, Chebyshev K = 3,
//! 9 channels, latent 128, batch norm, σ = sqrt(2·sigmoid), decoder FC tied to the μ head, loss
//! weights 40 / 3 / 1, Adam, batch 50); where that code departs from the paper's text,
//! [`ModelConfig`] offers both readings. Training departs from theirs (1e-3 for a fixed 8,000
//! epochs): the rate starts at 1e-2, is halved on plateaus of the validation loss, and the run
//! stops when that loss has stopped improving.
//!
//! ```
//! use meshvae::{ModelConfig, TrainConfig, TrainOptions, TrainRequest, TrainedModel, train};
//! use mesh_io::synth::{SynthConfig, generate};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // A small bend/twist set (8 meshes of 122 vertices) stands in for a user's mesh folder.
//! let config = SynthConfig { meshes_per_label: 4, rings: 8, segments: 10, cap_rings: 2,
//!                            ..SynthConfig::default() };
//! let set = generate(&config)?.set;
//! let out = std::env::temp_dir().join(format!("meshvae-doc-{}", std::process::id()));
//! let request = TrainRequest {
//!     set: &set,
//!     source: None,
//!     out: out.clone(),
//!     model: ModelConfig { latent: 16, ..ModelConfig::default() },
//!     train: TrainConfig { epochs: 2, batch: 4, ..TrainConfig::default() },
//!     features: Default::default(),
//!     hierarchy: Default::default(),
//!     split: None, // random halves from the seed, copies of one shape on one side
//! };
//! let options = TrainOptions { force: true, ..TrainOptions::default() };
//! let summary = train(&request, &options, |epoch| println!("{epoch:?}"))?;
//! assert_eq!(summary.epochs_run, 2);
//!
//! let model = TrainedModel::load(&out, &candle_core::Device::Cpu)?;
//! let report = model.evaluate(&set, &candle_core::Device::Cpu)?;
//! println!("test RMS {} (mean shape: {})", report.test.rms, report.mean_shape.rms);
//! # std::fs::remove_dir_all(&out)?;
//! # Ok(()) }
//! ```

mod adam;
mod batch_norm;
mod checkpoint;
mod config;
mod data;
mod dense;
mod embed;
mod error;
mod eval;
mod folder;
mod generate;
mod interpolate;
mod loss;
mod model;
mod ops;
mod params;
mod pca;
mod quality;
mod reconstruct;
mod rng;
mod schedule;
mod split;
mod sse;
mod structure;
mod train;
mod tsne;
mod wide;

pub use adam::{Adam, AdamConfig};
pub use batch_norm::BatchNorm;
pub use checkpoint::{Checkpoint, Progress};
pub use config::{ConvKind, ConvSpec, FEATURE_CHANNELS, ModelConfig};
pub use data::{MeshData, NormalizationFit, denormalize};
pub use embed::{
    EmbedOptions, Embedding, LoopMeasure, MIN_EMBED_MESHES, embed, largest_variance_dims,
    loop_measure,
};
pub use error::{Result, VaeError};
pub use eval::{ErrorReport, align_centroids, error_report, mean_shape};
pub use folder::{
    DEFAULT_MAX_STEPS, DEFAULT_NORMALIZE_QUANTILE, ModelFolder, ModelSpec, SplitFile, TrainConfig,
    TrainedModel,
};
pub use generate::{GenerateOptions, Generated, Neighbour, generate};
pub use interpolate::{Interpolation, interpolate};
pub use loss::{Loss, LossWeights};
/// The pooling choice (`ModelConfig::pool`) is the hierarchy's own [`Pooler`]: one enum from
/// the command line to the operators, which say how they apply ([`PoolMode`]).
pub use mesh_hierarchy::{PoolMode, Pooler};
pub use model::{Encoded, Engine, MeshVae, Mode, StepLoss};
pub use params::{ParamCount, param_count};
pub use pca::{Pca, centered_gram, distances_from_gram, pca, pca_of_gram, symmetric_eigen};
pub use quality::{MEAN_SHAPE_FRACTION, QualityWarning, quality_warnings};
pub use reconstruct::{CopySplit, EvalReport};
pub use rng::Rng;
pub use schedule::{Decision, REWARM_STEPS, Schedule, ScheduleState, StopReason};
pub use split::{Selection, Split, resolve_mesh};
pub use structure::{Layer, Structure};
pub use train::{
    EpochRecord, Executor, ExecutorKind, RunStatus, TrainOptions, TrainRequest, TrainSummary,
    hierarchy_config, read_log, read_status, train, validation_loss,
};
pub use tsne::{Calibration, TsneOptions, calibrate, tsne, tsne_cost};
