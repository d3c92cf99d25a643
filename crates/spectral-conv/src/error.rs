//! The one error type of this crate. Every variant names the operation (or argument) and what is
//! wrong.

/// Everything that can go wrong building or applying a graph operator or layer.
#[derive(Debug, thiserror::Error)]
pub enum ConvError {
    /// A tensor argument has the wrong rank, size, dtype or device.
    #[error("{op}: {what}")]
    Input { op: &'static str, what: String },
    /// A construction argument (matrix, channel count, order K, weight shape) is unusable.
    #[error("{op}: invalid argument `{arg}`: {what}")]
    Argument {
        op: &'static str,
        arg: &'static str,
        what: String,
    },
    /// An error raised by candle itself (allocation, device, a kernel's own check).
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
}

/// This crate's result type.
pub type Result<T> = std::result::Result<T, ConvError>;

impl ConvError {
    pub(crate) fn input(op: &'static str, what: impl Into<String>) -> Self {
        Self::Input {
            op,
            what: what.into(),
        }
    }

    pub(crate) fn argument(op: &'static str, arg: &'static str, what: impl Into<String>) -> Self {
        Self::Argument {
            op,
            arg,
            what: what.into(),
        }
    }
}
