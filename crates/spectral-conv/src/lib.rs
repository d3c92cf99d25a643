//! # spectral-conv: Chebyshev graph convolution and pooling as candle ops
//!
//! Not built yet (issue "spectral-conv"). In: sparse operators from `mesh-hierarchy`. Out: candle
//! modules (ChebConv, SpatialConv, pooling) with fast CPU kernels and gradients.
