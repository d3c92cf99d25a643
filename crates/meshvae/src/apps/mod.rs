//! What a trained model folder ([`crate::TrainedModel`]) is used for: reconstruction and its
//! error report (`reconstruct.rs`, `eval.rs`), the warnings about a poor model (`quality.rs`),
//! new shapes from the latent space (`generate.rs`), latent paths between meshes
//! (`interpolate.rs`) and 2-D embeddings of the set (`embed.rs`).

pub(crate) mod embed;
pub(crate) mod eval;
#[cfg(test)]
pub(crate) mod fixture;
pub(crate) mod generate;
pub(crate) mod interpolate;
pub(crate) mod quality;
pub(crate) mod reconstruct;
