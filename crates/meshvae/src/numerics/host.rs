//! Float data in host memory, in the model's precision: what the CPU engine reads and returns
//! in place of any tensor library's types (each executor converts its own tensors).

/// The float type of a model's variables and data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Precision {
    F32,
    F64,
}

/// Borrowed values of either precision.
#[derive(Debug, Clone, Copy)]
pub(crate) enum HostSlice<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

/// Owned values of either precision.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum HostVec {
    F32(Vec<f32>),
    F64(Vec<f64>),
}

/// A borrowed row-major array: values and dimensions.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HostArray<'a> {
    pub data: HostSlice<'a>,
    pub dims: &'a [usize],
}

/// An owned row-major array.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct HostTensor {
    pub data: HostVec,
    pub dims: Vec<usize>,
}

/// The values of `t` borrowed in place when it is a contiguous f32/f64 CPU tensor; `None`
/// otherwise (other devices, dtypes and layouts take candle's ops instead).
pub(crate) fn with_cpu_values<R>(
    t: &candle_core::Tensor,
    f: impl FnOnce(HostSlice<'_>) -> R,
) -> Option<R> {
    let (storage, layout) = t.storage_and_layout();
    let (candle_core::Storage::Cpu(cpu), Some((lo, hi))) = (&*storage, layout.contiguous_offsets())
    else {
        return None;
    };
    match cpu {
        candle_core::CpuStorage::F32(v) => Some(f(HostSlice::F32(&v[lo..hi]))),
        candle_core::CpuStorage::F64(v) => Some(f(HostSlice::F64(&v[lo..hi]))),
        _ => None,
    }
}
