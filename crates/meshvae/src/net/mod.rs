//! The network description, independent of any executor: the configuration a model is built
//! from ([`config::ModelConfig`], its convolutions and their order), the layer structure
//! (`CCPC`: [`structure::Structure`]) and the paper's parameter count ([`params::param_count`]).
//! Nothing here knows candle, the CPU engine or training.

pub(crate) mod config;
pub(crate) mod params;
pub(crate) mod structure;
