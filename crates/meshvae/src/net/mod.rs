//! The network description, independent of any executor: the configuration a model is built
//! from ([`config::ModelConfig`], its convolutions and their order), the layer structure
//! (`CCPC`: [`structure::Structure`]), the paper's parameter count ([`params::param_count`]),
//! the variables (named once, in [`vars`]) and the layer list every executor reads
//! ([`plan::NetPlan`]). Nothing here knows candle, the CPU engine or training.

pub(crate) mod baseline;
pub(crate) mod batch_norm;
pub(crate) mod config;
pub(crate) mod elementwise;
pub(crate) mod latent;
pub(crate) mod loss_weights;
pub(crate) mod network;
pub(crate) mod params;
pub(crate) mod plan;
pub(crate) mod structure;
pub(crate) mod vars;
