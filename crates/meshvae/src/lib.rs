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
//! why it stopped, [`StopReason`]), checkpoints, resumption and a clean stop on request
//! ([`StopFlag`], e.g. Ctrl-C) → evaluation. On the CPU, training runs a hand-written forward +
//! backward over reused buffers ([`EngineExecutor`], checked against candle's autograd,
//! [`CandleExecutor`]) when it supports the model (every CPU model of ours with K ≤ 8), and
//! candle's autograd otherwise; both implement [`Executor`], and which one ran, and why candle
//! where it did, is said in the log, `run.json` and the summary ([`ExecutorChoice`]). The applications' encoding and decoding run on the same engine on the CPU
//! ([`TrainedModel::reconstruct_batch`]). Both executors are built from one network
//! description (`net/plan.rs`). A conditional model
//! (`ModelConfig::labels`) also takes each mesh's label (see `candle/model/cond.rs`); generation,
//! interpolation and embedding work on the trained folder ([`TrainedModel`]).
//!
//! The same pipeline trains the auto-encoders the paper is compared with ([`Network`], set in
//! `ModelConfig::net`): Tan et al.'s fully connected mesh VAE on the same features, and CoMA and
//! SpiralNet++ on vertex positions (standardised per vertex, [`InputScaling`]), each as its
//! authors define it, on candle's autograd.
//!
//! The defaults are the paper's network as the authors' code runs it (`CCPC`, Chebyshev K = 3,
//! 9 channels, latent 128, batch norm, σ = sqrt(2·sigmoid), decoder FC tied to the μ head, loss
//! weights 40 / 3 / 1, Adam, batch 50); where that code departs from the paper's text,
//! [`ModelConfig`] offers both readings. Training departs from theirs (1e-3 for a fixed 8,000
//! epochs): the rate warms up to 1e-2 and falls along a cosine, Adam's β₂ is 0.95, and the run
//! stops when the validation loss has stopped improving.
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

mod apps;
mod candle;
mod cpu;
mod error;
mod executor;
mod net;
mod numerics;
mod optim;
mod train;
mod trained;

// Errors.
pub use error::{Result, VaeError};

// The network description (`net/`): configuration, layer structure, parameter count.
/// The pooling choice (`ModelConfig::pool`) is the hierarchy's own [`Pooler`]: one enum from
/// the command line to the operators, which say how they apply ([`PoolMode`]).
pub use mesh_hierarchy::{PoolMode, Pooler};
pub use net::config::{ConvKind, ConvSpec, FEATURE_CHANNELS, ModelConfig};
pub use net::network::{Activation, GraphConvKind, Input, Network, RecLoss};
pub use net::params::{ParamCount, param_count};
pub use net::structure::{Layer, Structure};

// The candle reference model (`candle/`).
pub use candle::batch_norm::{BatchNorm, Mode};
pub use candle::model::{Encoded, MeshVae};

// The executors (`executor/`): the hand-written CPU engine (`cpu/`) and candle's autograd.
pub use cpu::StepLoss;
pub use executor::{
    Batch, CandleExecutor, EngineExecutor, Executor, ExecutorChoice, ExecutorKind, StepReport,
    TrainStep, default_device,
};

// Training (`train/`): the loop, its optimiser, losses, schedule, data, split and checkpoints.
pub use optim::adam::{Adam, AdamConfig, GradClip};
pub use train::checkpoint::{Checkpoint, Progress};
pub use train::config::{
    DEFAULT_BETA2, DEFAULT_GRAD_CLIP, DEFAULT_HEAD_LR_SCALE, DEFAULT_MAX_STEPS,
    DEFAULT_NORMALIZE_QUANTILE, TrainConfig,
};
pub use train::data::{Inputs, MeshData, NormalizationFit, denormalize};
pub use train::folder::{ModelFolder, ModelSpec, SplitFile};
pub use train::loss::{Loss, LossWeights};
pub use train::scaling::{InputScaling, PositionScaling};
pub use train::schedule::{Decision, REWARM_STEPS, Schedule, ScheduleState, StopReason};
pub use train::split::{Selection, Split, resolve_mesh};
pub use train::{
    EpochRecord, PhaseSeconds, RunStatus, SPIKE_FACTOR, SPIKE_WINDOW, StopFlag, TrainOptions,
    TrainRequest, TrainSummary, hierarchy_config, loss_spikes, read_log, read_status, train,
    validation_loss,
};

// A trained model folder loaded for use (`trained.rs`).
pub use trained::TrainedModel;

// Applications of a trained model (`apps/`).
pub use apps::embed::{
    EmbedOptions, Embedding, LoopMeasure, MIN_EMBED_MESHES, embed, largest_variance_dims,
    loop_measure,
};
pub use apps::eval::{ErrorReport, align_centroids, error_report, mean_shape};
pub use apps::generate::{GenerateOptions, Generated, Neighbour, generate};
pub use apps::interpolate::{Interpolation, interpolate};
pub use apps::quality::{MEAN_SHAPE_FRACTION, QualityWarning, quality_warnings};
pub use apps::reconstruct::{CopySplit, EvalReport};

// Numerics (`numerics/`): random stream, PCA, t-SNE.
pub use numerics::pca::{
    Pca, centered_gram, distances_from_gram, pca, pca_of_gram, symmetric_eigen,
};
pub use numerics::platform::Platform;
pub use numerics::rng::Rng;
pub use numerics::tsne::{Calibration, TsneOptions, calibrate, tsne, tsne_cost};
