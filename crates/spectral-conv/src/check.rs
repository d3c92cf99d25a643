//! Argument checks the constructors share, so that each message is written once.

use crate::error::{ConvError, Result};
use candle_core::Tensor;

/// `Ok` when the `rows × cols` matrix given as `arg` to `op` is square.
pub(crate) fn square(op: &'static str, arg: &'static str, rows: usize, cols: usize) -> Result<()> {
    if rows == cols {
        Ok(())
    } else {
        Err(ConvError::argument(
            op,
            arg,
            format!("must be square, is {rows}x{cols}"),
        ))
    }
}

/// `Ok` when a layer with `c_out` output channels has no bias or a bias of shape `[c_out]`.
pub(crate) fn bias(op: &'static str, bias: Option<&Tensor>, c_out: usize) -> Result<()> {
    match bias {
        Some(b) if b.dims() != [c_out] => Err(ConvError::argument(
            op,
            "bias",
            format!("shape {:?}, expected [{c_out}]", b.dims()),
        )),
        _ => Ok(()),
    }
}
