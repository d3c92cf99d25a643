//! What the CPU custom ops share: the contiguous slice behind a tensor, and a forward pass
//! written once for f32 and f64.

use crate::kernel::Real;
use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, Layout, Shape, Storage, WithDType};

/// The contiguous `[lo, hi)` span of a storage a layout covers, or an error naming the op.
pub(crate) fn contiguous_span(op: &str, layout: &Layout) -> candle_core::Result<(usize, usize)> {
    layout
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::Msg(format!("{op}: input is not contiguous")))
}

/// The contiguous data of a CPU tensor of dtype `T` (from `Tensor::storage_and_layout`).
pub(crate) fn cpu_slice<'a, T: WithDType>(
    op: &str,
    storage: &'a Storage,
    layout: &Layout,
) -> candle_core::Result<&'a [T]> {
    let Storage::Cpu(cpu) = storage else {
        candle_core::bail!("{op}: the backward pass expects CPU tensors");
    };
    let (lo, hi) = contiguous_span(op, layout)?;
    Ok(&T::cpu_storage_as_slice(cpu)?[lo..hi])
}

/// A one-input op whose CPU forward pass maps a contiguous slice to a new buffer.
pub(crate) trait SliceOp {
    /// The op's name in error messages.
    const NAME: &'static str;

    /// The output and its shape for input `x` of shape `dims`.
    fn run<T: Real>(&self, x: &[T], dims: &[usize]) -> candle_core::Result<(Vec<T>, Shape)>;
}

/// `CustomOp1::cpu_fwd` for a [`SliceOp`]: f32 and f64, anything else an error.
pub(crate) fn cpu_fwd<O: SliceOp>(
    op: &O,
    storage: &CpuStorage,
    layout: &Layout,
) -> candle_core::Result<(CpuStorage, Shape)> {
    let (lo, hi) = contiguous_span(O::NAME, layout)?;
    match storage {
        CpuStorage::F32(x) => {
            let (y, shape) = op.run(&x[lo..hi], layout.dims())?;
            Ok((CpuStorage::F32(y), shape))
        }
        CpuStorage::F64(x) => {
            let (y, shape) = op.run(&x[lo..hi], layout.dims())?;
            Ok((CpuStorage::F64(y), shape))
        }
        other => candle_core::bail!("{}: dtype {:?} not supported", O::NAME, other.dtype()),
    }
}
