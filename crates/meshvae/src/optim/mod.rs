//! The optimiser both executors step: [`adam::Adam`] (its moments, its fused update over
//! gradient slices or candle's gradients, and gradient clipping). Below `train/` and `cpu/`,
//! which both use it.

pub(crate) mod adam;
