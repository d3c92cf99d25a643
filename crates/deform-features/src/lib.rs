//! # deform-features: per-vertex ACAP deformation features and their inverse
//!
//! **In:** a [`mesh_io::MeshSet`] (frames of one connectivity) and a rest mesh (frame 0 unless
//! told otherwise). **Out:** per frame and vertex, 9 numbers describing how the surface around the
//! vertex is rotated and stretched relative to the rest mesh — `[ωx, ωy, ωz, S11, S12, S13, S22,
//! S23, S33]`, the rotation vector of R_i and the symmetric stretch S_i of T_i = R_i S_i — as a
//! [`FeatureSet`] (f32 [N, V, 9]); their [`Normalization`] into [−0.95, 0.95]; and meshes
//! reconstructed from features by a factorised Poisson solve ([`Reconstructor`]).
//!
//! Pipeline of one frame: cotangent weights of the rest mesh ([`cotan`], clamped) → per-vertex
//! deformation gradient T_i by a weighted one-ring fit with a vertex-normal pair ([`fit`]) →
//! the minimal correction making all T_i exactly integrable ([`integrate`]) → polar
//! decomposition and rotation log ([`rotation`]) → ACAP-consistent rotation vectors
//! ([`consistency`]). Frames are processed in parallel (rayon); f64 throughout, f32 out.
//!
//! **The one choice that matters** ([`FeatureOptions::integrable`]): per-vertex fits are not
//! exactly integrable, so the Poisson reconstruction of the plain fit has a floor (rms ≈ 1.9e-3 of
//! the diagonal on horse-gallop, 3e-4 on samba and elephant-gallop), and general affine maps are
//! only approximately reproduced on curved meshes (similarities are exact). With the correction
//! (the default) every frame, and every affine map, round-trips exactly up to f32 rounding
//! (≈1e-8), at the price of rougher features: the correction is spread as a high-frequency
//! field (mean change of T_i ≈ 3 %, feature differences across edges ×1.2–3, wider
//! normalisation ranges). Set `integrable: false` for the smoother plain fit.
//!
//! ```no_run
//! use deform_features::{FeatureExtractor, FeatureOptions, Normalization, Reconstructor};
//! # fn main() -> Result<(), deform_features::FeatureError> {
//! let set = mesh_io::load_set("../shared/datasets/horse-gallop".as_ref())?.value;
//! let extractor = FeatureExtractor::for_set(&set, FeatureOptions::default())?;
//! let out = extractor.extract(&set)?; // f32 [N, V, 9] + warnings
//! let norm = Normalization::fit([&out.features])?;
//! let network_input = norm.apply(&out.features); // in [-0.95, 0.95]
//! // … and back: de-normalise, then one sparse solve per frame.
//! let raw = norm.invert(&network_input);
//! let rec = Reconstructor::new(extractor.rest())?;
//! let positions = rec.reconstruct(raw.frame(7))?; // Vec<[f64; 3]>, centroid = rest centroid
//! println!("{} vertices", positions.len());
//! # Ok(()) }
//! ```

pub mod consistency;
pub mod cotan;
mod error;
pub mod features;
pub mod fit;
pub mod integrate;
pub mod io;
pub mod normalize;
pub mod reconstruct;
pub mod rest;
pub mod rotation;
mod sparse;

#[cfg(test)]
#[path = "../tests/common/shapes.rs"]
mod testmesh;

pub use cotan::WeightClamp;
pub use error::FeatureError;
pub use features::{
    CHANNEL_NAMES, CHANNELS, FeatureExtractor, FeatureOptions, FeatureSet, Features,
    ROTATION_CHANNELS, extract_features,
};
pub use io::{FeatureFile, load_features, save_features};
pub use normalize::Normalization;
pub use reconstruct::Reconstructor;
pub use rest::{RestMesh, WeightStats};
