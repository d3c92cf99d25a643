//! Batch norm's constants, the one place every executor takes them from (the authors' values).

/// ε added to the variance.
pub const EPS: f64 = 1e-5;
/// Decay of the running statistics: r ← DECAY·r + (1 − DECAY)·batch.
pub const DECAY: f64 = 0.9;
